"""Why pyclray's BVH is an LBVH: its build time and tree quality against a top-down binned SAH
build, both in vectorized numpy, on the benchmark's sphere fields (bench/scale.py).

    python -m bench.bvh_build

The binned SAH here is the usual one (Wald 2007), level-synchronous so that numpy handles every
node of a level at once: per node, 16 bins along the longest axis of its centres' bounds, the
bins' boxes by one sort and reduceat, the best of the 15 splits by prefix and suffix scans, a leaf
where splitting costs more (or at most LEAF_SIZE shapes remain). The quality measure is the SAH
cost of the finished tree (pyclray.engine.bvh.sah_cost's definition: traversal 1 per internal node and 1
per shape of a leaf, weighted by area relative to the root's), which predicts the work of a random
ray through it.
"""
from __future__ import annotations

import time

import numpy as np

from pyclray.engine import bvh

from . import scale

BINS = 16


def _area(lo, hi):
    extent = np.maximum(hi - lo, 0.0)
    return extent[..., 0] * extent[..., 1] + extent[..., 1] * extent[..., 2] + extent[..., 2] * extent[..., 0]


def binned_sah(bounds: np.ndarray, leaf_size: int = bvh.LEAF_SIZE) -> float:
    """Build a binned SAH tree over the shapes' boxes; returns its SAH cost (the tree itself is
    not kept: only its cost and build time matter here)."""
    n = len(bounds)
    lo_all, hi_all = bounds[:, 0], bounds[:, 1]
    centre_all = 0.5 * (lo_all + hi_all)
    root_area = _area(lo_all.min(axis=0), hi_all.max(axis=0))
    order = np.arange(n)
    starts, counts = np.array([0]), np.array([n])  # the nodes of this level: ranges of order
    cost = 0.0
    while starts.size:
        m = len(starts)
        node = np.repeat(np.arange(m), counts)
        position = np.concatenate([np.arange(s, s + c) for s, c in zip(starts, counts)]) if m < 64 else (
            np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts) + np.repeat(starts, counts)
        )
        shapes = order[position]
        lo, hi, centre = lo_all[shapes], hi_all[shapes], centre_all[shapes]
        first = np.cumsum(counts) - counts
        node_lo = np.minimum.reduceat(lo, first, axis=0)
        node_hi = np.maximum.reduceat(hi, first, axis=0)
        c_lo = np.minimum.reduceat(centre, first, axis=0)
        c_hi = np.maximum.reduceat(centre, first, axis=0)
        area = _area(node_lo, node_hi)
        axis = np.argmax(c_hi - c_lo, axis=1)
        extent = (c_hi - c_lo)[np.arange(m), axis]
        c = centre[np.arange(len(shapes)), axis[node]]
        scale_ = np.where(extent > 0, BINS / np.where(extent > 0, extent, 1.0), 0.0)
        b = np.clip(((c - c_lo[node, axis[node]]) * scale_[node]).astype(np.int64), 0, BINS - 1)
        key = node * BINS + b
        sort = np.argsort(key, kind="stable")
        key_sorted = key[sort]
        uniq, at = np.unique(key_sorted, return_index=True)
        bin_lo = np.full((m * BINS, 3), np.inf)
        bin_hi = np.full((m * BINS, 3), -np.inf)
        bin_lo[uniq] = np.minimum.reduceat(lo[sort], at, axis=0)
        bin_hi[uniq] = np.maximum.reduceat(hi[sort], at, axis=0)
        bin_n = np.bincount(key, minlength=m * BINS).reshape(m, BINS)
        bin_lo, bin_hi = bin_lo.reshape(m, BINS, 3), bin_hi.reshape(m, BINS, 3)
        # split after bin j: left bins 0..j, right j+1..
        left_lo = np.minimum.accumulate(bin_lo, axis=1)[:, :-1]
        left_hi = np.maximum.accumulate(bin_hi, axis=1)[:, :-1]
        right_lo = np.minimum.accumulate(bin_lo[:, ::-1], axis=1)[:, ::-1][:, 1:]
        right_hi = np.maximum.accumulate(bin_hi[:, ::-1], axis=1)[:, ::-1][:, 1:]
        left_n = np.cumsum(bin_n, axis=1)[:, :-1]
        right_n = counts[:, None] - left_n
        split_cost = np.where((left_n > 0) & (right_n > 0),
                              _area(left_lo, left_hi) * left_n + _area(right_lo, right_hi) * right_n, np.inf)
        best = np.argmin(split_cost, axis=1)
        best_cost = split_cost[np.arange(m), best] / np.where(area > 0, area, 1.0) + 1.0
        splittable = np.isfinite(best_cost)
        split = (counts > leaf_size) & splittable & ((best_cost < counts) | (counts > 4 * leaf_size))
        # a node that cannot split by bins but is too big: halve it in its current order
        halve = (counts > leaf_size) & ~splittable
        cost += float((area[~split & ~halve] * counts[~split & ~halve]).sum() + area[split | halve].sum())
        # the next level: children ranges; the shapes of a split node reordered by bin
        order[position] = shapes[sort]
        left_count = np.where(split, left_n[np.arange(m), best], counts // 2)
        keep = split | halve
        starts = np.stack([starts[keep], starts[keep] + left_count[keep]], axis=1).ravel()
        counts = np.stack([left_count[keep], counts[keep] - left_count[keep]], axis=1).ravel()
    return cost / root_area


def main() -> None:
    print("| spheres | LBVH build ms | LBVH SAH cost | binned SAH build ms | binned SAH cost |")
    print("|---|---|---|---|---|")
    for count in (1_000, 10_000, 100_000, 1_000_000):
        centres, radii = scale.sphere_field(count)
        bounds = bvh.widened(np.stack([centres - radii[:, None], centres + radii[:, None]], axis=1))
        start = time.perf_counter()
        tree = bvh.build(bounds)
        lbvh_ms = (time.perf_counter() - start) * 1e3
        start = time.perf_counter()
        sah = binned_sah(bounds)
        sah_ms = (time.perf_counter() - start) * 1e3
        print(f"| {count:,} | {lbvh_ms:.0f} | {bvh.sah_cost(tree):.1f} | {sah_ms:.0f} | {sah:.1f} |", flush=True)


if __name__ == "__main__":
    main()
