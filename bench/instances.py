"""Mesh instances against Mitsuba 3's shapegroup/instance (issue 23's instancing target).

    python -m bench.instances [--count 10000] [--triangles 50000] [--size 512] [--rounds 3] [--block 3]
                              [--no-mitsuba]

One mesh of about --triangles triangles (a perturbed UV sphere) placed --count times on a square
field (random turns and scales: each instance its own transform), seen from above at an angle,
rendered at --size x --size: pyclray's depth, normal and id (the instances are two levels: one copy
of the triangles and one BVH, a transform and a top-level box each) against Mitsuba's llvm_ad_rgb
with one shapegroup holding the mesh and one instance per placement, its aov integrator making
depth, geometric normal and shape index (as pyclray.reference.mitsuba renders a check). Both warm:
each system renders once before its timed block (Mitsuba's JIT compiles its kernel at the first),
blocks rotate with a pause at each switch (bench.open3d_compare.blocks). Prints the medians (ms),
the speed-up, pyclray's bytes per instance (engine/scene/instances.py's instance_bytes) and its first
render (the scene's build: packing, both levels' BVHs). The machine is shared: compare ratios.
--no-mitsuba times pyclray alone: Mitsuba 3.9's llvm render of a shapegroup's instances grows faster
than their number (measured here: 10 s for 1,000 instances, 130 s and 3.2 GB for 3,000; at 10,000
its first render had not ended after 11 minutes and 18 GB, docs/benchmarks.md).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import pyclray
from pyclray.model.shapes.mesh_shapes import perturbed_sphere

from .open3d_compare import blocks

AOVS = ("depth", "normal", "id")


def field(count: int, triangles: int, size: int, seed: int = 0) -> pyclray.Scene:
    """count placements of one mesh of about `triangles` triangles on a square grid (spacing 3)."""
    rng = np.random.default_rng(seed)
    rows = max(int(round(np.sqrt(triangles / 2))), 4)
    columns = max(int(round((triangles + 2 * rows) / (2 * rows))), 4)
    v, f = perturbed_sphere(rows, columns, 1.0, 0.15, rng)
    mesh = pyclray.Mesh(v, f, name="rock")
    side = int(np.ceil(np.sqrt(count)))
    shapes = []
    for k in range(count):
        i, j = divmod(k, side)
        scale = tuple(rng.uniform(0.6, 1.3, 3))
        shapes.append(mesh.placed(scale=scale, axis=tuple(rng.normal(size=3)), angle=float(rng.uniform(0, 360)),
                                  translate=(3.0 * (i - side / 2), 0.0, 3.0 * (j - side / 2)), name=f"rock{k}"))
    reach = 1.5 * side
    camera = pyclray.Camera((0.0, 0.9 * reach, 1.6 * reach), (0.0, 0.0, 0.0), fov=60.0)
    return pyclray.Scene(camera, pyclray.Image(size, size), tuple(shapes))


def mitsuba_scene(scene: pyclray.Scene):
    """Mitsuba's scene of the same field: one shapegroup of the mesh (float32 object-space vertices),
    one instance per placement (its to_world as the check writes transforms), the check's sensor."""
    from pyclray.reference import mitsuba as bridge

    mi = bridge.import_mitsuba("llvm_ad_rgb")
    description = bridge.scene_dict(pyclray.Scene(scene.camera, scene.image, ()), "llvm_ad_rgb",
                                    "dd:depth,gn:geo_normal,si:shape_index")
    mesh = scene.shapes[0]
    group = bridge.mitsuba_mesh(mi, {"type": "mesh", "vertex_positions": mesh.vertices, "faces": mesh.faces}, "rock")
    description["group"] = {"type": "shapegroup", "rock": group}
    for k, shape in enumerate(scene.shapes):
        description[f"instance{k}"] = {"type": "instance", "shapegroup": {"type": "ref", "id": "group"},
                                       "to_world": bridge.mitsuba_values(mi, shape.transform())}
    return mi, mi.load_dict(description, optimize=False)


def run(count=10_000, triangles=50_000, size=512, rounds=3, block=3, mitsuba=True):
    from pyclray.engine.opencl.device import context_for
    from pyclray.engine.scene.instances import instance_bytes
    from pyclray.engine.api import tracer_for

    scene = field(count, triangles, size)
    start = time.perf_counter()
    frame = pyclray.render(scene, aovs=AOVS)
    first = time.perf_counter() - start
    cost = instance_bytes(tracer_for(scene, context_for(), "fp32").prepared)
    hit = float(np.mean(frame["id"] >= 0))
    out = {"scene": f"{count:,} instances of a {len(scene.shapes[0].faces):,}-triangle mesh, {size}x{size}, "
                    f"{hit:.0%} of the pixels hit", "first_render_s": first, "cost": cost}
    if not mitsuba:
        out["timed"] = blocks({"pyclray": lambda: pyclray.render(scene, aovs=AOVS)}, rounds, block)
        return out
    mi, mi_scene = mitsuba_scene(scene)

    def theirs():
        image = mi_scene.integrator().render(mi_scene, mi_scene.sensors()[0])
        return np.array(image)

    start = time.perf_counter()
    theirs()  # the JIT's first render compiles its kernel
    mitsuba_first = time.perf_counter() - start
    out["timed"] = blocks({"pyclray": lambda: pyclray.render(scene, aovs=AOVS), "mitsuba": theirs}, rounds, block)
    out["mitsuba_first_render_s"] = mitsuba_first
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=10_000)
    parser.add_argument("--triangles", type=int, default=50_000)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--block", type=int, default=3)
    parser.add_argument("--no-mitsuba", action="store_true", help="time pyclray alone")
    args = parser.parse_args(argv)
    out = run(args.count, args.triangles, args.size, args.rounds, args.block, not args.no_mitsuba)
    ours = out["timed"]["pyclray"]
    print(out["scene"])
    if args.no_mitsuba:
        print(f"render (depth, normal, id)  pyclray {ours['median']:9.1f} ms (quartiles {ours['q1']:.1f}-{ours['q3']:.1f})")
        print(f"first render (build)        pyclray {out['first_render_s']:9.2f} s")
    else:
        theirs = out["timed"]["mitsuba"]["median"]
        print(f"render (depth, normal, id)  pyclray {ours['median']:9.1f} ms  mitsuba llvm {theirs:9.1f} ms  "
              f"speed-up {theirs / ours['median']:5.2f}x")
        print(f"first render (build)        pyclray {out['first_render_s']:9.2f} s   "
              f"mitsuba llvm {out['mitsuba_first_render_s']:9.2f} s")
    cost = out["cost"]
    print(f"bytes per instance {cost['bytes_per_instance']:.0f} (own {cost['own_bytes_per_instance']}, top-level tree "
          f"{cost['tlas_bytes_per_instance']:.0f}); the shared mesh {cost['shared_bytes'] / 1e6:.1f} MB once")


if __name__ == "__main__":
    main()
