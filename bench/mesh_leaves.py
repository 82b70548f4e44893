"""Triangles per BVH leaf and the SAH's node cost against the render's cost.

    python -m bench.mesh_leaves [--bunny PATH] [--sizes 4 6 7] [--costs 4] [--rounds 3]

The meshes and cameras of bench.meshes (the bunny, 1,000,000 triangles); per leaf size and node
cost the scene is prepared anew, then a 512x512 render of depth, normal, id and primitive is timed 5
times, the variants rotating over the rounds. Reported: the median process CPU time (all of PoCL's
threads together), which another process's load on this shared machine does not inflate as it does
wall time; each variant as a ratio to the first (the baseline: leaves of 7, a node's visit 4 shape
tests, engine/bvh/tree.py's SCENE_LEAF_SIZE and SCENE_TRAVERSAL). The wide BVH's leaf code holds at most 7
(engine/bvh/wide.py).

A scene of SAH_FROM shapes or more (both meshes) takes its leaf size and node cost from
engine/bvh/scene.py's SCENE_LEAF_SIZE (a floor over Mesh.leaf_size) and SCENE_TRAVERSAL: both are
set here for each variant, and Mesh.leaf_size with them (smaller scenes)."""
from __future__ import annotations

import argparse
import time

import numpy as np

import pyclray
from pyclray.engine.bvh import scene as scene_bvh

from .meshes import camera_for, meshes

AOVS = ("depth", "normal", "id", "primitive")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bunny", default=None)
    parser.add_argument("--sizes", type=int, nargs="+", default=[7, 4, 6])
    parser.add_argument("--costs", type=float, nargs="+", default=[scene_bvh.SCENE_TRAVERSAL])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    scenes = {name: camera_for(mesh, 512) for name, mesh in meshes(args.bunny).items()}
    variants = [(size, cost) for cost in args.costs for size in args.sizes]
    times: dict = {}
    saved = pyclray.Mesh.leaf_size, scene_bvh.SCENE_LEAF_SIZE, scene_bvh.SCENE_TRAVERSAL
    try:
        for _ in range(args.rounds):
            for size, cost in variants:
                pyclray.Mesh.leaf_size = scene_bvh.SCENE_LEAF_SIZE = size
                scene_bvh.SCENE_TRAVERSAL = cost
                for name, scene in scenes.items():
                    pyclray.clear_cache()
                    pyclray.render(scene, aovs=AOVS)  # prepared with this tree, program built
                    time.sleep(0.05)
                    for _ in range(5):
                        start = time.process_time()
                        pyclray.render(scene, aovs=AOVS)
                        times.setdefault((name, size, cost), []).append(time.process_time() - start)
    finally:
        pyclray.Mesh.leaf_size, scene_bvh.SCENE_LEAF_SIZE, scene_bvh.SCENE_TRAVERSAL = saved
    for name in scenes:
        base = np.median(times[(name, *variants[0])])
        for size, cost in variants:
            median = np.median(times[(name, size, cost)])
            print(f"{name:6s} leaf {size:2d} node cost {cost:4.1f}: {1000 * median:7.1f} ms CPU  "
                  f"({median / base:.2f} of the first)")


if __name__ == "__main__":
    main()
