"""A distorted camera against a pinhole of the same K and pose (issue 39's target: a distorted
1024x768 view costs <= 1.2x a pinhole view of the same scene, after the first).

    python -m bench.lenses            # tp02 and 100,000 spheres, 1024x768, depth/normal/id
    python -m bench.lenses --quick    # tp02 only

Both views render on one handle (pyclray.prepare) in this process, in blocks (bench/views.py's
rule: each case a block of calls on its own, a pause at each switch, rounds in rotating order, the
median of all timed calls), timed by the wall clock and by the process's CPU time. The first distorted view solves the lens's inverse per pixel (float64,
on the host) and uploads its table of rays: that one-off cost is printed apart, not in the ratio.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import pyclray

from . import scale

PAUSE = 0.5
ROUNDS = 5
BLOCK = 12  # timed calls per block


def blocks(cases: dict) -> dict:
    """Median seconds per call of each case, wall clock and the process's CPU time (all of PoCL's
    threads: on a loaded machine the CPU time is what the call costs, the wall clock what it waited),
    in blocks: each case a block of calls on its own, a pause at each switch, rounds in rotating order."""
    wall = {name: [] for name in cases}
    cpu = {name: [] for name in cases}
    names = list(cases)
    for r in range(ROUNDS):
        for name in names[r % len(names):] + names[: r % len(names)]:
            for k in range(2):  # warm
                cases[name](k)
            for k in range(BLOCK):
                start, start_cpu = time.perf_counter(), time.process_time()
                cases[name](k)
                wall[name].append(time.perf_counter() - start)
                cpu[name].append(time.process_time() - start_cpu)
            time.sleep(PAUSE)
    return {name: (statistics.median(wall[name]), statistics.median(cpu[name])) for name in names}

WIDTH, HEIGHT = 1024, 768
AOVS = ("depth", "normal", "id")
K = [[800.0, 0.0, 511.5], [0.0, 800.0, 383.5], [0.0, 0.0, 1.0]]
DISTORTION = [-0.28, 0.07, 0.0002, -0.0001, 0.0]  # the contract's example lens: a strong barrel


def cameras(eye, target):
    """(pinhole, distorted): the same K and pose (OpenCV's axes from a look-at), the second with the lens."""
    look = pyclray.Camera(eye, target)
    pose = look.pose()
    return (pyclray.Camera.from_intrinsics(K, pose, WIDTH, HEIGHT),
            pyclray.Camera.from_intrinsics(K, pose, WIDTH, HEIGHT, distortion=DISTORTION))


def compare(scene: pyclray.Scene, label: str) -> dict:
    scene = scene.with_size(WIDTH, HEIGHT)
    pinhole, distorted = cameras(scene.camera.eye, getattr(scene.camera, "target", None) or (0.0, 0.0, 0.0))
    tracer = pyclray.prepare(scene)
    tracer.render(camera=pinhole, aovs=AOVS)
    start = time.perf_counter()
    tracer.render(camera=distorted, aovs=AOVS)  # the lens's inverse solved, its table uploaded, the program built
    first = time.perf_counter() - start
    result = blocks({"pinhole": lambda k: tracer.render(camera=pinhole, aovs=AOVS),
                     "distorted": lambda k: tracer.render(camera=distorted, aovs=AOVS)})
    (wall_p, cpu_p), (wall_d, cpu_d) = result["pinhole"], result["distorted"]
    print(f"  {label} {WIDTH}x{HEIGHT}: pinhole {1e3 * wall_p:.1f} ms ({1e3 * cpu_p:.1f} ms CPU), distorted "
          f"{1e3 * wall_d:.1f} ms ({1e3 * cpu_d:.1f} ms CPU): distorted / pinhole {wall_d / wall_p:.2f} wall, "
          f"{cpu_d / cpu_p:.2f} CPU (target <= 1.2); the first distorted view {1e3 * first:.0f} ms")
    tracer.close()
    return {"pinhole_ms": 1e3 * wall_p, "distorted_ms": 1e3 * wall_d, "ratio": wall_d / wall_p, "cpu_ratio": cpu_d / cpu_p,
            "first_ms": 1e3 * first}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="tp02 only")
    args = parser.parse_args(argv)
    from pathlib import Path

    scenes = Path(__file__).resolve().parent.parent / "scenes"
    compare(pyclray.load_scene(scenes / "tp02.toml"), "tp02")
    if not args.quick:
        compare(scale.scene(100_000), "100,000 spheres")


if __name__ == "__main__":
    main()
