"""count_hits and all_hits against Open3D's RaycastingScene (Embree) in one process (issue 38's targets).

    python -m bench.hits [--bunny PATH] [--rounds 3] [--block 3] [--rays 100000]

Cases, each timed in rotating blocks with a pause at each switch (bench.open3d_compare.blocks), on the
meshes of bench.meshes (the bunny, ~80,000 triangles, and a 1,000,000-triangle perturbed UV sphere):
- count: pyclray.count_hits against Open3D's count_intersections of the same 100,000 incoherent
  rays (random origins in the mesh's box, uniform directions; bench.meshes.incoherent_rays);
- list: pyclray.all_hits (depth, id, primitive) against list_intersections (its ray splits, t_hit,
  geometry ids, primitive ids and uvs) of the same rays.
Beside the times, correctness: rays from outside the mesh aimed exactly at each vertex and each
edge's midpoint (up to --targets of them) must cross a closed mesh an even number of times; the
table counts each system's odd counts (both meshes are closed: every edge is shared by two triangles). Prints a table of medians (ms), the ratios and the correctness counts. The
machine is shared: compare ratios (run `uptime` beside).
"""
from __future__ import annotations

import argparse

import numpy as np

import pyclray

from .meshes import camera_for, incoherent_rays, meshes, open3d_scene
from .open3d_compare import blocks


def edge_targets(mesh, most: int, rng) -> np.ndarray:
    """Each vertex and each edge's midpoint of the mesh (world coordinates), at most ``most`` of them."""
    v, f = mesh.world_vertices(), mesh.faces
    edges = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    points = np.concatenate([v, 0.5 * (v[edges[:, 0]] + v[edges[:, 1]])])
    return points[rng.choice(len(points), min(most, len(points)), replace=False)]


def closed(mesh) -> bool:
    """Whether every edge of the mesh is shared by exactly two of its triangles."""
    f = mesh.faces
    _, uses = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0,
                        return_counts=True)
    return bool((uses == 2).all())


def parity_rays(mesh, most: int):
    """Origins outside the mesh's bounding sphere (two to three radii from its centre) and directions
    toward each target."""
    rng = np.random.default_rng(2)
    lo, hi = mesh.box()
    centre, radius = 0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo)
    goal = edge_targets(mesh, most, rng)
    away = rng.normal(size=goal.shape)
    origins = centre + away / np.linalg.norm(away, axis=1, keepdims=True) * radius * rng.uniform(2, 3, (len(goal), 1))
    return origins, goal - origins


def run(bunny_path=None, rounds=3, block=3, count=100_000, most=100_000):
    import open3d as o3d

    rows, correctness = [], []
    for label, mesh in meshes(bunny_path).items():
        scene = camera_for(mesh, 64)
        tracer = pyclray.prepare(scene)
        o3d_scene = open3d_scene(mesh)
        origins, directions = incoherent_rays(mesh, count)
        rays = o3d.core.Tensor(np.hstack([origins, directions]).astype(np.float32))
        ours = tracer.count_hits(origins, directions)
        theirs = o3d_scene.count_intersections(rays).numpy()
        agree = float(np.mean(ours == theirs))
        timed = blocks({"pyclray": lambda: tracer.count_hits(origins, directions),
                        "open3d": lambda: o3d_scene.count_intersections(rays)}, rounds, block)
        rows.append((f"{label} ({len(mesh.faces):,} triangles): count_hits / count_intersections, {count:,} rays "
                     f"({ours.sum() / count:.2f} hits a ray; same count on {agree:.2%})", timed))
        timed = blocks({"pyclray": lambda: tracer.all_hits(origins, directions),
                        "open3d": lambda: o3d_scene.list_intersections(rays)}, rounds, block)
        rows.append((f"{label}: all_hits / list_intersections, {count:,} rays", timed))
        o, d = parity_rays(mesh, most)
        ours = tracer.count_hits(o, d)
        theirs = o3d_scene.count_intersections(o3d.core.Tensor(np.hstack([o, d]).astype(np.float32))).numpy()
        correctness.append(f"{label} ({'closed' if closed(mesh) else 'open: odd counts may be right'}): {len(o):,} rays "
                           f"from outside aimed at vertices and edge midpoints: odd counts "
                           f"pyclray {int(np.sum(ours % 2))}, Open3D {int(np.sum(theirs % 2))}")
        tracer.close()
        del o3d_scene
    return rows, correctness


def table(rows, correctness) -> str:
    lines = ["| case | pyclray (ms) | Open3D (ms) | pyclray / Open3D speed |", "|---|---:|---:|---:|"]
    for name, timed in rows:
        p, o = timed["pyclray"]["median"], timed["open3d"]["median"]
        lines.append(f"| {name} | {p:.1f} | {o:.1f} | {o / p:.2f}x |")
    return "\n".join(lines + [""] + [f"- {line}" for line in correctness])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bunny", help="the 75,408-triangle Stanford bunny (CGAL's demo data), else a subdivided one")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--block", type=int, default=3)
    parser.add_argument("--rays", type=int, default=100_000)
    parser.add_argument("--targets", type=int, default=100_000, help="parity rays at most (vertices and edge midpoints)")
    args = parser.parse_args(argv)
    print(table(*run(args.bunny, args.rounds, args.block, args.rays, args.targets)))


if __name__ == "__main__":
    main()
