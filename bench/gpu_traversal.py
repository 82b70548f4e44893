"""The pair nodes (one ray per work-item: engine/bvh/pairs.py, kernels/bvh_pairs.h) beside the wide
tree they replace at a lane width of 1 (issue 41, items 1 and 3), on bench.meshes' bunny (80,000
triangles) and 1,000,000-triangle mesh, and on `--instances` instances of the bunny (its own tree's
pair nodes: kernels/instance.cl):

    python -m bench.gpu_traversal [--rounds 3] [--block 5] [--size 512] [--rays 100000] [--sample 2000]
                                  [--instances 50] [--cases bunny,1M,instances] [--points 100000]
                                  [--parts trees,reads,rays,closest]

- the trees: nodes and bytes of the wide tree (224 bytes a node), the binary one (32) and the pair
  nodes (64), and the conversion's time at prepare time (the binary nodes packed around the anchor,
  then the pair nodes: pack_nodes + pack_pairs, the median of 5);
- nodes read per ray (`--sample` of the incoherent rays, and the camera rays of every 64th pixel):
  each node whose box the ray enters before its nearest hit (pyclray's cast depth), in float64 on
  the binary tree's boxes: a pair node is read per internal binary node entered, a wide node per
  wide node entered; the leaves are the same in both. This is the part of a traversal no visiting
  order saves (the nearest hit found first): a lower bound of both, their ratio the reads' ratio;
- PoCL at a lane width of 1 (PYCLRAY_LANES=1, the programs a GPU builds): the pair nodes against
  the wide tree at one lane (PYCLRAY_TRAVERSAL=wide), render of size x size (depth, normal, id,
  primitive) and cast of `--rays` incoherent rays, each call's wall time in alternating blocks
  (bench.open3d_compare.blocks); the 8-lane default beside them for scale. The instances (the bunny
  placed on a square grid, each turned about y and scaled by 0.8-1.2, a mirrored one in every
  three): the same rows, the camera over the grid, the incoherent rays from within its box; no tree
  or read rows (their trees are the bunny's);
- the closest-point query likewise, on the bunny and the 1M mesh (issue 41, item 3): closest_points
  (every output) of `--points` points uniform in the mesh's box and as many near its surface
  (bench.points.near_points: within 1% of the box's size), the pair nodes' search against the wide
  tree's at one lane and the 8 lanes', with the ratio of the process CPU times.
`--parts` picks the parts (trees, reads, rays, closest; all by default).
Prints one table a part; the machine is shared: compare ratios, note the load printed.
"""
from __future__ import annotations

import argparse
import os
import time
from contextlib import contextmanager

import numpy as np

import pyclray
from pyclray.engine.api import tracer_for
from pyclray.engine.bvh.pairs import PAIR_NODE, leaf_codes, pack_pairs
from pyclray.engine.bvh.tree import NODE, pack_nodes
from pyclray.engine.bvh.wide import WIDE_NODE
from pyclray.engine.opencl.device import context_for
from pyclray.model.layout import layout

from .meshes import camera_for, incoherent_rays, meshes
from .open3d_compare import blocks
from .points import near_points

AOVS = ("depth", "normal", "id", "primitive")


@contextmanager
def environment(**values):
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update({k: str(v) for k, v in values.items()})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def entered(lo, hi, origins, directions, limits):
    """(rays, boxes) bool: the ray enters the box before its limit (float64 slab test)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = 1.0 / directions
        t0 = (lo[None] - origins[:, None]) * inverse[:, None]
        t1 = (hi[None] - origins[:, None]) * inverse[:, None]
    near = np.nan_to_num(np.minimum(t0, t1), nan=-np.inf).max(axis=2)
    far = np.nan_to_num(np.maximum(t0, t1), nan=np.inf).min(axis=2)
    return (np.maximum(near, 0.0) <= far) & (near <= limits[:, None])


def reads_per_ray(bvh, origins, directions, depth):
    """(pair nodes, wide nodes, leaves) entered per ray before its nearest hit (see the docstring)."""
    tree, wide = bvh.tree, bvh.wide
    inner = np.flatnonzero(tree.count == 0)
    leaves = np.flatnonzero(tree.count > 0)
    internal_slots = (wide.binary >= 0) & (tree.count[np.maximum(wide.binary, 0)] == 0)
    wide_sources = wide.binary[internal_slots]  # the binary node each wide node below the root opens
    limits = np.where(np.isfinite(depth), depth, np.inf)
    chunk = max(1, 2_000_000 // tree.nodes)  # rays at once: (chunk, nodes, 3) arrays of a few tens of MB
    pair, wide_reads, leaf = [], [], []
    for start in range(0, len(origins), chunk):
        o, d, t = origins[start:start + chunk], directions[start:start + chunk], limits[start:start + chunk]
        pair.append(entered(tree.lo[inner], tree.hi[inner], o, d, t).sum(axis=1))
        wide_reads.append(1 + entered(tree.lo[wide_sources], tree.hi[wide_sources], o, d, t).sum(axis=1))
        leaf.append(entered(tree.lo[leaves], tree.hi[leaves], o, d, t).sum(axis=1))
    return tuple(float(np.mean(np.concatenate(x))) for x in (pair, wide_reads, leaf))


def tree_rows(label, tracer):
    bvh = tracer.prepared.bvh
    anchor = tracer.prepared.anchor
    times = []
    for _ in range(5):
        start = time.perf_counter()
        pairs = pack_pairs(bvh.tree, pack_nodes(bvh.tree, anchor), leaf_codes(bvh.tree))
        times.append((time.perf_counter() - start) * 1e3)
    wide_bytes = layout(WIDE_NODE, "fp32").itemsize
    return [(f"{label}: wide nodes (x {wide_bytes} B)", len(bvh.wide.child), len(bvh.wide.child) * wide_bytes / 2**20, ""),
            (f"{label}: binary nodes (x {layout(NODE, 'fp32').itemsize} B)", bvh.tree.nodes,
             bvh.tree.nodes * layout(NODE, "fp32").itemsize / 2**20, ""),
            (f"{label}: pair nodes (x {layout(PAIR_NODE, 'fp32').itemsize} B)", len(pairs), pairs.nbytes / 2**20,
             f"conversion {np.median(times):.1f} ms")]


def instances_of(mesh, count: int) -> list:
    """A scene's shapes: the mesh placed count times on a square grid (mesh instances: one shared
    copy), each turned about y, scaled by 0.8-1.2 and every third mirrored, as one list."""
    rng = np.random.default_rng(2)
    lo, hi = mesh.box()
    size = float(np.max(hi - lo))
    side = int(np.ceil(np.sqrt(count)))
    shapes = []
    for k in range(count):
        scale = float(rng.uniform(0.8, 1.2))
        shapes.append(mesh.placed(scale=(-scale if k % 3 == 2 else scale, scale, scale), axis=(0.0, 1.0, 0.0),
                                  angle=float(rng.uniform(0, 360)),
                                  translate=tuple(1.3 * size * np.array([k % side, 0.0, k // side]) - 0.5 * (lo + hi))))
    return shapes


def at(lanes, traversal, fn):
    """fn, called with $PYCLRAY_LANES and $PYCLRAY_TRAVERSAL set."""
    def call():
        with environment(PYCLRAY_LANES=lanes, PYCLRAY_TRAVERSAL=traversal):
            return fn()
    return call


def timing_rows(label, scene, origins, directions, args):
    """The render's and the cast's medians: pairs at one lane, the wide tree at one lane and at 8."""
    rows = []
    render = lambda: pyclray.render(scene, AOVS, acceleration="bvh")  # noqa: E731
    cast = lambda: pyclray.cast(scene, origins, directions, aovs=AOVS)  # noqa: E731
    for name, fn in (("render", render), ("cast", cast)):
        systems = {"pairs, 1 lane": at(1, "pairs", fn), "wide, 1 lane": at(1, "wide", fn),
                   "wide, 8 lanes": at(8, "wide", fn)}
        timed = blocks(systems, args.rounds, args.block)
        what = f"{args.size}x{args.size} primary rays" if name == "render" else f"{len(origins):,} incoherent rays cast"
        rows.append((f"{label}: {what}", *(timed[s]["median"] for s in systems)))
    return rows


def closest_rows(label, mesh, scene, tracer, args):
    """closest_points' medians, uniform and near points: pairs at one lane, the wide tree at one
    lane and at 8, and the ratio of the first two's process CPU times."""
    rows = []
    rng = np.random.default_rng(2)
    lo, hi = mesh.box()
    for kind, points in (("uniform", rng.uniform(lo, hi, (args.points, 3))),
                         ("near the surface", near_points(tracer, lo, hi, args.points, rng))):
        query = lambda points=points: pyclray.closest_points(scene, points)  # noqa: E731
        systems = {"pairs, 1 lane": at(1, "pairs", query), "wide, 1 lane": at(1, "wide", query),
                   "wide, 8 lanes": at(8, "wide", query)}
        timed = blocks(systems, args.rounds, args.block)
        rows.append((f"{label}: {args.points:,} points {kind}", *(timed[s]["median"] for s in systems),
                     timed["pairs, 1 lane"]["cpu"] / timed["wide, 1 lane"]["cpu"]))
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--block", type=int, default=5)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--rays", type=int, default=100_000)
    parser.add_argument("--sample", type=int, default=2000)
    parser.add_argument("--instances", type=int, default=50)
    parser.add_argument("--cases", default="bunny,1M,instances")
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--parts", default="trees,reads,rays,closest")
    args = parser.parse_args(argv)
    cases, parts = args.cases.split(","), set(args.parts.split(","))
    ctx = context_for(None)
    trees, reads, timing, closest = [], [], [], []
    every = meshes(None)
    for label, mesh in every.items():
        if label not in cases:
            continue
        scene = camera_for(mesh, args.size)
        tracer = tracer_for(scene, ctx, "fp32")
        if "trees" in parts:
            trees += tree_rows(label, tracer)
        if "closest" in parts:
            closest += closest_rows(label, mesh, scene, tracer, args)
        if not parts & {"reads", "rays"}:
            continue
        origins, directions = incoherent_rays(mesh, args.rays)
        sample = slice(0, args.sample)
        if "reads" in parts:
            depth = pyclray.cast(scene, origins[sample], directions[sample], aovs=("depth",))["depth"].astype(np.float64)
            reads.append((f"{label}: {args.sample} incoherent rays",
                          *reads_per_ray(tracer.prepared.bvh, origins[sample], directions[sample], depth)))
            from pyclray.reference import oracle

            cam_o, cam_d = (a.reshape(-1, 3)[::64] for a in oracle.camera_rays(scene))
            cam_depth = pyclray.cast(scene, cam_o, cam_d, aovs=("depth",))["depth"].astype(np.float64)
            reads.append((f"{label}: camera rays (every 64th pixel)",
                          *reads_per_ray(tracer.prepared.bvh, cam_o, cam_d, cam_depth)))
        if "rays" in parts:
            timing += timing_rows(label, scene, origins, directions, args)
    if "instances" in cases and "rays" in parts:
        shapes = instances_of(every["bunny"], args.instances)
        lo = np.min([s.box()[0] for s in shapes], axis=0)
        hi = np.max([s.box()[1] for s in shapes], axis=0)
        centre, radius = 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))
        eye = centre + np.array([0.0, 0.6, 0.8]) * radius * 1.6
        scene = pyclray.Scene(pyclray.Camera(tuple(eye), tuple(centre), fov=45.0),
                              pyclray.Image(args.size, args.size), tuple(shapes))
        assert "instance" in tracer_for(scene, ctx, "fp32").prepared.types
        rng = np.random.default_rng(1)
        origins = rng.uniform(lo, hi, (args.rays, 3))
        directions = rng.normal(size=(args.rays, 3))
        timing += timing_rows(f"{args.instances} bunny instances", scene, origins, directions, args)
    print(f"PoCL on {ctx.device.name.strip()}; load {os.getloadavg()[0]:.1f}")
    if trees:  # (the meshes' cases)
        print("| tree | nodes | MiB | |\n|---|---|---|---|")
    for row in trees:
        print(f"| {row[0]} | {row[1]:,} | {row[2]:.2f} | {row[3]} |")
    if reads:
        print("\n| rays | pair nodes read | wide nodes read | bytes: pairs / wide | leaves entered |\n|---|---|---|---|---|")
    for case, pair, wide, leaves in reads:
        ratio = (pair * layout(PAIR_NODE, "fp32").itemsize) / (wide * layout(WIDE_NODE, "fp32").itemsize)
        print(f"| {case} | {pair:.1f} | {wide:.1f} | {ratio:.2f} | {leaves:.1f} |")
    if timing:
        print("\n| case (ms, medians) | pairs, 1 lane | wide, 1 lane | pairs / wide | wide, 8 lanes |\n|---|---|---|---|---|")
    for case, pairs, wide, eight in timing:
        print(f"| {case} | {pairs:.2f} | {wide:.2f} | {pairs / wide:.2f} | {eight:.2f} |")
    if closest:  # (and the ratio of the process CPU times: steadier on a shared machine)
        print("\n| closest_points (ms, medians) | pairs, 1 lane | wide, 1 lane | pairs / wide (CPU) | wide, 8 lanes |"
              "\n|---|---|---|---|---|")
    for case, pairs, wide, eight, cpu in closest:
        print(f"| {case} | {pairs:.2f} | {wide:.2f} | {pairs / wide:.2f} ({cpu:.2f}) | {eight:.2f} |")


if __name__ == "__main__":
    main()
