"""The grazing ground of issue 42, item 1: fp32 render and cast of the same float64 pixel rays
against the float64 oracle (docs/exactness.md, item 9).

    .venv/bin/python bench/grazing.py [--height 1.5] [--far 1000]

640x480, K = [[525, 0, 320], [0, 525, 240], [0, 0, 1]], an OpenCV pose pitched 20 degrees down at
``height`` over the plane y = 0 (the horizon in view); prints, over the ground pixels nearer than
``far``, the largest relative depth error (where, and at which |cos|) and how many pixels err by
more than 1e-6, for render and for cast.
"""
from __future__ import annotations

import argparse
import math

import numpy as np

import pyclray
from pyclray.reference import oracle


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--height", type=float, default=1.5)
    parser.add_argument("--far", type=float, default=1000.0)
    parser.add_argument("--precision", default="fp32", choices=("fp32", "fp64"))
    args = parser.parse_args(argv)
    pitch = math.radians(20.0)
    forward = np.array([math.cos(pitch), -math.sin(pitch), 0.0])
    right = np.array([0.0, 0.0, -1.0])
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, np.cross(forward, right), forward, (0.3, args.height, 0.7)
    camera = pyclray.Camera.from_intrinsics([[525, 0, 320], [0, 525, 240], [0, 0, 1]], pose)
    scene = pyclray.Scene(camera, pyclray.Image(640, 480), [pyclray.Plane(normal=(0, 1, 0), offset=0.0)])
    origins, directions = (x.reshape(-1, 3) for x in camera.rays(640, 480))
    truth = oracle.trace(scene, origins, directions, aovs=("depth", "id"))["depth"]
    ground = np.isfinite(truth) & (truth < args.far)
    cos = np.abs(directions[:, 1])
    results = {"render": pyclray.render(scene, aovs=("depth",), precision=args.precision)["depth"].reshape(-1),
               "cast": pyclray.cast(scene, origins, directions, aovs=("depth",), precision=args.precision)["depth"]}
    print(f"{ground.sum()} ground pixels nearer than {args.far:g} ({args.precision})")
    for name, depth in results.items():
        relative = np.abs(depth[ground].astype(np.float64) - truth[ground]) / truth[ground]
        worst = np.argmax(relative)
        print(f"{name}: max relative depth error {relative[worst]:.3g} (t = {truth[ground][worst]:.1f}, "
              f"|cos| {cos[ground][worst]:.4f}); worse than 1e-6: {(relative > 1e-6).sum()} pixels")


if __name__ == "__main__":
    main()
