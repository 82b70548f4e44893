"""Quick figures without pytest-benchmark: warm render times of a scene, and the first render of a
new process with no cache, with pyclray's disk cache only, and with both caches warm.

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


def first_render(path: str, cache: str, pocl_cache: bool) -> float:
    env = dict(os.environ, PYCLRAY_CACHE_DIR=cache, POCL_KERNEL_CACHE="1" if pocl_cache else "0")
    out = subprocess.run([sys.executable, "-c", FIRST_RENDER, path], env=env, check=True, capture_output=True, text=True)
    return float(out.stdout)


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    path = argv[0] if argv else str(Path(__file__).resolve().parent.parent / "scenes" / "tp02.toml")
    for size, rounds in ((512, 40), (2048, 15)):
        median, best = warm(path, size, rounds)
        print(f"warm render {size}x{size}: median {median * 1e3:.2f} ms, min {best * 1e3:.2f} ms ({rounds} renders)")
    with tempfile.TemporaryDirectory() as cache:
        cold = first_render(path, cache, pocl_cache=False)
        disk = first_render(path, cache, pocl_cache=False)
        first_render(path, cache, pocl_cache=True)  # fills PoCL's own cache
        both = first_render(path, cache, pocl_cache=True)
    print(f"first render of a new process: no cache {cold * 1e3:.0f} ms, pyclray's disk cache only "
          f"{disk * 1e3:.0f} ms, pyclray's and PoCL's caches {both * 1e3:.0f} ms")


if __name__ == "__main__":
    main()
