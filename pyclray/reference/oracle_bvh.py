"""Which shapes each ray may hit, from the scene's BVH, and the oracle's two nearest hits.

The BVH is pyclray's own (engine.bvh: an LBVH over each bounded shape's box, widened); it is
traversed for a whole chunk of rays at once, breadth first: the (ray, node) pairs of one level are
slab-tested together, the hits' children form the next level's pairs, and the leaves give the
(ray, shape) pairs to test. The slab test is conservative (boxes widened by bvh.WIDEN of their size,
and a margin on the entry and exit distances), so a shape whose test would hit is never dropped;
a pair too many only costs its test. Unbounded shapes (a plane) are tested against every ray.
"""
from __future__ import annotations

import numpy as np

CHUNK = 1 << 16  # rays traversed together: bounded memory (a level's pairs) and progress steps


def by_shape(ids: np.ndarray):
    """(shape index, positions) for each shape index >= 0 present in ids: one sort, not a pass over
    all rays per shape."""
    order = np.argsort(ids, kind="stable")
    sorted_ids = ids[order]
    starts = np.flatnonzero(np.r_[True, sorted_ids[1:] != sorted_ids[:-1]])
    ends = np.r_[starts[1:], len(ids)]
    for start, end in zip(starts, ends):
        if sorted_ids[start] >= 0:
            yield int(sorted_ids[start]), order[start:end]


_last: dict = {}  # pad -> (shapes tuple, tree): the scene last traced (a check traces one scene many times)


def shape_tree(scene, pad: float = 0.0):
    """(BVH over the bounded shapes' boxes, each widened by pad too, their shape indices, the
    indices of the shapes tested against every ray), kept for the last tuple of shapes."""
    kept = _last.get(pad)
    if kept is not None and kept[0] is scene.shapes:
        return kept[1]
    if len(_last) > 4:
        _last.clear()
    _last[pad] = (scene.shapes, _build_tree(scene, pad))
    return _last[pad][1]


LARGE = 0.25  # a shape whose box spans more than this part of all the boxes' is tested against every ray


def _build_tree(scene, pad: float = 0.0):
    """The tree over the bounded shapes but the large ones: a box as large as the scene (the ground
    sphere of radius 1000 under the book's 486 spheres) holds every ray anyway, and would make the
    Morton codes of all the others' centres coarse (an LBVH of ties); such shapes, and the unbounded
    ones, are tested against every ray."""
    from ..engine.bvh.tree import build, widened

    bounded = [index for index, shape in enumerate(scene.shapes) if shape.bounded]
    boxes = np.array([scene.shapes[index].box() for index in bounded]).reshape(-1, 2, 3)
    diagonal = np.linalg.norm(boxes[:, 1] - boxes[:, 0], axis=1)
    span = np.linalg.norm(boxes[:, 1].max(axis=0) - boxes[:, 0].min(axis=0)) if len(boxes) else 0.0
    large = diagonal > LARGE * span if len(boxes) > 8 else np.zeros(len(boxes), bool)
    everywhere = sorted([index for index, shape in enumerate(scene.shapes) if not shape.bounded]
                        + [b for b, big in zip(bounded, large) if big])
    kept = np.array(bounded, np.int64)[~large]
    boxes = widened(boxes[~large]) + np.array([-pad, pad])[None, :, None]
    return build(boxes), kept, np.array(everywhere, np.int64)


def _slab_hits(tree, O, inverse, rays, nodes) -> np.ndarray:
    """Whether each ray meets each node's box at some t >= 0, conservatively: the slab distances are
    compared with a relative margin of 2e-9 (far above their rounding), so that a box the ray only
    grazes is kept. A direction's zero component has an inverse of +-1e300 (ray_inverses): a slab
    the origin lies in gives -+1e300 on its two sides (never a NaN), one it lies outside a distance
    beyond any other slab's."""
    o, inv = O[rays], inverse[rays]
    with np.errstate(over="ignore"):
        t0 = (tree.lo[nodes] - o) * inv
        t1 = (tree.hi[nodes] - o) * inv
    near, far = np.minimum(t0, t1), np.maximum(t0, t1)  # per axis (columns: numpy's reduce over 3 is slow)
    enter = np.maximum(np.maximum(near[:, 0], near[:, 1]), np.maximum(near[:, 2], 0.0))
    leave = np.minimum(np.minimum(far[:, 0], far[:, 1]), far[:, 2])
    return (leave >= 0) & (enter * (1 - 2e-9) <= leave * (1 + 2e-9))


def ray_inverses(D) -> np.ndarray:
    """1 / D, with +-1e300 for components of magnitude below 1e-300 (zero, or whose inverse overflows)."""
    with np.errstate(divide="ignore", over="ignore"):
        return np.where(np.abs(D) < 1e-300, np.copysign(1e300, D), 1.0 / D)


def candidates(tree, order, O, D) -> tuple[np.ndarray, np.ndarray]:
    """(rays, shapes) index pairs: each bounded shape whose (widened) box a ray crosses."""
    if not order.size:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    inverse = ray_inverses(D)
    rays, nodes = np.arange(len(D)), np.zeros(len(D), np.int64)
    found_rays, found_shapes = [], []
    while rays.size:
        hit = _slab_hits(tree, O, inverse, rays, nodes)
        rays, nodes = rays[hit], nodes[hit]
        count = tree.count[nodes]
        leaf = count > 0
        if leaf.any():  # each leaf's shapes: order[first .. first + count - 1]
            leaf_rays, first, n = rays[leaf], tree.first[nodes[leaf]].astype(np.int64), count[leaf].astype(np.int64)
            repeat = np.repeat(np.arange(len(n)), n)
            offset = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
            found_rays.append(leaf_rays[repeat])
            found_shapes.append(order[tree.order[first[repeat] + offset]])
        inner = ~leaf
        first = tree.first[nodes[inner]].astype(np.int64)
        rays = np.concatenate([rays[inner], rays[inner]])
        nodes = np.concatenate([first, first + 1])
    if not found_rays:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(found_rays), np.concatenate(found_shapes)


def ray_shape_pairs(tree, order, unbounded, O, D):
    """(rays, shapes): each ray with each shape whose box it crosses, and with each shape tested
    against every ray."""
    pair_rays, pair_shapes = candidates(tree, order, O, D)
    if unbounded.size:
        pair_rays = np.concatenate([pair_rays, np.tile(np.arange(len(D)), len(unbounded))])
        pair_shapes = np.concatenate([pair_shapes, np.repeat(unbounded, len(D))])
    return pair_rays, pair_shapes


def near_pairs(scene, O, D, pad: float):
    """(rays, shapes): every shape that a ray parallel to one of these, at most pad from it, may
    meet (its box, widened by pad, crosses the ray): the shapes a slightly moved ray is tested with."""
    return ray_shape_pairs(*shape_tree(scene, pad), O, D)


def any_hit(scene, pairs, O, D, limit) -> np.ndarray:
    """Per ray, whether one of its pairs' shapes is hit at some 0 < t < limit (limit per ray)."""
    pair_rays, pair_shapes = pairs
    blocked = np.zeros(len(D), bool)
    for index, mine in by_shape(pair_shapes):
        rays = pair_rays[mine]
        t = scene.shapes[index].oracle_distance(O[rays], D[rays])
        blocked[rays[t < limit[rays]]] = True
    return blocked


def hits(scene, tree, order, unbounded, O, D):
    """(rays, shapes, t) of every finite hit t > 0 of a shape test on these rays."""
    pair_rays, pair_shapes = ray_shape_pairs(tree, order, unbounded, O, D)
    t = np.full(len(pair_rays), np.inf)
    for index, mine in by_shape(pair_shapes):
        rays = pair_rays[mine]
        t[mine] = scene.shapes[index].oracle_distance(O[rays], D[rays])
    finite = np.isfinite(t)
    return pair_rays[finite], pair_shapes[finite], t[finite]


def nearest_two(scene, O, D, update=None):
    """(best t, its shape, second t, its shape) per ray: the nearest hit and the nearest of any other
    shape (inf and -1 where none); an exact tie of t goes to the lower shape index."""
    n = len(D)
    best, second = np.full(n, np.inf), np.full(n, np.inf)
    best_id, second_id = np.full(n, -1, np.int32), np.full(n, -1, np.int32)
    tree, order, unbounded = shape_tree(scene)
    for start in range(0, n, CHUNK):
        stop = min(start + CHUNK, n)
        rays, shapes, t = hits(scene, tree, order, unbounded, O[start:stop], D[start:stop])
        # per ray, its hits by increasing t, then shape index: the first is the nearest, the next the second
        sort = np.lexsort((shapes, t, rays))
        rays, shapes, t = rays[sort], shapes[sort], t[sort]
        first = np.flatnonzero(np.r_[True, rays[1:] != rays[:-1]]) if rays.size else np.zeros(0, np.int64)
        best[start + rays[first]], best_id[start + rays[first]] = t[first], shapes[first]
        runner = first + 1
        has = runner < len(rays)
        has[has] &= rays[runner[has]] == rays[first[has]]
        second[start + rays[first[has]]], second_id[start + rays[first[has]]] = t[runner[has]], shapes[runner[has]]
        if update is not None:
            update(stop - start)
    return best, best_id, second, second_id
