"""Benchmark fixtures and modes. Kept out of the default test run (setup.cfg: testpaths = tests).

    python -m pytest bench                   # quick: the headline cases at 512x512, under a minute
    python -m pytest bench --bench-full      # the whole matrix (2048x2048, fp64, cold, scalar_rgb...)
    python -m pytest bench --bench-full --update-report  # the same, and rewrite the tracked report

A run leaves the checkout as it was: the results go outside it, to bench.OUT
($XDG_CACHE_HOME/pyclray/bench, by default ~/.cache/pyclray/bench; $PYCLRAY_BENCH_OUT moves it):
results.json, the report REPORT.md and its plot error_vs_time.png, written at the end of the run (the
report needs matplotlib, in the bench extra). Only --update-report writes the tracked bench/results.json,
bench/REPORT.md, bench/error_vs_time.png and the headline table of docs/benchmarks.md. An explicit
--benchmark-json PATH is honoured as given.

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

from . import HERE, OUT  # noqa: E402  (OUT: outside the checkout, where a run's results and report go)

SCENES = HERE.parent / "scenes"
TRACKED = {"results": HERE / "results.json", "report": HERE / "REPORT.md", "plot": HERE / "error_vs_time.png",
           "headline": HERE.parent / "docs" / "benchmarks.md"}
# the environment variable test_bench.py reads for the timing budget per case (set here, before the
# benchmark modules are imported by the collection)
MODE_VARIABLE = "PYCLRAY_BENCH_MODE"

# The quick run: what the headline table and the speed targets need, at 512x512 in fp32 (the test
# function -> which of its parameters are kept; None: the function is left out). Everything else
# (2048x2048, fp64, grid scenes, scalar_rgb, the breakdown, the exact-cost comparison) is --bench-full's.
QUICK = {
    "test_oracle": {"name": ("tp02", "shapes")},
    "test_floor": {"size": (512,), "mode": ("in-place",)},
    "test_pyclray_warm": {"name": ("tp02", "shapes"), "size": (512,), "precision": ("fp32",)},
    "test_pyclray_new_scene": {"name": ("tp02",), "size": (512,)},
    "test_pyclray_cold": {"name": ("tp02",), "aovs": ("all",), "precision": ("fp32",)},
    "test_mitsuba_llvm": {"name": ("tp02", "shapes"), "size": (512,)},
    "test_targets_blocks": {"group": ("tp02 512",)},
}


def pytest_addoption(parser):
    group = parser.getgroup("pyclray benchmarks")
    group.addoption("--bench-full", action="store_true",
                    help="run the whole benchmark matrix (about 7 minutes on 2 cores); default: the quick run")
    group.addoption("--update-report", "--bench-update", action="store_true", dest="update_report",
                    help="write the tracked bench/results.json, bench/REPORT.md, bench/error_vs_time.png and the "
                    f"headline of docs/benchmarks.md (default: {OUT}, outside the checkout); use with --bench-full")


def _paths(config) -> dict:
    if config.getoption("update_report"):
        return TRACKED
    return {"results": OUT / "results.json", "report": OUT / "REPORT.md", "plot": OUT / "error_vs_time.png",
            "headline": None}


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config):
    os.environ[MODE_VARIABLE] = "full" if config.getoption("--bench-full") else "quick"
    if not hasattr(config.option, "benchmark_json"):
        return  # pytest-benchmark is not installed: the benchmark fixture will say so
    if config.option.benchmark_json is None:
        path = _paths(config)["results"]
        path.parent.mkdir(parents=True, exist_ok=True)
        config.option.benchmark_json = path
        session = getattr(config, "_benchmarksession", None)
        if session is not None:  # pytest-benchmark configured before us: its session read the option already
            session.json = path


def pytest_collection_modifyitems(config, items):
    if config.getoption("--bench-full"):
        return
    kept, left = [], []
    for item in items:
        name = getattr(item, "originalname", item.name)
        rule = QUICK.get(name)
        params = getattr(getattr(item, "callspec", None), "params", {})
        if rule is not None and all(params.get(key) in values for key, values in rule.items() if key in params):
            kept.append(item)
        else:
            left.append(item)
    if left:
        config.hook.pytest_deselected(items=left)
        items[:] = kept


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session, exitstatus):
    """The report of the run, from the JSON pytest-benchmark has just written (its own
    sessionfinish runs first)."""
    config = session.config
    results = getattr(config.option, "benchmark_json", None)
    paths = _paths(config)
    if results is None or not Path(results).is_file() or Path(results) != paths["results"]:
        return  # no run, or a JSON path of the user's own: the report is theirs to make
    from . import report

    arguments = [str(results), "-o", str(paths["report"]), "--plot", str(paths["plot"])]
    if paths["headline"] is not None:
        arguments += ["--readme", str(paths["headline"])]
    try:
        report.main(arguments)
    except ModuleNotFoundError as error:  # matplotlib: pip install -e ".[bench]"
        print(f"\nbench: no report ({error}); the results are in {results}")


def pytest_report_header(config):
    mode = "the whole matrix" if config.getoption("--bench-full") else "quick (--bench-full for the whole matrix)"
    where = "the tracked bench/ files" if config.getoption("update_report") else f"{OUT} (outside the checkout)"
    return f"pyclray benchmarks: {mode}; results and report in {where}"


@pytest.fixture(scope="session")
def scenes_dir() -> Path:
    return SCENES
