"""`python -m pytest bench` (issue 27, item 5): a quick run by default (the headline cases at
512x512, fp32), whose results and report go to an untracked folder, so a user who runs it keeps a
clean checkout; the whole matrix and the tracked report only when asked (--bench-full, --update-report)."""
import json
import os
import subprocess
import sys

from conftest import REPO

# every file a benchmark run or its report could rewrite, and that git tracks
TRACKED = ["bench/results.json", "bench/REPORT.md", "bench/error_vs_time.png", "bench/open3d_results.json",
           "bench/results-shapes.json", "docs/benchmarks.md", "README.md"]


def bench(*args, out=None):
    env = dict(os.environ)
    env.pop("PYCLRAY_BENCH_OUT", None)
    if out is not None:
        env["PYCLRAY_BENCH_OUT"] = str(out)
    return subprocess.run([sys.executable, "-m", "pytest", "bench", "-p", "no:cacheprovider", *args],
                          capture_output=True, text=True, cwd=REPO, env=env)


def collected(*args) -> list[str]:
    result = bench("--collect-only", "-q", *args)
    assert result.returncode == 0, result.stdout + result.stderr
    return [line for line in result.stdout.splitlines() if line.startswith("bench/")]


def test_the_quick_run_is_the_headline_cases_and_the_full_run_is_everything():
    quick, full = collected(), collected("--bench-full")
    assert set(quick) < set(full) and 5 <= len(quick) <= 20 < len(full)
    for case in quick:
        assert not any(word in case for word in ("2048", "fp64", "scalar", "grid", "breakdown", "exact_cost")), case
    for word in ("2048", "fp64", "mitsuba_scalar", "grid1024", "breakdown", "exact_cost"):
        assert any(word in case for case in full), word
    assert any("tp02-512-all-fp32" in case for case in quick) and any("mitsuba_llvm[tp02-512]" in case for case in quick)


def test_a_bench_run_writes_its_results_and_report_outside_the_tracked_files(tmp_path):
    """One case of the quick run: results.json and REPORT.md (the plot too where matplotlib is
    installed) under $PYCLRAY_BENCH_OUT (by default outside the checkout); no tracked file changes."""
    before = {name: (REPO / name).read_bytes() if (REPO / name).exists() else None for name in TRACKED}
    out = tmp_path / "out"
    result = bench("-q", "-k", "test_floor", out=out)
    assert result.returncode == 0, result.stdout + result.stderr
    assert {name: (REPO / name).read_bytes() if (REPO / name).exists() else None for name in TRACKED} == before
    results = json.loads((out / "results.json").read_text())
    assert [b["name"] for b in results["benchmarks"]] == ["test_floor[512-in-place]"]
    assert (out / "REPORT.md").read_text().startswith("# pyclray benchmarks")
    assert f"wrote {out / 'REPORT.md'}" in result.stdout


def test_bench_out_is_ignored_by_git():
    ignored = (REPO / ".gitignore").read_text().split()
    assert "bench/out/" in ignored


def test_by_default_a_run_writes_outside_the_checkout(tmp_path):
    """Issue 42 item 10: without $PYCLRAY_BENCH_OUT a run's results and report go outside the
    checkout (under the user's cache folder, $XDG_CACHE_HOME/pyclray/bench), not even into an ignored
    folder of it; the run says where."""
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))
    env.pop("PYCLRAY_BENCH_OUT", None)
    untracked = lambda: subprocess.run(["git", "status", "--porcelain", "--ignored", "--untracked-files=all", "bench"],
                                       capture_output=True, text=True, cwd=REPO).stdout.splitlines()
    before = set(untracked())
    result = subprocess.run([sys.executable, "-m", "pytest", "bench", "-p", "no:cacheprovider", "-q", "-k", "test_floor"],
                            capture_output=True, text=True, cwd=REPO, env=env)
    assert result.returncode == 0, result.stdout + result.stderr
    out = tmp_path / "cache" / "pyclray" / "bench"
    assert (out / "results.json").is_file() and (out / "REPORT.md").is_file()
    assert f"wrote {out / 'REPORT.md'}" in result.stdout
    new = {line for line in set(untracked()) - before if "__pycache__" not in line}
    assert not new, new


def test_update_report_is_the_option_that_writes_the_tracked_files():
    result = bench("--help")
    assert "--update-report" in result.stdout and "--bench-full" in result.stdout
