"""Point queries against Open3D's RaycastingScene (Embree) in one process (issue 38's targets):
distance, occupancy and signed distance of 100,000 points, and the signs right next to the surface.

    python -m bench.points [--quick] [--rounds 3] [--block 3] [--bunny PATH]

Meshes: bench.meshes' (the bunny subdivided twice, 80,000 triangles, or --bunny's; a 1,000,000-
triangle perturbed UV sphere), both closed. Points (seeded): 100,000 uniform in the mesh's box, and
100,000 within 1% of the box's largest side from the surface (the nearest surface points of uniform
points, moved by a uniform offset in [-1%, 1%] of the size along a random direction).

Cases, each timed in rotating blocks with a pause at each switch (bench.open3d_compare.blocks), the
medians and their ratios printed, of the wall clock and of the process CPU time (every thread's:
on a shared machine what other work leaves alone):
- distance: pyclray.Tracer.distance against compute_distance (float32 points for Open3D, its only type);
- occupancy and signed distance, parity: Tracer.occupancy / signed_distance(sign="parity") against
  compute_occupancy / compute_signed_distance(nsamples=1) (one ray each, as pyclray's parity);
- the same with sign="winding" (pyclray only: its ratio to the parity form, target within 3x): a
  closed mesh's winding number is exact, its signed crossing count; the hierarchical sum of open
  meshes is timed on the mesh with every 100th face removed, against the closed mesh's parity.
Signs next to the surface: 20,000 points at 1e-6 of the size from the surface, on each side of a
triangle's interior (away from its edges, where the side is known by construction: along the face
normal is outside), fp64 points for pyclray and their float32 roundings for Open3D (which takes no
other): the sign errors of each (Open3D's nsamples=1: one ray that may graze an edge; its float32
rounding of the point itself may cross the surface, counted apart: those points' float32 side).
The machine is shared: compare ratios (uptime's load is printed).
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

import pyclray

from .meshes import meshes
from .open3d_compare import blocks

COUNT = 100_000
NEAR = 0.01  # the near points' band: 1% of the size
SIGN_POINTS = 20_000
SIGN_OFFSET = 1e-6  # of the size


def near_points(tracer, lo, hi, count, rng):
    seeds = rng.uniform(lo, hi, (count, 3))
    on = tracer.closest_points(seeds)["position"].astype(np.float64)
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return on + direction * rng.uniform(-NEAR, NEAR, (count, 1)) * float(np.max(hi - lo))


def sign_points(mesh, size, rng):
    """(points, inside): SIGN_POINTS points at SIGN_OFFSET * size from random triangles' interiors
    (barycentrics at least 0.05 from each edge), on either side."""
    a, b, c = mesh.corners()
    tri = rng.integers(0, len(a), SIGN_POINTS)
    u = rng.uniform(0.05, 0.9, SIGN_POINTS)
    v = rng.uniform(0.05, 0.95 - u)
    on = a[tri] + u[:, None] * (b[tri] - a[tri]) + v[:, None] * (c[tri] - a[tri])
    inside = rng.random(SIGN_POINTS) < 0.5
    normal = mesh.face_normals()[tri]
    return on + np.where(inside, -1.0, 1.0)[:, None] * normal * SIGN_OFFSET * size, inside


def open_winding_rows(name, mesh, tracer, uniform, rounds, block):
    """The hierarchical winding number (open meshes): the mesh with every 100th face removed, its
    occupancy by winding against the closed mesh's by parity, in blocks."""
    holed = pyclray.Mesh(mesh.vertices, mesh.faces[np.arange(len(mesh.faces)) % 100 != 0], name="holed")
    scene = pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(8, 8), (holed,))
    with pyclray.prepare(scene) as holed_tracer:
        times = blocks({"winding, open": lambda: holed_tracer.occupancy(uniform, sign="winding"),
                        "parity, closed": lambda: tracer.occupancy(uniform, sign="parity")}, rounds, block)
    return [(name, "uniform", "occupancy winding, 1% of faces removed: hierarchical (vs parity, closed)",
             _both(times["winding, open"]), _both(times["parity, closed"]))]


def _both(timed: dict) -> tuple[float, float]:
    """(wall, CPU) medians in ms of a system's calls (bench.open3d_compare.blocks)."""
    return timed["median"], timed["cpu"]


def run_mesh(name, mesh, rounds, block, rng):
    import open3d as o3d

    lo, hi = np.asarray(mesh.box())
    size = float(np.max(hi - lo))
    scene = pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(8, 8), (mesh,))
    tracer = pyclray.prepare(scene)
    o3d_scene = o3d.t.geometry.RaycastingScene()
    o3d_scene.add_triangles(o3d.core.Tensor(mesh.world_vertices().astype(np.float32)),
                            o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    uniform = rng.uniform(lo, hi, (COUNT, 3))
    near = near_points(tracer, lo, hi, COUNT, rng)
    rows = []
    for label, points in (("uniform", uniform), ("near", near)):
        tensor = o3d.core.Tensor(points.astype(np.float32))
        systems = {
            "pyclray distance": lambda: tracer.distance(points),
            "Open3D compute_distance": lambda: o3d_scene.compute_distance(tensor).numpy(),
            "pyclray occupancy parity": lambda: tracer.occupancy(points, sign="parity"),
            "Open3D compute_occupancy": lambda: o3d_scene.compute_occupancy(tensor, nsamples=1).numpy(),
            "pyclray signed_distance parity": lambda: tracer.signed_distance(points, sign="parity"),
            "Open3D compute_signed_distance": lambda: o3d_scene.compute_signed_distance(tensor, nsamples=1).numpy(),
            "pyclray occupancy winding": lambda: tracer.occupancy(points, sign="winding"),
            "pyclray signed_distance winding": lambda: tracer.signed_distance(points, sign="winding"),
        }
        times = blocks(systems, rounds, block)
        ms = {k: _both(v) for k, v in times.items()}
        rows.append((name, label, "distance", ms["pyclray distance"], ms["Open3D compute_distance"]))
        rows.append((name, label, "occupancy parity", ms["pyclray occupancy parity"], ms["Open3D compute_occupancy"]))
        rows.append((name, label, "signed_distance parity", ms["pyclray signed_distance parity"],
                     ms["Open3D compute_signed_distance"]))
        rows.append((name, label, "occupancy winding (vs parity)", ms["pyclray occupancy winding"],
                     ms["pyclray occupancy parity"]))
        rows.append((name, label, "signed_distance winding (vs parity)", ms["pyclray signed_distance winding"],
                     ms["pyclray signed_distance parity"]))
    rows += open_winding_rows(name, mesh, tracer, uniform, rounds, block)
    points, inside = sign_points(mesh, size, rng)
    points32 = points.astype(np.float32)
    errors = {
        "pyclray parity (fp64 points)": int(np.sum(tracer.occupancy(points, sign="parity").astype(bool) != inside)),
        "pyclray winding (fp64 points)": int(np.sum(tracer.occupancy(points, sign="winding").astype(bool) != inside)),
    }
    # the float32 points' own side (their rounding may cross the surface): pyclray's exact parity of them
    side32 = tracer.occupancy(points32.astype(np.float64), sign="parity").astype(bool)
    o3d_occupancy = o3d_scene.compute_occupancy(o3d.core.Tensor(points32), nsamples=1).numpy().astype(bool)
    errors["Open3D nsamples=1 (float32 points, against their own side)"] = int(np.sum(o3d_occupancy != side32))
    errors["float32 rounding crossed the surface"] = int(np.sum(side32 != inside))
    tracer.close()
    return rows, errors


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="the bunny only, one round")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--block", type=int, default=3)
    parser.add_argument("--bunny", help="a larger bunny's file (bench.meshes)")
    parser.add_argument("--open-winding", action="store_true",
                        help="only the hierarchical winding number of the meshes with holes, against parity")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    chosen = meshes(args.bunny)
    if args.quick:
        chosen = {"bunny": chosen["bunny"]}
        args.rounds = 1
    print(f"load before: {os.getloadavg()[0]:.2f} (2 cores shared)")
    started = time.perf_counter()
    for name, mesh in chosen.items():
        if args.open_winding:
            scene = pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(8, 8), (mesh,))
            lo, hi = np.asarray(mesh.box())
            with pyclray.prepare(scene) as tracer:
                rows = open_winding_rows(name, mesh, tracer, rng.uniform(lo, hi, (COUNT, 3)), args.rounds, args.block)
            for _, label, query, mine, other in rows:
                print(f"| {name} | {label} | {query} | {mine[0]:.1f} | {other[0]:.1f} | {other[0] / mine[0]:.2f} "
                      f"| {other[1] / mine[1]:.2f} |")
            continue
        rows, errors = run_mesh(f"{name} ({len(mesh.faces):,} triangles)", mesh, args.rounds, args.block, rng)
        print(f"\n{name}: {len(mesh.faces):,} triangles, {COUNT:,} points; medians in ms; ratio = other / pyclray "
              "(wall; and of the process CPU time, all threads)")
        print(f"| points | query | pyclray | other | ratio | CPU ratio |\n|---|---|---:|---:|---:|---:|")
        for _, label, query, mine, other in rows:
            print(f"| {label} | {query} | {mine[0]:.1f} | {other[0]:.1f} | {other[0] / mine[0]:.2f} | {other[1] / mine[1]:.2f} |")
        print(f"sign errors of {SIGN_POINTS:,} points at {SIGN_OFFSET:g} of the size from the surface:")
        for key, value in errors.items():
            print(f"  {key}: {value}")
    print(f"\nload after: {os.getloadavg()[0]:.2f}; {time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main()
