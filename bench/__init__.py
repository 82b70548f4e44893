"""pyclray's benchmarks against Mitsuba 3 and the float64 oracle (run with pytest: docs/benchmarks.md).

A run writes its results under OUT (bench/out/, ignored by git; $PYCLRAY_BENCH_OUT moves it), so a
checkout stays clean; only an explicit update (`python -m pytest bench --bench-full --bench-update`,
`python -m bench.report --update`, `python -m bench.open3d_compare --update`) rewrites the tracked
results and report in bench/.
"""
import os
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("PYCLRAY_BENCH_OUT") or HERE / "out")
