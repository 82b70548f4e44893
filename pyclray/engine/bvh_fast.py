"""Compiled passes over a large scene's boxes (numba): a mesh's triangle bounds from its shared
vertices and faces (engine/indexed.py), and the widened bounds the BVH is built over (bvh.widened).
Imported for large scenes only, as bvh_sah: numba's import would cost every small scene's cold start.

Each writes the same float64 operations, in the same order, as the numpy it replaces (no fastmath, no
contraction: numba compiles a * b + c as written), so the bounds keep their bits; each makes one pass
over its input instead of numpy's several temporaries (a million triangles' corners gathered, their
minimum and maximum, the padding: 0.12 s in numpy, 10 ms here)."""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def triangle_bounds(vertices, faces, out):
    """out[f] = base.padded_bounds of face f's triangle: the min and max of its three vertices (xyz of
    (V, 4) float64), padded by 1e-12 (|lo| + |hi|) + 1e-300."""
    for f in range(faces.shape[0]):
        i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
        for a in range(3):
            x, y, z = vertices[i, a], vertices[j, a], vertices[k, a]
            lo = min(min(x, y), z)
            hi = max(max(x, y), z)
            pad = 1e-12 * (abs(lo) + abs(hi)) + 1e-300
            out[f, 0, a] = lo - pad
            out[f, 1, a] = hi + pad


@numba.njit(cache=True, nogil=True)
def widen(bounds, widen_by, out):
    """out = bvh.widened(bounds): each box grown on every side by widen_by times its largest side."""
    for n in range(bounds.shape[0]):
        size = 0.0
        for a in range(3):
            size = max(size, bounds[n, 1, a] - bounds[n, 0, a])
        size *= widen_by
        for a in range(3):
            out[n, 0, a] = bounds[n, 0, a] - size
            out[n, 1, a] = bounds[n, 1, a] + size
