"""cast's kernels A against B in one process, on bench.meshes' incoherent rays (issue 23).

    python -m bench.cast_ab A_KERNELS [B_KERNELS] [--bunny PATH] [--rounds 10] [--meshes bunny,1M]

A_KERNELS, B_KERNELS: two pyclray/engine/kernels/ folders (B: this checkout's), e.g. a `git worktree`
of main's beside a branch's. Only the OpenCL sources differ between A and B: the host code, and so the
buffers' layout, is this checkout's, so it measures kernel changes that keep the layout. Each
side's program is built from its folder (engine/launch/programs.py reads its sources from kernel_dir(), and
cast's launch asks run.kernel_for: both are pointed at the side's build); the two then alternate
in blocks of 3 calls (one untimed call and a short pause at each switch), and the medians of each
call's process CPU time are compared. Before timing, every result of both (depth, normal, id at fp32
and fp64, occluded) is compared bit for bit.

Why in one process: on the shared 2-core machine, separate processes' ratios to Open3D moved by
10% between runs of the same code, more than most kernel changes measured; the same process
alternating A and B every 3 calls moves by about 3%.
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

import pyclray
from pyclray.engine.queries import cast as cast_module
from pyclray.engine.launch import programs
from pyclray.engine.launch import run

from .meshes import camera_for, meshes


def incoherent_rays(mesh, count=100_000):
    """bench.meshes' incoherent rays: origins uniform in the mesh's box, directions uniform."""
    rng = np.random.default_rng(1)
    lo, hi = mesh.box()
    origins = rng.uniform(lo, hi, (count, 3))
    directions = rng.normal(size=(count, 3))
    return origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)


def switcher(folders: dict):
    """(use, kernel_for): use(side) makes the following casts run side's kernels, built from its
    folder once per variant."""
    built, current = {}, [next(iter(folders))]
    own_kernel_for, own_kernel_dir = cast_module.kernel_for, programs.kernel_dir

    def kernel_for(ctx, variant):
        key = (current[0], variant)
        if key not in built:
            programs.kernel_dir = lambda: Path(folders[current[0]])
            programs.clear()
            try:
                built[key] = own_kernel_for(ctx, variant)
            finally:
                programs.kernel_dir = own_kernel_dir
                programs.clear()
        return built[key]

    cast_module.kernel_for = run.kernel_for = kernel_for

    def use(side):
        current[0] = side
    return use


def compare(scene, origins, directions, use, rounds: int) -> dict:
    results = {}
    for side in "AB":
        use(side)
        out = []
        for precision in ("fp32", "fp64"):
            frame = pyclray.cast(scene, origins, directions, precision=precision)
            out += [frame[k] for k in ("depth", "normal", "id")]
        out.append(pyclray.occluded(scene, origins, directions))
        results[side] = out
    same = all(np.array_equal(a.view(np.uint8), b.view(np.uint8)) for a, b in zip(results["A"], results["B"]))
    cpu = {"A": [], "B": []}
    for r in range(rounds):
        for side in ("AB" if r % 2 == 0 else "BA"):
            use(side)
            time.sleep(0.03)
            pyclray.cast(scene, origins, directions)
            for _ in range(3):
                start = time.process_time()
                pyclray.cast(scene, origins, directions)
                cpu[side].append(time.process_time() - start)
    return {"A": float(np.median(cpu["A"])) * 1e3, "B": float(np.median(cpu["B"])) * 1e3, "same": same}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("a", help="kernels/ folder of A")
    parser.add_argument("b", nargs="?", default=str(programs.kernel_dir()), help="kernels/ folder of B")
    parser.add_argument("--bunny", help="the 75,408-triangle bunny00.off of CGAL's demo data")
    parser.add_argument("--rounds", type=int, default=10)
    parser.add_argument("--meshes", default="bunny,1M")
    args = parser.parse_args(argv)
    use = switcher({"A": args.a, "B": args.b})
    for label, mesh in meshes(args.bunny).items():
        if label not in args.meshes.split(","):
            continue
        origins, directions = incoherent_rays(mesh)
        r = compare(camera_for(mesh, 64), origins, directions, use, args.rounds)
        print(f"{label}: A {r['A']:.1f} ms  B {r['B']:.1f} ms  CPU B/A {r['B'] / r['A']:.3f}  "
              f"same bits {r['same']}  load {os.getloadavg()[0]:.2f}", flush=True)


if __name__ == "__main__":
    main()
