"""Benchmark fixtures. Kept out of the default test run (setup.cfg: testpaths = tests); run with

    pytest bench/ --benchmark-only --benchmark-json=bench/results.json && python -m bench.report

PoCL's own kernel cache is switched off here (before PoCL is loaded), so that a "cold" render
really compiles: cold = pyclray's in-memory programs cleared, PYCLRAY_CACHE_DIR an empty temp dir
and no PoCL cache. Warm renders are not affected (programs stay in memory). OpenBLAS runs one
thread (unless OPENBLAS_NUM_THREADS is set), so that no BLAS thread spins during a timing.
"""
import os

os.environ.setdefault("POCL_KERNEL_CACHE", "0")
# numpy's BLAS threads (the oracle, the error metrics) would keep spinning into the next timing
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

_CACHE = tempfile.mkdtemp(prefix="pyclray-bench-cache-")
os.environ["PYCLRAY_CACHE_DIR"] = _CACHE  # never the user's cache

SCENES = Path(__file__).resolve().parent.parent / "scenes"


@pytest.fixture(scope="session")
def scenes_dir() -> Path:
    return SCENES
