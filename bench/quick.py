"""Quick figures without pytest-benchmark: warm render times of a scene, and the first render of a
new process with no cache, with pyclray's disk cache only, and with both caches warm (5 runs of each,
each with new cache folders; $PYCLRAY_QUICK_RUNS changes the count).

    python -m bench.quick [SCENE]
"""
from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FIRST_RENDER = """
import sys, time, pyclray
scene = pyclray.load_scene(sys.argv[1])
start = time.perf_counter(); pyclray.render(scene); print(time.perf_counter() - start)
"""


def warm(path: str, size: int, rounds: int) -> tuple[float, float]:
    import pyclray

    scene = pyclray.load_scene(path).with_size(size, size)
    pyclray.render(scene)
    times = []
    for _ in range(rounds):
        start = time.perf_counter()
        pyclray.render(scene)
        times.append(time.perf_counter() - start)
    return statistics.median(times), min(times)


def first_render(path: str, cache: str, pocl_dir: str, pocl_cache: bool) -> float:
    env = dict(os.environ, PYCLRAY_CACHE_DIR=cache, POCL_CACHE_DIR=pocl_dir, POCL_KERNEL_CACHE="1" if pocl_cache else "0")
    out = subprocess.run([sys.executable, "-c", FIRST_RENDER, path], env=env, check=True, capture_output=True, text=True)
    return float(out.stdout)


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    path = argv[0] if argv else str(Path(__file__).resolve().parent.parent / "scenes" / "tp02.toml")
    for size, rounds in ((512, 40), (2048, 15)):
        median, best = warm(path, size, rounds)
        print(f"warm render {size}x{size}: median {median * 1e3:.2f} ms, min {best * 1e3:.2f} ms ({rounds} renders)")
    runs = int(os.environ.get("PYCLRAY_QUICK_RUNS", "5"))
    cold, disk, both = [], [], []
    for _ in range(runs):  # each run with new caches: empty, then pyclray's, then both
        with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as pocl:
            cold.append(first_render(path, cache, pocl, pocl_cache=False))
            disk.append(first_render(path, cache, pocl, pocl_cache=False))
            first_render(path, cache, pocl, pocl_cache=True)  # fills PoCL's own cache
            both.append(first_render(path, cache, pocl, pocl_cache=True))

    def spread(times):
        times = sorted(t * 1e3 for t in times)
        return f"median {statistics.median(times):.0f} ms (min {times[0]:.0f}, max {times[-1]:.0f})"

    print(f"first render of a new process, {runs} runs each: no cache {spread(cold)}; pyclray's disk cache "
          f"only {spread(disk)}; pyclray's and PoCL's caches {spread(both)}")


if __name__ == "__main__":
    main()
