"""The host path of count_hits and all_hits on the GPU class (issue 41): a prepared handle's
count_hits and all_hits (depth, id, primitive) of 1, 1,000 and 100,000 incoherent rays on the bunny
(bench.meshes' 80,000-triangle subdivided scan, closed), and its point queries (distance,
occupancy and signed distance by parity, of 1,000 and 100,000 points uniform in its box), the CPU's host path ($PYCLRAY_GPU_CLASS=0: the
host's checks, numba's ray order of large batches, the hits' rows gathered in numpy) beside the GPU
class's ($PYCLRAY_GPU_CLASS=1: engine/queries/cast_device.py's HitRays, all_hits_device), on this
machine's PoCL, in rotating blocks in one process (bench.open3d_compare.blocks: medians of wall and
process CPU time, ms).

    .venv/bin/python -m bench.hits_host [--rounds 3] [--block 10] [--sizes 1,1000,100000] [--points 1000,100000]

On PoCL the GPU class's path pays for what a GPU does cheaply (a launch each of the check, the
query's kernel and the rows' copy: 0.02-0.04 ms each here) and skips the ray order, which a CPU
device's large batches of hit queries take; the figures say what the host path costs, not a GPU's.
The point queries on the GPU class take no Morton order, no parity grid and numpy's nearest faces
for their parity rays (engine/queries/closest.py), counted through count_hits' device path.
The machine is shared: compare the two paths' figures at each size, and note `uptime`.
"""
from __future__ import annotations

import argparse
import os

import numpy as np

import pyclray

from .cast_host import bunny
from .meshes import incoherent_rays
from .open3d_compare import blocks


def on_path(switch: str, call):
    def run():
        os.environ["PYCLRAY_GPU_CLASS"] = switch
        call()
    return run


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--block", type=int, default=10)
    parser.add_argument("--sizes", default="1,1000,100000")
    parser.add_argument("--points", default="1000,100000")
    args = parser.parse_args(argv)
    mesh = bunny()
    scene = pyclray.Scene(pyclray.Camera((0, 0, 1), (0, 0, 0)), pyclray.Image(8, 8), (mesh,))
    print(f"{os.uname().nodename}: {open('/proc/loadavg').read().split()[:3]} (load)")
    print("| rays | query | CPU host path | GPU class | CPU host path, CPU | GPU class, CPU |")
    print("|---|---|---|---|---|---|")
    with pyclray.prepare(scene) as handle:
        for size in (int(s) for s in args.sizes.split(",")):
            origins, directions = incoherent_rays(mesh, size)
            for query, call in (("count_hits", lambda: handle.count_hits(origins, directions)),
                                ("all_hits", lambda: handle.all_hits(origins, directions))):
                block = max(1, args.block if size < 10_000 else args.block // 5)
                result = blocks({"0": on_path("0", call), "1": on_path("1", call)}, args.rounds, block)
                print(f"| {size:,} | {query} | {result['0']['median']:.3f} | {result['1']['median']:.3f} | "
                      f"{result['0']['cpu']:.3f} | {result['1']['cpu']:.3f} |")
        lo, hi = mesh.box()
        for size in (int(s) for s in args.points.split(",") if s):
            p = np.random.default_rng(2).uniform(lo, hi, (size, 3))
            for query, call in (("distance", lambda: handle.distance(p)),
                                ("occupancy", lambda: handle.occupancy(p)),
                                ("signed_distance", lambda: handle.signed_distance(p))):
                block = max(1, args.block if size < 10_000 else args.block // 5)
                result = blocks({"0": on_path("0", call), "1": on_path("1", call)}, args.rounds, block)
                print(f"| {size:,} points | {query} | {result['0']['median']:.3f} | {result['1']['median']:.3f} | "
                      f"{result['0']['cpu']:.3f} | {result['1']['cpu']:.3f} |")
    os.environ.pop("PYCLRAY_GPU_CLASS", None)


if __name__ == "__main__":
    main()
