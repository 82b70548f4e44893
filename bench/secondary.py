"""Secondary rays (issue 25): cast and occluded of 100,000 random rays against Open3D (Embree) on
two ray sets, and shading with shadows against the unshadowed render and Mitsuba llvm's direct
integrator (one sample, one point light), on the scenes of bench/scale.py.

Ray sets: "box" (bench/scale.py's random_rays: origins anywhere in the spheres' box, directions
uniform) and "view" (origins near the camera, directions N(0, 0.6) around the view axis, as issue
25 measured). Timings are medians of blocks of calls, the systems taking turns with short pauses
(open3d_compare.blocks); the ratio is Open3D's time over pyclray's (> 1: pyclray faster). The casts
also report each system's median process CPU time per call (both use the machine's cores: on a
shared machine that ratio moves less than the wall clock's; the issue's targets are wall clock).

Mitsuba is timed apart, warm: its scene of 100,000 sphere shapes, each with its own BSDF, takes
tens of seconds per render, so it is loaded, rendered once untimed (Dr.Jit traces and compiles its
kernels in that first call; it is reported as "first call") and then timed over --mitsuba-calls
renders, which reuse the compiled kernels.

    .venv/bin/python -m bench.secondary [--rounds 4 --block 3] [--no-mitsuba] [--mitsuba-calls 2]
    .venv/bin/python -m bench.secondary --flag-ab PYCLRAY_OLD_PRETEST --rounds 6   (a kernel change, A/B)
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time

import numpy as np

import pyclray

from . import scale
from .open3d_compare import blocks, once


def view_rays(count: int, seed: int = 2):
    """Origins within 0.5 of the camera, directions N(0, 0.6) around the unit view axis."""
    rng = np.random.default_rng(seed)
    eye, target = np.array(scale.EYE), np.array(scale.TARGET)
    axis = (target - eye) / np.linalg.norm(target - eye)
    origins = eye + rng.uniform(-0.5, 0.5, (count, 3))
    directions = axis + rng.normal(0.0, 0.6, (count, 3))
    return origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)


def with_cpu(systems: dict) -> tuple[dict, dict]:
    """(the systems, each call's process CPU time in ms by name): the same calls, each also timed by
    time.process_time (the process's threads together: PoCL's, Open3D's TBB workers), a figure
    that a shared machine's load moves less than the wall clock. As blocks times them: the first
    call after a switch of system (blocks' untimed warm-up) is not counted."""
    cpu = {name: [] for name in systems}
    last = [None]

    def timed(name, function):
        def call():
            start = time.process_time()
            function()
            if last[0] == name:
                cpu[name].append((time.process_time() - start) * 1e3)
            last[0] = name
        return call

    return {name: timed(name, function) for name, function in systems.items()}, cpu


def casts(rounds: int, block: int) -> dict:
    import open3d as o3d

    out = {}
    sets = {"box": scale.random_rays(100_000), "view": view_rays(100_000)}
    for count in (16_384, 100_000):
        scene = scale.scene(count)
        o3d_scene, _ = scale.open3d_scene(count)
        for name, (origins, directions) in sets.items():
            rays = o3d.core.Tensor(np.hstack([origins, directions]).astype(np.float32))
            systems, cpu = with_cpu({
                "pyclray cast": lambda: pyclray.cast(scene, origins, directions),
                "open3d cast_rays": lambda: o3d_scene.cast_rays(rays),
                "pyclray occluded": lambda: pyclray.occluded(scene, origins, directions),
                "open3d test_occlusions": lambda: o3d_scene.test_occlusions(rays),
            })
            timing = blocks(systems, rounds, block)
            for system, values in cpu.items():
                timing[system]["cpu"] = float(np.median(values))
            out[f"{count:,} spheres + ground, {name} rays"] = timing
        del o3d_scene
    return out


def lit_scenes(count: int = 100_000):
    """(the point light, the lit scene with shadows, the same without): bench/scale.py's spheres."""
    light = pyclray.PointLight((6.0, 14.0, 10.0), (300.0, 300.0, 300.0))
    lit = dataclasses.replace(scale.scene(count), lights=(light,))
    return light, lit, dataclasses.replace(lit, shading=dataclasses.replace(lit.shading, shadows=False))


def shading(rounds: int, block: int, mitsuba_calls: int) -> dict:
    light, lit, unshadowed = lit_scenes()
    systems = {
        "pyclray shaded, shadows": lambda: pyclray.render(lit, aovs=("shaded",)),
        "pyclray shaded, no shadows": lambda: pyclray.render(unshadowed, aovs=("shaded",)),
    }
    name = "shaded 512x512, ground + 100,000 spheres, one point light"
    out = {name: blocks(systems, rounds, block)}
    if mitsuba_calls:
        out[name].update(mitsuba_direct(lit, light, mitsuba_calls))
    return out


def mitsuba_direct(lit, light, calls: int) -> dict:
    """Mitsuba llvm_ad_rgb's direct integrator (1 spp) on the scene's diffuse version: the first
    render (tracing and compiling its kernels) and the median of `calls` warm renders after it."""
    from pyclray.reference.mitsuba import import_mitsuba
    from pyclray.reference.validation.shaded import diffuse_version, direct_scene_dict

    mi = import_mitsuba("llvm_ad_rgb")
    mi_scene = mi.load_dict(direct_scene_dict(diffuse_version(lit), light, "llvm_ad_rgb"), optimize=False)
    first = once(lambda: mi.render(mi_scene, spp=1).numpy())
    times = [once(lambda: mi.render(mi_scene, spp=1).numpy()) for _ in range(calls)]
    return {"mitsuba llvm direct, 1 spp, first call": {"median": first, "q1": first, "q3": first, "n": 1},
            "mitsuba llvm direct, 1 spp, warm": {"median": float(np.median(times)), "q1": min(times),
                                                 "q3": max(times), "n": calls}}


def flag_ab(flag: str, rounds: int) -> None:
    """A kernel change measured against the code before it in one process, where a shared machine's
    load moves both alike (fresh processes taking turns moved by 10% between rounds either way): the
    kernels built with and without -D<flag> (the old code kept under #ifdef <flag> while measuring)
    take turns on the same calls, each switch rebuilding from the disk cache; medians of wall and
    process CPU ms per call. A 3% change showed in every case this way (docs/benchmarks.md)."""
    from pyclray.engine.launch import programs

    base = list(programs.BUILD_OPTIONS)
    sets = {"view": view_rays(100_000), "box": scale.random_rays(100_000)}
    for count in (16_384, 100_000):
        scene = scale.scene(count)
        times = {}
        for r in range(rounds):
            for name, (origins, directions) in sets.items():
                for query, calls in (("occluded", 8), ("cast", 3)):
                    function = getattr(pyclray, query)
                    for on in ((True, False) if r % 2 else (False, True)):
                        programs.BUILD_OPTIONS = base + ([f"-D{flag}"] if on else [])
                        programs.clear()
                        function(scene, origins, directions)  # the switch's build and first call, untimed
                        for _ in range(calls):
                            cpu, wall = time.process_time(), time.perf_counter()
                            function(scene, origins, directions)
                            times.setdefault((name, query, flag if on else "without"), []).append(
                                ((time.perf_counter() - wall) * 1e3, (time.process_time() - cpu) * 1e3))
        programs.BUILD_OPTIONS = base
        programs.clear()
        print(f"{count:,} spheres + ground, load {os.getloadavg()[0]:.2f}")
        for key in sorted(times):
            wall, cpu = np.median(np.array(times[key]), axis=0)
            print(f"  {key[0]} rays, {key[1]:8s} {key[2]:24s} wall {wall:7.2f} ms  CPU {cpu:7.2f} ms")


def ratios(results: dict) -> list[str]:
    """The issue's ratios: Open3D's time over pyclray's per query, shadows over no shadows, Mitsuba
    (warm) over pyclray's shadowed render."""
    lines = []
    for name, timing in results.items():
        median = {system: t["median"] for system, t in timing.items()}
        for query, theirs in (("cast", "open3d cast_rays"), ("occluded", "open3d test_occlusions")):
            if f"pyclray {query}" in median:
                ours = timing[f"pyclray {query}"]
                cpu = f" (CPU time {timing[theirs]['cpu'] / ours['cpu']:.2f}x)" if "cpu" in ours else ""
                lines.append(f"{name}: {query} {median[theirs] / median[f'pyclray {query}']:.2f}x Open3D{cpu}")
        if "pyclray shaded, shadows" in median:
            shadows = median["pyclray shaded, shadows"]
            lines.append(f"{name}: shadows / no shadows {shadows / median['pyclray shaded, no shadows']:.2f}")
            if "mitsuba llvm direct, 1 spp, warm" in median:
                lines.append(f"{name}: Mitsuba warm / pyclray {median['mitsuba llvm direct, 1 spp, warm'] / shadows:.0f}x")
    return lines


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--block", type=int, default=3)
    parser.add_argument("--no-mitsuba", action="store_true")
    parser.add_argument("--mitsuba-calls", type=int, default=2, help="warm Mitsuba renders timed (default 2)")
    parser.add_argument("--flag-ab", metavar="FLAG", help="instead: the casts' kernels with and without -DFLAG in turn (flag_ab)")
    args = parser.parse_args(argv)
    if args.flag_ab:
        flag_ab(args.flag_ab, args.rounds)
        return
    print("load:", os.getloadavg())
    mitsuba_calls = 0 if args.no_mitsuba else max(args.mitsuba_calls, 1)
    results = {**casts(args.rounds, args.block), **shading(args.rounds, args.block, mitsuba_calls)}
    print("load:", os.getloadavg())
    for name, timing in results.items():
        print(name)
        for system, t in timing.items():
            cpu = f", CPU {t['cpu']:.1f} ms" if "cpu" in t else ""
            print(f"  {system:38s} {t['median']:8.1f} ms  (q1 {t['q1']:.1f}, q3 {t['q3']:.1f}, n {t['n']}{cpu})")
    print("\n".join(ratios(results)))
    print(json.dumps(results))


if __name__ == "__main__":
    main()
