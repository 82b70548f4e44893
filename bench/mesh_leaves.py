"""Triangles per BVH leaf (pyclray.Mesh.leaf_size) against the render's cost.

    python -m bench.mesh_leaves [--bunny PATH] [--sizes 4 6 7] [--rounds 3]

The meshes and cameras of bench.meshes (the bunny, 1,000,000 triangles); per leaf size the scene is
prepared anew, then a 512x512 render of depth, normal, id and primitive is timed 5 times, the sizes
rotating over the rounds. Reported: the median process CPU time (all of PoCL's threads together),
which another process's load on this shared machine does not inflate as it does wall time; each size
as a ratio to the first (the baseline, LEAF_SIZE = 4 of engine/bvh.py). The wide BVH's leaf code
holds at most 7 (engine/bvh_wide.py)."""
from __future__ import annotations

import argparse
import time

import numpy as np

import pyclray

from .meshes import camera_for, meshes

AOVS = ("depth", "normal", "id", "primitive")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bunny", default=None)
    parser.add_argument("--sizes", type=int, nargs="+", default=[4, 6, 7])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    scenes = {name: camera_for(mesh, 512) for name, mesh in meshes(args.bunny).items()}
    times: dict = {}
    default = pyclray.Mesh.leaf_size
    try:
        for _ in range(args.rounds):
            for size in args.sizes:
                pyclray.Mesh.leaf_size = size
                for name, scene in scenes.items():
                    pyclray.clear_cache()
                    pyclray.render(scene, aovs=AOVS)  # prepared with this leaf size, program built
                    time.sleep(0.05)
                    for _ in range(5):
                        start = time.process_time()
                        pyclray.render(scene, aovs=AOVS)
                        times.setdefault((name, size), []).append(time.process_time() - start)
    finally:
        pyclray.Mesh.leaf_size = default
    for name in scenes:
        base = np.median(times[(name, args.sizes[0])])
        for size in args.sizes:
            median = np.median(times[(name, size)])
            print(f"{name:6s} leaf {size:2d}: {1000 * median:7.1f} ms CPU  ({median / base:.2f} of leaf {args.sizes[0]})")


if __name__ == "__main__":
    main()
