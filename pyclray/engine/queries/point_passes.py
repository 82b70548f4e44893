"""Compiled passes over a large batch of query points (numba, as engine/queries/ray_order.py's, and
imported only for batches of at least closest.COHERENT_FROM points): their coherent order, and the
nearest face of a box per point (the direction of its parity ray: engine/queries/closest.py). Each
point is computed on its own: neither changes any bit of a result, only which points run side by
side and which (exact) ray decides a parity."""
from __future__ import annotations

import numba
import numpy as np

from .ray_order import _counting_sort, morton_tables

# points in 32 cells per axis of their box: 15 bits, the counting sort's range (ray_order.CODES)
POINT_CELLS = 32
POINT_TABLES = morton_tables((5, 5, 5))


@numba.njit(cache=True, nogil=True)
def _point_codes(points, lo, scale, tables):
    count = points.shape[0]
    codes = np.empty(count, np.uint16)
    top = POINT_CELLS - 1
    for i in range(count):
        code = np.uint16(0)
        for axis in range(3):
            value = min(max((points[i, axis] - lo[axis]) * scale[axis], 0.0), top)
            code |= tables[axis, int(value)]
        codes[i] = code
    return codes


def coherent_order(points: np.ndarray) -> np.ndarray:
    """int32 order[i]: the place of the i-th point along a 15-bit Morton curve of the points' box
    (one pass to code, a counting sort: numpy's 30-bit codes and argsort took 5 to 10 times as long)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    extent = hi - lo
    scale = np.where(extent > 0, POINT_CELLS / np.where(extent > 0, extent, 1.0), 0.0)
    return _counting_sort(_point_codes(points, lo, scale, POINT_TABLES))


@numba.njit(cache=True, nogil=True)
def _nearest_faces(points, lo, hi, faces):
    count = points.shape[0]
    out = np.empty((count, 3))
    for i in range(count):
        best, face = np.inf, 0
        for face_index in range(6):  # numpy's argmin's order: the first nearest face
            axis = face_index % 3
            gap = points[i, axis] - lo[axis] if face_index < 3 else hi[axis] - points[i, axis]
            if gap < best:
                best, face = gap, face_index
        for axis in range(3):
            out[i, axis] = faces[face, axis]
    return out


def nearest_face_directions(points: np.ndarray, lo: np.ndarray, hi: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(N, 3) float64: per point the row of faces (6, 3: -x, -y, -z, +x, +y, +z) of the box (lo, hi)'s
    face nearest to it, in one pass."""
    return _nearest_faces(np.ascontiguousarray(points, np.float64), np.asarray(lo, np.float64),
                          np.asarray(hi, np.float64), np.ascontiguousarray(faces, np.float64))
