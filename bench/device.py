"""pyclray alone on one OpenCL device: issue 23's and 25's cases, for a device where Open3D and
Mitsuba are not at hand (a lent GPU machine, whose figures go beside the CPU ratios of
bench.meshes and bench.secondary, never into them).

    PYOPENCL_CTX=0 .venv/bin/python -m bench.device [--rounds 3] [--block 5] [--quick]

Cases (the scenes and rays of bench.meshes and bench.secondary, so figures line up):
- meshes (the subdivided bunny, 80,000 triangles, and the 1,000,000-triangle perturbed sphere): the
  first render after clear_cache() (preparation and BVH build included), primary rays 512x512
  (depth, normal, id, primitive), cast and occluded of 100,000 incoherent rays;
- 16,384 and 100,000 spheres + ground: cast and occluded of the box and view ray sets;
- shading 512x512 at 100,000 spheres with a point light, with and without shadows.
Each case's calls are timed in blocks (open3d_compare.blocks), medians in ms; the last line is the
device and the phases' times.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import pyclray
from pyclray.engine.opencl.device import context_for, describe

from . import scale
from .meshes import camera_for, incoherent_rays, meshes
from .open3d_compare import blocks
from .secondary import lit_scenes, view_rays

AOVS = ("depth", "normal", "id", "primitive")


def mesh_rows(rounds: int, block: int) -> list[tuple[str, float]]:
    rows = []
    for label, mesh in meshes(None).items():
        scene = camera_for(mesh, 512)
        pyclray.render(scene, aovs=AOVS)  # the program compiled (and cached) before the build's timing
        builds = []
        for _ in range(3):
            pyclray.clear_cache()
            start = time.perf_counter()
            pyclray.render(scene, aovs=AOVS)
            builds.append((time.perf_counter() - start) * 1e3)
        rows.append((f"{label}: first render (build included)", float(np.median(builds))))
        origins, directions = incoherent_rays(mesh)
        timed = blocks({"primary": lambda: pyclray.render(scene, aovs=AOVS),
                        "cast": lambda: pyclray.cast(scene, origins, directions),
                        "occluded": lambda: pyclray.occluded(scene, origins, directions)}, rounds, block)
        rows += [(f"{label}: primary rays 512x512", timed["primary"]["median"]),
                 (f"{label}: cast 100,000 incoherent rays", timed["cast"]["median"]),
                 (f"{label}: occluded 100,000 incoherent rays", timed["occluded"]["median"])]
    return rows


def sphere_rows(rounds: int, block: int, counts) -> list[tuple[str, float]]:
    rows = []
    sets = {"box": scale.random_rays(100_000), "view": view_rays(100_000)}
    for count in counts:
        scene = scale.scene(count)
        for name, (origins, directions) in sets.items():
            timed = blocks({"cast": lambda: pyclray.cast(scene, origins, directions),
                            "occluded": lambda: pyclray.occluded(scene, origins, directions)}, rounds, block)
            rows += [(f"{count:,} spheres + ground, {name} rays: {query} 100,000", timed[query]["median"])
                     for query in ("cast", "occluded")]
    _, lit, flat = lit_scenes(counts[-1])
    timed = blocks({"shadows": lambda: pyclray.render(lit, aovs=("shaded",)),
                    "no shadows": lambda: pyclray.render(flat, aovs=("shaded",))}, rounds, block)
    rows += [(f"shaded 512x512, {counts[-1]:,} spheres, {k}", timed[k]["median"]) for k in ("shadows", "no shadows")]
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--block", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="spheres: 16,384 only")
    args = parser.parse_args(argv)
    device = describe(context_for(None).device)
    phases = {}
    start = time.perf_counter()
    rows = mesh_rows(args.rounds, args.block)
    phases["meshes"] = time.perf_counter() - start
    start = time.perf_counter()
    rows += sphere_rows(args.rounds, args.block, (16_384,) if args.quick else (16_384, 100_000))
    phases["spheres"] = time.perf_counter() - start
    width = max(len(name) for name, _ in rows)
    for name, ms in rows:
        print(f"{name:{width}s} {ms:9.2f} ms", flush=True)
    print(f"device {device}; " + ", ".join(f"{k} {v:.0f} s" for k, v in phases.items()))


if __name__ == "__main__":
    main()
