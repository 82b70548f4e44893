"""What the tree's quality does to render time: the same scenes rendered through the Morton LBVH and
through the binned SAH tree (pyclray.engine.bvh.build's two methods), in one process, in blocks
(bench/views.py's rule: each case a block of calls on its own, a pause at each switch, rounds in
rotating order, the median of all timed calls).

    python -m bench.bvh_build --render [--quick]

Scenes: bench/scale.py's field of N spheres over a ground plane, uniform and clustered
(bench/bvh_build.spheres), as one pyclray.Spheres batch; per scene, a 512x512 render (depth, normal,
id: packets of camera rays through the binary tree) and a cast of 100,000 random rays (from points
of the field in random directions: single rays through the wide tree).
"""
from __future__ import annotations

import functools

import numpy as np

import pyclray
from pyclray.engine import bvh, scene_bvh

from . import scale
from .bvh_build import spheres
from .views import blocks

SIZE = 512
AOVS = ("depth", "normal", "id")
RAYS = 100_000


def scene_with(bounds: np.ndarray, method: str) -> pyclray.Scene:
    """A scene of these spheres' boxes (as spheres) whose BVH is built by method (its prepared
    scene is built here, once: later renders reuse its tree)."""
    centres, radii = 0.5 * (bounds[:, 0] + bounds[:, 1]), 0.5 * (bounds[:, 1, 0] - bounds[:, 0, 0])
    shapes = (pyclray.Plane((0.0, 1.0, 0.0), 0.0), pyclray.Spheres(centres, radii))
    scene = pyclray.Scene(pyclray.Camera(scale.EYE, scale.TARGET, fov=scale.FOV), pyclray.Image(SIZE, SIZE), shapes)
    original = scene_bvh.build
    scene_bvh.build = functools.partial(bvh.build, method=method)
    try:
        pyclray.render(scene, AOVS, acceleration="bvh")
        origins, directions = scale.random_rays(16)
        pyclray.cast(scene, origins, directions)
    finally:
        scene_bvh.build = original
    return scene


def main(quick: bool) -> None:
    sizes = (100_000,) if quick else (100_000, 1_000_000)
    origins, directions = scale.random_rays(RAYS)
    print("| scene | SAH cost LBVH / SAH | render 512x512 ms: LBVH | SAH | LBVH / SAH | cast 100k rays ms: LBVH | SAH | LBVH / SAH |")
    print("|---|---|---|---|---|---|---|---|")
    for n in sizes:
        for clustered in (False, True):
            bounds = spheres(n, clustered=clustered)
            trees = {m: bvh.build(bvh.widened(bounds), method=m) for m in ("lbvh", "sah")}
            scenes = {m: scene_with(bounds, m) for m in ("lbvh", "sah")}
            cases = {}
            for m, scene in scenes.items():
                cases[f"render {m}"] = lambda k, scene=scene: pyclray.render(scene, AOVS, acceleration="bvh")
                cases[f"cast {m}"] = lambda k, scene=scene: pyclray.cast(scene, origins, directions)
            t = blocks(cases)
            label = f"{'clustered' if clustered else 'uniform'} {n:,}"
            print(f"| {label} | {bvh.sah_cost(trees['lbvh']) / bvh.sah_cost(trees['sah']):.2f} | "
                  f"{1e3 * t['render lbvh']:.1f} | {1e3 * t['render sah']:.1f} | {t['render lbvh'] / t['render sah']:.2f} | "
                  f"{1e3 * t['cast lbvh']:.1f} | {1e3 * t['cast sah']:.1f} | {t['cast lbvh'] / t['cast sah']:.2f} |", flush=True)
            pyclray.clear_cache()
