"""pyclray's benchmarks against Mitsuba 3 and the float64 oracle (run with pytest: docs/benchmarks.md).

A run writes its results under OUT, outside the checkout ($XDG_CACHE_HOME/pyclray/bench, by default
~/.cache/pyclray/bench; $PYCLRAY_BENCH_OUT moves it), so a checkout stays as it was; only an explicit
update (`python -m pytest bench --bench-full --update-report`,
`python -m bench.report --update`, `python -m bench.open3d_compare --update`) rewrites the tracked
results and report in bench/.
"""
import os
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("PYCLRAY_BENCH_OUT")
           or Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "pyclray" / "bench")
