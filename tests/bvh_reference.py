"""A plain float64 traversal of a BVH (pyclray/engine/bvh/tree.py's flat layout), the reference the BVH
tests hold the builders' trees to."""
import numpy as np


def traverse_reference(tree, origin, direction, t_max=np.inf):
    """The shapes (positions in the input bounds) whose leaf boxes the ray origin + t direction,
    0 < t <= t_max, meets: a stack traversal of tree (a pyclray.engine.bvh.tree.BVH)."""
    origin = np.asarray(origin, np.float64)
    direction = np.asarray(direction, np.float64)
    out = []
    stack = [0]
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = 1.0 / direction
    while stack:
        k = stack.pop()
        with np.errstate(invalid="ignore"):
            t0 = (tree.lo[k] - origin) * inverse
            t1 = (tree.hi[k] - origin) * inverse
        # an axis the ray is parallel to: inside the slab or not at all
        parallel = direction == 0
        inside = (origin >= tree.lo[k]) & (origin <= tree.hi[k])
        near = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t0, t1))
        far = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t0, t1))
        enter, leave = max(near.max(), 0.0), min(far.min(), t_max)
        if enter > leave:
            continue
        if tree.count[k] > 0:
            out.extend(tree.order[tree.first[k]: tree.first[k] + tree.count[k]].tolist())
        else:
            stack += [int(tree.first[k]), int(tree.first[k]) + 1]
    return sorted(out)
