"""Compiled passes over a large scene's boxes (numba): a mesh's triangle bounds from its shared
vertices and faces (engine/scene/indexed.py), the widened bounds the BVH is built over (bvh.widened), the
binary nodes' packing (bvh.pack_nodes) and the SAH tree's float64 node boxes (bvh_sah).
Imported for large scenes only, as bvh_sah: numba's import would cost every small scene's cold start.

Each writes the same float64 operations, in the same order, as the numpy it replaces (no fastmath, no
contraction: numba compiles a * b + c as written), so the bounds keep their bits; each makes one pass
over its input instead of numpy's several temporaries (a million triangles' corners gathered, their
minimum and maximum, the padding; docs/benchmarks.md, "Why the engine does what it does")."""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def _least(x, y):
    """numpy's minimum: a NaN wins"""
    return x if x < y or x != x else y


@numba.njit(cache=True, inline="always")
def _most(x, y):
    """numpy's maximum: a NaN wins"""
    return x if x > y or x != x else y


@numba.njit(cache=True, nogil=True)
def triangle_bounds(vertices, faces, out):
    """out[f] = base.padded_bounds of face f's triangle: the min and max of its three vertices (xyz of
    (V, 4) float64), padded by 1e-12 (|lo| + |hi|) + 1e-300."""
    for f in range(faces.shape[0]):
        i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
        for a in range(3):
            x, y, z = vertices[i, a], vertices[j, a], vertices[k, a]
            lo, hi = _least(_least(x, y), z), _most(_most(x, y), z)
            pad = 1e-12 * (abs(lo) + abs(hi)) + 1e-300
            out[f, 0, a] = lo - pad
            out[f, 1, a] = hi + pad


@numba.njit(cache=True, nogil=True)
def widen(bounds, widen_by, out):
    """out = bvh.widened(bounds): each box grown on every side by widen_by times its largest side."""
    for n in range(bounds.shape[0]):
        size = 0.0
        for a in range(3):
            extent = bounds[n, 1, a] - bounds[n, 0, a]
            if extent > size or extent != extent:  # a NaN wins, as in numpy's max
                size = extent
        size *= widen_by
        for a in range(3):
            out[n, 0, a] = bounds[n, 0, a] - size
            out[n, 1, a] = bounds[n, 1, a] + size


_FLOAT_MAX = float(np.finfo(np.float32).max)


@numba.njit(cache=True, nogil=True)
def pack_binary(lo, hi, first, count, origin, out, bits):
    """bvh.pack_nodes in one pass: each corner relative to origin in float64, kept within float32's
    finite range (a NaN stays NaN), rounded outward to float32 (bvh.outward32's bits), and first and
    count as the bits of w (out: the (M, 8) float32 view of the node array, bits its int32 view).
    Both roundings are computed and one kept: which one is a coin toss per corner, a branch on it
    mispredicted half the time."""
    down, up = np.float32(-np.inf), np.float32(np.inf)
    for k in range(lo.shape[0]):
        for a in range(3):
            x = _least(_most(lo[k, a] - origin[a], -_FLOAT_MAX), _FLOAT_MAX)
            f = np.float32(x)
            below = np.nextafter(f, down)
            out[k, a] = below if f > x else f
            x = _least(_most(hi[k, a] - origin[a], -_FLOAT_MAX), _FLOAT_MAX)
            f = np.float32(x)
            above = np.nextafter(f, up)
            out[k, 4 + a] = above if f < x else f
        bits[k, 3], bits[k, 7] = first[k], count[k]


@numba.njit(cache=True, nogil=True)
def pack_wide_boxes(lo, hi, binary, origin, out):
    """bvh_wide.pack_wide's boxes in one pass (the same bits as its numpy form, bvh.outward32's):
    slot s of wide node w holds binary node binary[w, s] (an empty slot, < 0: lo > hi), its
    corners relative to origin in float64, rounded outward to float32 (out: the (W, 56) float32 view
    of the wide nodes, rows lo_x, lo_y, lo_z, hi_x, hi_y, hi_z of 8 lanes). The numpy form gathers
    the (W, 8, 3) corners and writes each row through a strided view: 2/3 of a 1,000,000-triangle
    mesh's wide tree packing."""
    down, up = np.float32(-np.inf), np.float32(np.inf)
    for w in range(binary.shape[0]):
        for s in range(8):
            k = binary[w, s]
            for a in range(3):
                if k < 0:
                    out[w, 8 * a + s] = np.float32(_FLOAT_MAX)
                    out[w, 24 + 8 * a + s] = np.float32(-_FLOAT_MAX)
                    continue
                x = _least(_most(lo[k, a] - origin[a], -_FLOAT_MAX), _FLOAT_MAX)
                f = np.float32(x)
                below = np.nextafter(f, down)
                out[w, 8 * a + s] = below if f > x else f
                x = _least(_most(hi[k, a] - origin[a], -_FLOAT_MAX), _FLOAT_MAX)
                f = np.float32(x)
                above = np.nextafter(f, up)
                out[w, 24 + 8 * a + s] = above if f < x else f


@numba.njit(cache=True, nogil=True)
def leaf_boxes(bounds, index, first, count, lo, hi, p0, p1, ordered):
    """The float64 boxes of the leaves over leaf positions p0 .. p1 - 1 (whole leaves: a leaf's first
    position in range), each the exact union of its primitives' bounds. The bounds of the range are
    first gathered into leaf order in one sequential pass (its loads overlap, where leaf by leaf each
    waits; docs/benchmarks.md, "Why the engine does what it does"), into ordered (scratch of p1 - p0
    rows)."""
    for p in range(p0, p1):
        q = index[p]
        for side in range(2):
            for a in range(3):
                ordered[p - p0, side, a] = bounds[q, side, a]
    for k in range(first.shape[0]):
        if count[k] > 0 and p0 <= first[k] < p1:
            for a in range(3):
                low, high = np.inf, -np.inf
                for p in range(first[k], first[k] + count[k]):
                    low = min(low, ordered[p - p0, 0, a])
                    high = max(high, ordered[p - p0, 1, a])
                lo[k, a], hi[k, a] = low, high


@numba.njit(cache=True, nogil=True)
def inner_boxes(first, count, lo, hi):
    """The internal nodes' boxes, bottom up (children come after their parent): the union of their
    two children's."""
    for k in range(first.shape[0] - 1, -1, -1):
        if count[k] == 0:
            c = first[k]
            for a in range(3):
                lo[k, a] = min(lo[c, a], lo[c + 1, a])
                hi[k, a] = max(hi[c, a], hi[c + 1, a])


@numba.njit(cache=True, nogil=True)
def leaf_cut(first, count, p, n):
    """The first of the n leaf positions at or after p where a leaf starts (n where none does)."""
    best = n
    for k in range(first.shape[0]):
        if count[k] > 0 and p <= first[k] < best:
            best = first[k]
    return best
