"""Triangle meshes against Open3D's RaycastingScene (Embree) in one process (issue 23's targets).

    python -m bench.meshes [--bunny PATH] [--rounds 3] [--block 5]

Cases, each timed in rotating blocks with a pause at each switch (bench.open3d_compare.blocks):
- primary rays 512x512 on a ~70k-triangle scanned mesh (the 75,408-triangle Stanford bunny of CGAL's
  demo data when --bunny names it, else scenes/meshes/bunny.ply subdivided twice: 80,000 triangles)
  and on a 1,000,000-triangle mesh (a perturbed UV sphere): pyclray's render of depth, normal, id
  and primitive against Open3D's cast_rays of the same pinhole rays (t_hit, normals, ids,
  primitive ids, uvs);
- 100,000 incoherent rays (random origins and directions in the mesh's bounds): pyclray.cast
  (depth, normal, id) against cast_rays;
- the scene build: pyclray's first render after pyclray.clear_cache() (preparation: packing, the BVH,
  the per-view pass, and the render of 512x512 pixels) and Open3D's add_triangles + first cast of one
  ray (Embree builds lazily), the median of BUILDS of each, alternating;
- memory: the bytes the prepared scene holds per triangle (PreparedScene.nbytes: vertices, faces or
  triangle entries, ids, the BVH; issue 23's target <= 64), in the build's row; and after the
  table (memory_rows): what a first cast adds per triangle (cast's buffers, built when a cast first
  asks: engine/queries/cast.py's cast_inputs, a mesh's in blocks (engine/queries/cast_blocks.py), and the tree's
  leaf-order bounds on the host where a cast gathered them), and a mesh shared
  by 100 instances (bench.instances' field: the shared vertices, faces and tree per unique triangle,
  engine/scene/instances.py's instance_bytes).
Prints a table of medians (ms) and the ratios, for primary and incoherent rays also of each call's
process CPU time (with_cpu). The machine is shared: compare ratios.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import pyclray
from pyclray.engine.opencl.device import context_for
from pyclray.engine.api import tracer_for
from pyclray.model.shapes.mesh_shapes import perturbed_sphere

from .engine_ab import subdivided

from .open3d_compare import blocks

SCENES = Path(__file__).resolve().parent.parent / "scenes"
BUILDS = 5  # builds timed of each system, alternating: their median


def meshes(bunny_path):
    if bunny_path:
        bunny = pyclray.Mesh.load(bunny_path)
        bunny = pyclray.Mesh(bunny.vertices, bunny.faces, name="bunny")
    else:
        base = pyclray.Mesh.load(SCENES / "meshes" / "bunny.ply")
        bunny = pyclray.Mesh(*subdivided(base.vertices, base.faces, 2), name="bunny")
    v, f = perturbed_sphere(500, 1000, 0.5, 0.02, np.random.default_rng(0))
    big = pyclray.Mesh(v, f, name="sphere")
    return {"bunny": bunny, "1M": big}


def camera_for(mesh, size):
    lo, hi = mesh.box()
    centre, radius = 0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo)
    eye = centre + np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0]) * radius * 2.6
    return pyclray.Scene(pyclray.Camera(tuple(eye), tuple(centre), fov=45.0), pyclray.Image(size, size), (mesh,))


def incoherent_rays(mesh, count: int = 100_000):
    """(origins, unit directions): random origins in the mesh's box, uniform directions (seeded)."""
    rng = np.random.default_rng(1)
    lo, hi = mesh.box()
    origins = rng.uniform(lo, hi, (count, 3))
    directions = rng.normal(size=(count, 3))
    return origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)


def open3d_scene(mesh):
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    a = mesh.world_vertices().astype(np.float32)
    scene.add_triangles(o3d.core.Tensor(a), o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    return scene


def pinhole_rays(scene):
    """The scene's own unit camera rays as Open3D's (N, 6) float32 tensor."""
    import open3d as o3d
    from pyclray.reference import oracle

    origins, directions = oracle.camera_rays(scene)
    return o3d.core.Tensor(np.concatenate([origins, directions], -1).reshape(-1, 6).astype(np.float32))


def with_cpu(systems: dict):
    """The systems' calls, each also recording its process CPU time (all the threads of both:
    PoCL's and Embree's), and the lists they record into. Another process's load slows a call's
    wall time but adds little to its CPU time, so on this shared machine the CPU ratio moves less
    between runs; it counts the work, not the cores' overlap (and any spinning of a thread pool
    waiting for the next call, Embree's TBB workers included)."""
    cpu = {name: [] for name in systems}

    def recorded(name, function):
        def call():
            start = time.process_time()
            function()
            cpu[name].append(time.process_time() - start)
        return call

    return {name: recorded(name, function) for name, function in systems.items()}, cpu


def run(bunny_path=None, rounds=3, block=5):
    import open3d as o3d

    rows = []
    for label, mesh in meshes(bunny_path).items():
        scene = camera_for(mesh, 512)
        # the build: pyclray's first render from cold (its program cached on disk), Open3D's first cast;
        # the median of BUILDS of each, alternating (one build is one sample: the shared machine's noise)
        pyclray.render(scene, aovs=("depth", "normal", "id", "primitive"))
        rays = pinhole_rays(scene)
        ours_build, theirs_build = [], []
        for _ in range(BUILDS):
            pyclray.clear_cache()
            start = time.perf_counter()
            pyclray.render(scene, aovs=("depth", "normal", "id", "primitive"))
            ours_build.append(time.perf_counter() - start)
            time.sleep(0.2)
            start = time.perf_counter()
            o3d_scene = open3d_scene(mesh)
            o3d_scene.cast_rays(rays[:1])
            theirs_build.append(time.perf_counter() - start)
            time.sleep(0.2)
        held = tracer_for(scene, context_for(None), "fp32").prepared.nbytes() / len(mesh.faces)
        rows.append((f"{label} ({len(mesh.faces):,} triangles, {held:.1f} B/triangle): first render / build + first cast",
                     {"pyclray": {"median": np.median(ours_build) * 1e3}, "open3d": {"median": np.median(theirs_build) * 1e3}}))
        systems, cpu = with_cpu({"pyclray": lambda: pyclray.render(scene, aovs=("depth", "normal", "id", "primitive")),
                                 "open3d": lambda: o3d_scene.cast_rays(rays)})
        timed = blocks(systems, rounds, block)
        for name in timed:
            timed[name]["cpu"] = float(np.median(cpu[name])) * 1e3
        rows.append((f"{label}: primary rays 512x512", timed))
        origins, directions = incoherent_rays(mesh)
        o3d_rays = o3d.core.Tensor(np.hstack([origins, directions]).astype(np.float32))
        systems, cpu = with_cpu({"pyclray": lambda: pyclray.cast(scene, origins, directions),
                                 "open3d": lambda: o3d_scene.cast_rays(o3d_rays)})
        timed = blocks(systems, rounds, block)
        for name in timed:
            timed[name]["cpu"] = float(np.median(cpu[name])) * 1e3
        rows.append((f"{label}: 100,000 incoherent rays", timed))
        del o3d_scene
    return rows


def cast_bytes(scene) -> int:
    """The bytes a scene's first cast added: cast's device buffers (its cached handle's cast inputs)
    and the leaf-order bounds the prepared scene's tree gathered for it."""
    tracer = tracer_for(scene, context_for(None), "fp32")
    held = tracer.cast_inputs()[3]  # cast_inputs' bytes: the sizes of its buffers
    tree = tracer.prepared.bvh
    return held + (tree.__dict__["bounds"].nbytes if "bounds" in tree.__dict__ else 0)


def memory_rows(bunny_path=None) -> list[str]:
    """Bytes per triangle: each mesh's prepared scene and what a first cast adds; a shared mesh's."""
    from pyclray.engine.scene.instances import instance_bytes

    from .instances import field

    rows = []
    for label, mesh in meshes(bunny_path).items():
        scene = camera_for(mesh, 64)
        pyclray.clear_cache()
        pyclray.render(scene, aovs=("depth",))
        held = tracer_for(scene, context_for(None), "fp32").prepared.nbytes()
        pyclray.cast(scene, *incoherent_rays(mesh, 1000))
        n = len(mesh.faces)
        rows.append(f"{label} ({n:,} triangles): render {held / n:.1f} B/triangle; a first cast adds {cast_bytes(scene) / n:.1f}")
    scene = field(100, 50_000, 64)
    pyclray.clear_cache()
    pyclray.render(scene, aovs=("depth",))
    cost = instance_bytes(tracer_for(scene, context_for(None), "fp32").prepared)
    unique = len(scene.shapes[0].faces)
    rows.append(f"a mesh of {unique:,} triangles shared by {cost['instances']} instances: {cost['shared_bytes'] / unique:.1f} "
                f"B per unique triangle, {cost['bytes_per_instance']:.0f} B per instance")
    pyclray.clear_cache()
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bunny", help="the 75,408-triangle bunny00.off of CGAL's demo data")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--block", type=int, default=5)
    args = parser.parse_args(argv)
    for name, timed in run(args.bunny, args.rounds, args.block):
        ours, theirs = timed["pyclray"]["median"], timed["open3d"]["median"]
        print(f"{name:70s} pyclray {ours:9.1f} ms  open3d {theirs:9.1f} ms  speed-up {theirs / ours:5.2f}x")
        if "cpu" in timed["pyclray"]:  # primary and incoherent rays: the CPU time per call too (with_cpu)
            ours, theirs = timed["pyclray"]["cpu"], timed["open3d"]["cpu"]
            print(f"{'':70s} CPU     {ours:9.1f} ms  open3d {theirs:9.1f} ms  CPU ratio {theirs / ours:5.2f}x")
    for row in memory_rows(args.bunny):
        print(row)


if __name__ == "__main__":
    main()
