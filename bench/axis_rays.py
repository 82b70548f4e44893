"""Axis-aligned rays against the same rays tilted off the axis (issue 38: a ray along an axis once
entered every box on one side of it in the flat axes' slab tests, kernels/bvh_ray.h's box_ray).

    python -m bench.axis_rays [--count 100000] [--rounds 3] [--block 3] [--precision fp32]

Mesh: bench.meshes' bunny (80,000 triangles). Rays (seeded): COUNT origins uniform in the mesh's
box, moved to 10% of its size before its low x face, direction (1, 0, 0), and the same rays with
direction (1, 0.01, 0.01) (normalized by the queries). Per query (count_hits, all_hits, cast,
occluded) the medians of the two ray sets, timed in rotating blocks (bench.open3d_compare.blocks),
and their ratio (axis / tilted: about 1 where axis-aligned rays cost what any ray costs).
"""
from __future__ import annotations

import argparse
import os

import numpy as np

import pyclray

from .meshes import meshes
from .open3d_compare import blocks

QUERIES = ("count_hits", "all_hits", "cast", "occluded")


def rays(mesh, count, rng):
    lo, hi = np.asarray(mesh.box())
    origins = rng.uniform(lo, hi, (count, 3))
    origins[:, 0] = lo[0] - 0.1 * float(np.max(hi - lo))
    axis = np.tile([1.0, 0.0, 0.0], (count, 1))
    return origins, axis, axis + np.array([0.0, 0.01, 0.01])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=100_000)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--block", type=int, default=3)
    parser.add_argument("--precision", default="fp32", choices=("fp32", "fp64"))
    args = parser.parse_args(argv)
    mesh = meshes(None)["bunny"]
    origins, axis, tilted = rays(mesh, args.count, np.random.default_rng(0))
    scene = pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(8, 8), (mesh,))
    print(f"load: {os.getloadavg()[0]:.2f}  lanes: {os.environ.get('PYCLRAY_LANES', 'default')}  "
          f"precision: {args.precision}  rays: {args.count}")
    with pyclray.prepare(scene, precision=args.precision) as tracer:
        for query in QUERIES:
            call = getattr(tracer, query)
            medians = blocks({"axis": lambda: call(origins, axis), "tilted": lambda: call(origins, tilted)},
                             args.rounds, args.block)
            axis_ms, tilted_ms = medians["axis"]["median"], medians["tilted"]["median"]
            print(f"{query:>10}: axis {axis_ms:9.1f} ms  tilted {tilted_ms:7.1f} ms  ratio {axis_ms / tilted_ms:7.1f}")


if __name__ == "__main__":
    main()
