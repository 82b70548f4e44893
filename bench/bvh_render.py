"""What the tree's quality does to render time: the same scenes rendered through the Morton LBVH and
through the binned SAH tree (pyclray.engine.bvh.tree.build's two methods), in one process, in blocks
(each case a block of calls on its own, a pause at each switch, the order reversed every other
round; the median of all timed calls, in wall and in CPU seconds: the CPU time moves less with the
load of a shared machine).

    python -m bench.bvh_build --render [--quick]

Scenes: bench/scale.py's field of N spheres over a ground plane, uniform and clustered
(bench/scale.sphere_boxes), as one pyclray.Spheres batch; per scene, a 512x512 render (depth, normal,
id: packets of camera rays through the binary tree) and a cast of 100,000 random rays (from points
of the field in random directions: single rays through the wide tree). Then bench/meshes.py's two
meshes (the bunny subdivided to 80,000 triangles, a perturbed sphere of 1,000,000), the render from
its camera and 100,000 rays from random points of the mesh's box in random directions.
"""
from __future__ import annotations

import functools
import statistics
import time

import numpy as np

import pyclray
from pyclray.engine import api
from pyclray.engine.bvh import tree as bvh
from pyclray.engine.bvh import scene as scene_bvh
from pyclray.engine.opencl.device import context_for

from . import scale

SIZE = 512
AOVS = ("depth", "normal", "id")
RAYS = 100_000
ROUNDS = 6
CALLS = 5  # timed calls per block
PAUSE = 0.3


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


def timed(cases: dict, rounds: int = ROUNDS) -> dict:
    """Per case (a callable): the median wall and CPU seconds of its calls (CPU: the process's, the
    device's PoCL threads included: on a shared machine it moves less with the load than the wall
    clock), timed in blocks of CALLS after two untimed calls, a pause at each switch, the cases'
    order reversed every other round."""
    times = {name: ([], []) for name in cases}
    for r in range(rounds):
        for name in (list(cases) if r % 2 == 0 else list(cases)[::-1]):
            run = cases[name]
            run(), run()
            for _ in range(CALLS):
                wall, cpu = time.perf_counter(), time.process_time()
                run()
                times[name][0].append(time.perf_counter() - wall)
                times[name][1].append(time.process_time() - cpu)
            time.sleep(PAUSE)
    return {name: (statistics.median(w), statistics.median(c)) for name, (w, c) in times.items()}


def compare(label: str, scene: pyclray.Scene, origins, directions) -> None:
    """One table row: the scene through each tree."""
    scenes = {m: built_with(scene, m) for m in ("lbvh", "sah")}
    trees = {m: api.tracer_for(s, context_for(None), "fp32").prepared.bvh.tree for m, s in scenes.items()}  # the prepared scenes' own
    cases = {}
    for m, s in scenes.items():
        cases[f"render {m}"] = lambda s=s: pyclray.render(s, AOVS, acceleration="bvh")
        cases[f"cast {m}"] = lambda s=s: pyclray.cast(s, origins, directions)
    t = timed(cases)
    cells = []
    for kind in ("render", "cast"):
        (wall_l, cpu_l), (wall_s, cpu_s) = t[f"{kind} lbvh"], t[f"{kind} sah"]
        cells += [f"{1e3 * wall_l:.1f} / {1e3 * cpu_l:.1f}", f"{1e3 * wall_s:.1f} / {1e3 * cpu_s:.1f}",
                  f"{wall_l / wall_s:.2f} / {cpu_l / cpu_s:.2f}"]
    print(f"| {label} | {bvh.sah_cost(trees['lbvh']) / bvh.sah_cost(trees['sah']):.2f} | " + " | ".join(cells) + " |", flush=True)
    pyclray.clear_cache()


def main(quick: bool) -> None:
    from .meshes import camera_for, meshes

    sizes = (100_000,) if quick else (100_000, 1_000_000)
    print("| scene | SAH cost LBVH / SAH | render 512x512 ms (wall / CPU): LBVH | SAH | LBVH / SAH | "
          "cast 100k rays ms (wall / CPU): LBVH | SAH | LBVH / SAH |")
    print("|---|---|---|---|---|---|---|---|")
    origins, directions = scale.random_rays(RAYS)
    for n in sizes:
        for clustered in (False, True):
            compare(f"{'clustered' if clustered else 'uniform'} spheres {n:,}", sphere_scene(scale.sphere_boxes(n, clustered=clustered)),
                    origins, directions)
    rng = np.random.default_rng(2)
    for name, mesh in meshes(None).items():
        if quick and name == "1M":
            continue
        lo, hi = mesh.box()
        directions = rng.normal(size=(RAYS, 3))
        compare(f"mesh {name} ({len(mesh.faces):,} triangles)", camera_for(mesh, SIZE), rng.uniform(lo, hi, (RAYS, 3)),
                directions / np.linalg.norm(directions, axis=1, keepdims=True))
