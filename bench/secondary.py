"""Secondary rays (issue 25): cast and occluded of 100,000 random rays against Open3D (Embree) on
two ray sets, and shading with shadows against the unshadowed render and Mitsuba llvm's direct
integrator (one sample, one point light), on the scenes of bench/scale.py.

Ray sets: "box" (bench/scale.py's random_rays: origins anywhere in the spheres' box, directions
uniform) and "view" (origins near the camera, directions N(0, 0.6) around the view axis, as issue
25 measured). Timings are medians of blocks of calls, the systems taking turns with short pauses
(open3d_compare.blocks); the ratio is Open3D's time over pyclray's (> 1: pyclray faster).

    .venv/bin/python -m bench.secondary [--rounds 4 --block 3] [--no-mitsuba]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os

import numpy as np

import pyclray

from . import scale
from .open3d_compare import blocks


def view_rays(count: int, seed: int = 2):
    """Origins within 0.5 of the camera, directions N(0, 0.6) around the unit view axis."""
    rng = np.random.default_rng(seed)
    eye, target = np.array(scale.EYE), np.array(scale.TARGET)
    axis = (target - eye) / np.linalg.norm(target - eye)
    origins = eye + rng.uniform(-0.5, 0.5, (count, 3))
    directions = axis + rng.normal(0.0, 0.6, (count, 3))
    return origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)


def casts(rounds: int, block: int) -> dict:
    import open3d as o3d

    out = {}
    sets = {"box": scale.random_rays(100_000), "view": view_rays(100_000)}
    for count in (16_384, 100_000):
        scene = scale.scene(count)
        o3d_scene, _ = scale.open3d_scene(count)
        for name, (origins, directions) in sets.items():
            rays = o3d.core.Tensor(np.hstack([origins, directions]).astype(np.float32))
            timing = blocks({
                "pyclray cast": lambda: pyclray.cast(scene, origins, directions),
                "open3d cast_rays": lambda: o3d_scene.cast_rays(rays),
                "pyclray occluded": lambda: pyclray.occluded(scene, origins, directions),
                "open3d test_occlusions": lambda: o3d_scene.test_occlusions(rays),
            }, rounds, block)
            out[f"{count:,} spheres + ground, {name} rays"] = timing
        del o3d_scene
    return out


def shading(rounds: int, block: int, mitsuba: bool) -> dict:
    scene = scale.scene(100_000)
    light = pyclray.PointLight((6.0, 14.0, 10.0), (300.0, 300.0, 300.0))
    lit = dataclasses.replace(scene, lights=(light,))
    unshadowed = dataclasses.replace(lit, shading=dataclasses.replace(lit.shading, shadows=False))
    systems = {
        "pyclray shaded, shadows": lambda: pyclray.render(lit, aovs=("shaded",)),
        "pyclray shaded, no shadows": lambda: pyclray.render(unshadowed, aovs=("shaded",)),
    }
    if mitsuba:
        from pyclray.reference.mitsuba import import_mitsuba
        from pyclray.reference.validation.shaded import diffuse_version, direct_scene_dict

        mi = import_mitsuba("llvm_ad_rgb")
        mi_scene = mi.load_dict(direct_scene_dict(diffuse_version(lit), light, "llvm_ad_rgb"), optimize=False)
        systems["mitsuba llvm direct, 1 spp"] = lambda: mi.render(mi_scene, spp=1).numpy()
    return {"shaded 512x512, ground + 100,000 spheres, one point light": blocks(systems, rounds, block)}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--block", type=int, default=3)
    parser.add_argument("--no-mitsuba", action="store_true")
    args = parser.parse_args(argv)
    print("load:", os.getloadavg())
    results = {**casts(args.rounds, args.block), **shading(args.rounds, args.block, not args.no_mitsuba)}
    print("load:", os.getloadavg())
    for name, timing in results.items():
        print(name)
        for system, t in timing.items():
            print(f"  {system:32s} {t['median']:8.1f} ms  (q1 {t['q1']:.1f}, q3 {t['q3']:.1f}, n {t['n']})")
    print(json.dumps(results))


if __name__ == "__main__":
    main()
