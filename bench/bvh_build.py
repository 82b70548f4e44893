"""pyclray's BVH builder against a full binned SAH build: build time and tree quality (SAH cost), on
the benchmark's sphere fields and on triangle soups; and what the tree's quality does to render time.

    python -m bench.bvh_build                   # the tables (about ten minutes: the reference is slow)
    python -m bench.bvh_build --quick           # 100,000 primitives only
    python -m bench.bvh_build --mesh bunny.off  # a mesh file of yours too (trimesh reads it)
    python -m bench.bvh_build --render          # render and cast times through each tree

The reference (``reference``) is a full binned SAH build written for clarity, in vectorized numpy,
level by level: at every node, 32 bins along each of the three axes, every split between bins
weighed by the surface area heuristic (traversal and intersection cost 1, as bvh.sah_cost), a leaf
where the node holds at most LEAF_SIZE primitives and testing them costs no more than the best
split. It is slow (seconds per 100,000 primitives) and independent of pyclray.engine.bvh.sah's
compiled builder, which it checks. The SAH cost (bvh.sah_cost: the expected number of box and
primitive tests of a random ray, relative to the root's area) is the quality measure.

Build times: "warm" is the best of three builds in this process after one untimed build; "cold" is
a new process's first build, numba's import and the load of its compiled code from its disk cache
included (a new process per figure, the primitives made before the clock starts); "first ever" the
same with an empty numba cache (the compile, once per installation).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from pyclray.engine.bvh import tree as bvh

from . import scale

BINS = 32


def _half_area(lo, hi):
    extent = np.maximum(hi - lo, 0.0)
    return extent[..., 0] * extent[..., 1] + extent[..., 1] * extent[..., 2] + extent[..., 2] * extent[..., 0]


def reference(bounds: np.ndarray, leaf_size: int = bvh.LEAF_SIZE, bins: int = BINS, traversal: float = 1.0) -> bvh.BVH:
    """The full binned SAH tree over these (N, 2, 3) bounds, built level by level (each level's
    nodes at once), in bvh.BVH's layout (children numbered level by level). traversal: a node's
    visit in shape tests (the scene's trees are built with bvh.SCENE_TRAVERSAL)."""
    bounds = np.asarray(bounds, np.float64)
    n = len(bounds)
    lo_all, hi_all = bounds[:, 0], bounds[:, 1]
    centre_all = lo_all + hi_all  # doubled centroids
    order = np.arange(n)
    starts, counts, ids = np.array([0]), np.array([n]), np.array([0])
    first, count, next_id = [np.zeros(1, np.int64)], [np.zeros(1, np.int64)], 1
    rows = []  # (node ids, their first, their count) per level
    while starts.size:
        m = len(starts)
        node = np.repeat(np.arange(m), counts)
        position = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) + np.repeat(starts, counts)
        shapes = order[position]
        lo, hi, centre = lo_all[shapes], hi_all[shapes], centre_all[shapes]
        at = np.cumsum(counts) - counts
        area = _half_area(np.minimum.reduceat(lo, at, axis=0), np.maximum.reduceat(hi, at, axis=0))
        c_lo, c_hi = np.minimum.reduceat(centre, at, axis=0), np.maximum.reduceat(centre, at, axis=0)
        extent = c_hi - c_lo
        scale_ = np.where(extent > 0, bins * (1 - 1e-9) / np.where(extent > 0, extent, 1.0), 0.0)
        bin_of = np.clip(((centre - c_lo[node]) * scale_[node]).astype(np.int64), 0, bins - 1)  # (P, 3)
        best_cost = np.full(m, np.inf)
        best_axis = np.zeros(m, np.int64)
        best_k = np.zeros(m, np.int64)
        for axis in range(3):
            key = node * bins + bin_of[:, axis]
            bin_n = np.bincount(key, minlength=m * bins).reshape(m, bins)
            bin_lo = np.full((m * bins, 3), np.inf)
            bin_hi = np.full((m * bins, 3), -np.inf)
            np.minimum.at(bin_lo, key, lo)
            np.maximum.at(bin_hi, key, hi)
            bin_lo, bin_hi = bin_lo.reshape(m, bins, 3), bin_hi.reshape(m, bins, 3)
            # splitting after bin k: bins 0..k to the left, k+1.. to the right
            left = _half_area(np.minimum.accumulate(bin_lo, axis=1), np.maximum.accumulate(bin_hi, axis=1))[:, :-1]
            right = _half_area(np.minimum.accumulate(bin_lo[:, ::-1], axis=1)[:, ::-1],
                               np.maximum.accumulate(bin_hi[:, ::-1], axis=1)[:, ::-1])[:, 1:]
            left_n = np.cumsum(bin_n, axis=1)[:, :-1]
            right_n = counts[:, None] - left_n
            cost = np.where((left_n > 0) & (right_n > 0) & (scale_[:, axis, None] > 0), left * left_n + right * right_n, np.inf)
            k = np.argmin(cost, axis=1)
            better = cost[np.arange(m), k] < best_cost
            best_cost[better], best_axis[better], best_k[better] = cost[np.arange(m), k][better], axis, k[better]
        split_cost = traversal + best_cost / np.where(area > 0, area, np.inf)
        leaf = (counts == 1) | ((counts <= leaf_size) & (counts <= split_cost))
        halve = ~leaf & ~np.isfinite(best_cost)  # every centroid alike: the halves as they are
        split = ~leaf
        # reorder each split node's shapes: the left side's first (a stable sort within the node)
        right_side = bin_of[np.arange(len(shapes)), best_axis[node]] > best_k[node]
        right_side &= ~halve[node]
        sort = np.lexsort((right_side, node))
        order[position] = shapes[sort]
        left_count = np.where(halve, counts // 2, np.bincount(node, weights=~right_side, minlength=m).astype(np.int64))
        child_ids = next_id + 2 * np.cumsum(split) - 2
        next_id += 2 * int(split.sum())
        rows.append((ids, np.where(split, child_ids, starts), np.where(split, 0, counts)))
        starts = np.stack([starts[split], starts[split] + left_count[split]], axis=1).ravel()
        counts = np.stack([left_count[split], counts[split] - left_count[split]], axis=1).ravel()
        ids = np.stack([child_ids[split], child_ids[split] + 1], axis=1).ravel()
    first, count = np.zeros(next_id, np.int32), np.zeros(next_id, np.int32)
    for level_ids, level_first, level_count in rows:
        first[level_ids], count[level_ids] = level_first, level_count
    lo, hi = np.empty((next_id, 3)), np.empty((next_id, 3))
    # boxes bottom up: leaves by one reduceat (their ranges partition order), then the levels
    leaf = np.flatnonzero(count > 0)
    leaf = leaf[np.argsort(first[leaf])]
    lo[leaf] = np.minimum.reduceat(lo_all[order], first[leaf], axis=0)
    hi[leaf] = np.maximum.reduceat(hi_all[order], first[leaf], axis=0)
    for level_ids, _, level_count in reversed(rows):
        inner = level_ids[level_count == 0]
        lo[inner] = np.minimum(lo[first[inner]], lo[first[inner] + 1])
        hi[inner] = np.maximum(hi[first[inner]], hi[first[inner] + 1])
    return bvh.BVH(lo, hi, first, count, order)


# -- the primitives ---------------------------------------------------------------------------------

def triangle_bounds(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    corners = vertices[faces]
    return np.stack([corners.min(axis=1), corners.max(axis=1)], axis=1)


def _quads(nu: int, nv: int, closed_v: bool):
    """The two triangles of each cell of an nu x nv grid of vertices (u wrapping around, v wrapping
    where closed_v)."""
    u, v = np.meshgrid(np.arange(nu), np.arange(nv if closed_v else nv - 1), indexing="ij")
    u, v = u.ravel(), v.ravel()
    a, b = u * nv + v, ((u + 1) % nu) * nv + v
    c, d = ((u + 1) % nu) * nv + (v + 1) % nv, u * nv + (v + 1) % nv
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def tessellated_sphere(triangles: int) -> np.ndarray:
    """A UV sphere of radius 1 with about this many triangles (thin ones at the poles)."""
    nv = int(np.sqrt(triangles / 4))
    nu = triangles // (2 * (nv - 1))
    theta, phi = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False), np.linspace(0, np.pi, nv), indexing="ij")
    vertices = np.stack([np.sin(phi) * np.cos(theta), np.cos(phi), np.sin(phi) * np.sin(theta)], -1).reshape(-1, 3)
    return triangle_bounds(vertices, _quads(nu, nv, False))


def torus(triangles: int, major: float = 1.0, minor: float = 0.3) -> np.ndarray:
    nv = int(np.sqrt(triangles / 8))
    nu = triangles // (2 * nv)
    theta, phi = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False), np.linspace(0, 2 * np.pi, nv, endpoint=False),
                             indexing="ij")
    ring = major + minor * np.cos(phi)
    vertices = np.stack([ring * np.cos(theta), minor * np.sin(phi), ring * np.sin(theta)], -1).reshape(-1, 3)
    return triangle_bounds(vertices, _quads(nu, nv, True))


def grid(triangles: int) -> np.ndarray:
    """A flat square grid of triangles in the plane y = 0 (boxes of no height: areas of one face)."""
    side = int(np.sqrt(triangles / 2)) + 1
    x, z = np.meshgrid(np.linspace(-1, 1, side), np.linspace(-1, 1, side), indexing="ij")
    vertices = np.stack([x, np.zeros_like(x), z], -1).reshape(-1, 3)
    u, v = np.meshgrid(np.arange(side - 1), np.arange(side - 1), indexing="ij")
    a = (u * side + v).ravel()
    faces = np.concatenate([np.stack([a, a + side, a + side + 1], 1), np.stack([a, a + side + 1, a + 1], 1)])
    return triangle_bounds(vertices, faces)


def mesh_file(path: str) -> np.ndarray:
    import trimesh  # only for --mesh

    mesh = trimesh.load(path, process=False, force="mesh")
    return triangle_bounds(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces))


def cases(quick: bool, meshes=()) -> dict:
    """name -> a function making the widened (N, 2, 3) bounds the scene's BVH is built over."""
    sizes = (100_000,) if quick else (100_000, 1_000_000)
    out = {}
    for n in sizes:
        out[f"spheres uniform {n:,}"] = lambda n=n: scale.sphere_boxes(n)
        out[f"spheres clustered {n:,}"] = lambda n=n: scale.sphere_boxes(n, clustered=True)
    n = sizes[-1]
    out[f"tessellated sphere {n:,}"] = lambda: tessellated_sphere(n)
    out[f"torus {n:,}"] = lambda: torus(n)
    out[f"grid {n:,}"] = lambda: grid(n)
    for path in meshes:
        out[os.path.basename(path)] = lambda path=path: mesh_file(path)
    return {name: (lambda make=make: bvh.widened(make())) for name, make in out.items()}


# -- build times and quality ------------------------------------------------------------------------

COLD = """
import sys, time
import numpy as np
bounds = np.load(sys.argv[1])
from pyclray.engine.bvh import tree as bvh
start = time.perf_counter()
bvh.build(bounds)
print(time.perf_counter() - start)
"""


def cold_seconds(bounds: np.ndarray, numba_cache: str | None = None) -> float:
    """A new process's first bvh.build of these bounds (numba_cache: its cache folder, None for the
    usual one)."""
    env = dict(os.environ)
    if numba_cache is not None:
        env["NUMBA_CACHE_DIR"] = numba_cache
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "bounds.npy")
        np.save(path, bounds)
        out = subprocess.run([sys.executable, "-c", COLD, path], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.split()[-1])


def warm_seconds(bounds: np.ndarray, method: str | None = None, repeat: int = 3) -> float:
    bvh.build(bounds, method=method)
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        bvh.build(bounds, method=method)
        best = min(best, time.perf_counter() - start)
    return best


def quality(quick: bool, meshes=()) -> list[str]:
    lines = ["| primitives | N | SAH cost: reference | pyclray (SAH) | ratio | LBVH | ratio | "
             "build ms: pyclray warm | cold | LBVH warm | reference |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    print("\n".join(lines), flush=True)
    for name, make in cases(quick, meshes).items():
        bounds = make()
        start = time.perf_counter()
        ref = bvh.sah_cost(reference(bounds))
        ref_s = time.perf_counter() - start
        ours, lbvh = bvh.sah_cost(bvh.build(bounds, method="sah")), bvh.sah_cost(bvh.build(bounds, method="lbvh"))
        warm, cold, lbvh_warm = warm_seconds(bounds), cold_seconds(bounds), warm_seconds(bounds, "lbvh")
        lines.append(f"| {name} | {len(bounds):,} | {ref:.1f} | {ours:.1f} | {ours / ref:.3f} | {lbvh:.1f} | "
                     f"{lbvh / ref:.3f} | {1e3 * warm:.0f} | {1e3 * cold:.0f} | {1e3 * lbvh_warm:.0f} | {1e3 * ref_s:.0f} |")
        print(lines[-1], flush=True)
    return lines


def first_ever(count: int = 100_000) -> str:
    """A new process's first build with an empty numba cache (numba compiles the builder)."""
    bounds = bvh.widened(scale.sphere_boxes(count))
    with tempfile.TemporaryDirectory() as cache:
        compile_ = cold_seconds(bounds, cache)
        cached = cold_seconds(bounds, cache)
    return (f"first ever build (empty numba cache, {count:,} spheres): {compile_:.2f} s; "
            f"the next process's, from that cache: {cached:.2f} s")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.bvh_build", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="100,000 primitives only")
    parser.add_argument("--mesh", action="append", default=[], help="a mesh file to add (read by trimesh)")
    parser.add_argument("--render", action="store_true", help="render and cast times through each tree")
    args = parser.parse_args(argv)
    print(f"load average: {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)")
    if args.render:
        from . import bvh_render

        bvh_render.main(args.quick)
        return
    print(first_ever())
    quality(args.quick, args.mesh)


if __name__ == "__main__":
    main()
