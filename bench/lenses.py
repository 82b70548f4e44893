"""A distorted camera against a pinhole of the same K and pose (issue 39's target: a distorted
1024x768 view costs <= 1.2x a pinhole view of the same scene, after the first).

    python -m bench.lenses            # tp02 and 100,000 spheres, 1024x768, depth/normal/id
    python -m bench.lenses --quick    # tp02 only

Both views render on one handle (pyclray.prepare) in this process, in blocks (bench/views.py's
rule: each case a block of calls on its own, a pause at each switch, rounds in rotating order, the
median of all timed calls). The first distorted view solves the lens's inverse per pixel (float64,
on the host) and uploads its table of rays: that one-off cost is printed apart, not in the ratio.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import pyclray

from . import scale
from .views import blocks

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
    ratio = result["distorted"] / result["pinhole"]
    print(f"  {label} {WIDTH}x{HEIGHT}: pinhole {1e3 * result['pinhole']:.1f} ms, distorted {1e3 * result['distorted']:.1f} ms: "
          f"distorted / pinhole {ratio:.2f} (target <= 1.2); the first distorted view {1e3 * first:.0f} ms")
    tracer.close()
    return {"pinhole_ms": 1e3 * result["pinhole"], "distorted_ms": 1e3 * result["distorted"], "ratio": ratio,
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
