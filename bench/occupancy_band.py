"""What occupancy's exact band costs next to a surface (docs/benchmarks.md, "Exact sides next to
the surface"): one checkout's times, run for each of two checkouts in turn (main's and a
branch's: --pyclray names the checkout whose pyclray is timed, default this one's):

    python -m bench.occupancy_band [--pyclray CHECKOUT] [--points 100000] [--bunny PATH]

The bunny of bench.meshes, its near points of bench.points (within 1% of the size), fp32: the
medians of the count kernel from points alone (engine.queries.closest.count_from_points, its
surface variant, process CPU time, 4x the points), and of Tracer.occupancy (parity, winding) and
signed_distance (parity) (wall), each after two untimed calls (the fp32 handle's fp64 twin is made
at the first). Also how many points the count leaves undecided (3) at each precision.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np


def median_ms(call, repeats: int, clock=time.perf_counter) -> float:
    call()
    call()
    times = []
    for _ in range(repeats):
        start = clock()
        call()
        times.append(clock() - start)
    return float(np.median(times)) * 1e3


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--bunny", default=None)
    parser.add_argument("--pyclray", default=None, help="the checkout whose pyclray is timed")
    args = parser.parse_args()
    if args.pyclray:  # before anything imports pyclray (bench.meshes does)
        sys.path.insert(0, os.path.abspath(args.pyclray))
    import pyclray
    from pyclray.engine.queries import closest

    from .meshes import meshes
    from .points import near_points

    mesh = meshes(args.bunny)["bunny"]
    lo, hi = np.asarray(mesh.box())
    scene = pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(8, 8), (mesh,))
    print(f"load before: {os.getloadavg()[0]:.2f}; pyclray from {os.path.dirname(pyclray.__file__)}")
    with pyclray.prepare(scene) as tracer:
        near = near_points(tracer, lo, hi, args.points, np.random.default_rng(0))
        many = near_points(tracer, lo, hi, 4 * args.points, np.random.default_rng(1))
        closed = tracer.mesh_handle(closed=True)
        directions = closest.parity_directions(closed, many)
        surface = closest._surface_arguments(closed)
        counts = {"count from points (CPU)": median_ms(lambda: closest.count_from_points(closed, many, directions, surface), 12,
                                                       time.process_time),
                  "occupancy parity": median_ms(lambda: tracer.occupancy(near), 21),
                  "signed_distance parity": median_ms(lambda: tracer.signed_distance(near), 7),
                  "occupancy winding": median_ms(lambda: tracer.occupancy(near, sign="winding"), 7)}
        for name, value in counts.items():
            print(f"| {name} | {value:.1f} ms |")
        on = closest.count_from_points(closed, many, directions, surface)[1]
        print(f"undecided of {len(many):,} (fp32): {int(np.count_nonzero(on == 3))}")
    print(f"load after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
