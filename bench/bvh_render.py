"""What the tree's quality does to render time: the same scenes rendered through the Morton LBVH and
through the binned SAH tree (pyclray.engine.bvh.build's two methods), in one process, in blocks
(bench/views.py's rule: each case a block of calls on its own, a pause at each switch, rounds in
rotating order, the median of all timed calls).

    python -m bench.bvh_build --render [--quick]

Scenes: bench/scale.py's field of N spheres over a ground plane, uniform and clustered
(bench/bvh_build.spheres), as one pyclray.Spheres batch; per scene, a 512x512 render (depth, normal,
id: packets of camera rays through the binary tree) and a cast of 100,000 random rays (from points
of the field in random directions: single rays through the wide tree). Then bench/meshes.py's two
meshes (the bunny subdivided to 80,000 triangles, a perturbed sphere of 1,000,000), the render from
its camera and 100,000 rays from random points of the mesh's box in random directions.
"""
from __future__ import annotations

import functools

import numpy as np

import pyclray
from pyclray.engine import bvh, scene_bvh, views

from . import scale
from .bvh_build import spheres
from .views import blocks

SIZE = 512
AOVS = ("depth", "normal", "id")
RAYS = 100_000


def sphere_scene(bounds: np.ndarray) -> pyclray.Scene:
    """A scene of spheres with these boxes, over the ground."""
    centres, radii = 0.5 * (bounds[:, 0] + bounds[:, 1]), 0.5 * (bounds[:, 1, 0] - bounds[:, 0, 0])
    shapes = (pyclray.Plane((0.0, 1.0, 0.0), 0.0), pyclray.Spheres(centres, radii))
    return pyclray.Scene(pyclray.Camera(scale.EYE, scale.TARGET, fov=scale.FOV), pyclray.Image(SIZE, SIZE), shapes)


def built_with(scene: pyclray.Scene, method: str) -> pyclray.Scene:
    """The scene (a copy of its shapes tuple: a prepared scene of its own) whose BVH is built by
    method (its prepared scene is built here, once: later renders reuse its tree)."""
    scene = pyclray.Scene(scene.camera, scene.image, tuple(list(scene.shapes)))
    original = scene_bvh.build
    scene_bvh.build = functools.partial(bvh.build, method=method)
    try:
        pyclray.render(scene, AOVS, acceleration="bvh")
        origins, directions = scale.random_rays(16)
        pyclray.cast(scene, origins, directions)
    finally:
        scene_bvh.build = original
    return scene


def compare(label: str, scene: pyclray.Scene, origins, directions) -> None:
    """One table row: the scene through each tree, in blocks."""
    scenes = {m: built_with(scene, m) for m in ("lbvh", "sah")}
    trees = {m: views.scene_bvh(s).tree for m, s in scenes.items()}  # the prepared scenes' own
    cases = {}
    for m, s in scenes.items():
        cases[f"render {m}"] = lambda k, s=s: pyclray.render(s, AOVS, acceleration="bvh")
        cases[f"cast {m}"] = lambda k, s=s: pyclray.cast(s, origins, directions)
    t = blocks(cases)
    print(f"| {label} | {bvh.sah_cost(trees['lbvh']) / bvh.sah_cost(trees['sah']):.2f} | "
          f"{1e3 * t['render lbvh']:.1f} | {1e3 * t['render sah']:.1f} | {t['render lbvh'] / t['render sah']:.2f} | "
          f"{1e3 * t['cast lbvh']:.1f} | {1e3 * t['cast sah']:.1f} | {t['cast lbvh'] / t['cast sah']:.2f} |", flush=True)
    pyclray.clear_cache()


def main(quick: bool) -> None:
    from .meshes import camera_for, meshes

    sizes = (100_000,) if quick else (100_000, 1_000_000)
    print("| scene | SAH cost LBVH / SAH | render 512x512 ms: LBVH | SAH | LBVH / SAH | cast 100k rays ms: LBVH | SAH | LBVH / SAH |")
    print("|---|---|---|---|---|---|---|---|")
    origins, directions = scale.random_rays(RAYS)
    for n in sizes:
        for clustered in (False, True):
            compare(f"{'clustered' if clustered else 'uniform'} spheres {n:,}", sphere_scene(spheres(n, clustered=clustered)),
                    origins, directions)
    rng = np.random.default_rng(2)
    for name, mesh in meshes(None).items():
        if quick and name == "1M":
            continue
        lo, hi = mesh.box()
        directions = rng.normal(size=(RAYS, 3))
        compare(f"mesh {name} ({len(mesh.faces):,} triangles)", camera_for(mesh, SIZE), rng.uniform(lo, hi, (RAYS, 3)),
                directions / np.linalg.norm(directions, axis=1, keepdims=True))
