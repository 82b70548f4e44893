"""Compiled passes over a large batch of query points (numba, as engine/queries/ray_order.py's, and
imported only for batches of at least closest.COHERENT_FROM points): their coherent order, and the
nearest face of a box per point (the direction of its parity ray: engine/queries/closest.py). Each
point is computed on its own: neither changes any bit of a result, only which points run side by
side and which (exact) ray decides a parity."""
from __future__ import annotations

import numba
import numpy as np


# points in 1024 cells per axis of their box: a 30-bit Morton code (near-surface points fill few
# cells of a coarser grid, and the order within a cell is the order given)
POINT_BITS = 10


@numba.njit(cache=True, nogil=True)
def _spread10(v):
    """v's 10 bits at every third place (bit i at bit 3 i)."""
    v = (v | (v << 16)) & 0x030000FF
    v = (v | (v << 8)) & 0x0300F00F
    v = (v | (v << 4)) & 0x030C30C3
    return (v | (v << 2)) & 0x09249249


@numba.njit(cache=True, nogil=True)
def _point_order(points, lo, scale):
    """The stable order of the points' 30-bit codes: the codes in one pass, then a radix sort of two
    15-bit digits (a counting sort each)."""
    count = points.shape[0]
    top = (1 << POINT_BITS) - 1
    codes = np.empty(count, np.uint32)
    for i in range(count):
        code = 0
        for axis in range(3):
            cell = min(max((points[i, axis] - lo[axis]) * scale[axis], 0.0), top)
            code |= _spread10(np.int64(cell)) << axis
        codes[i] = code
    order = np.arange(count).astype(np.int32)
    for shift in (0, 15):
        starts = np.zeros((1 << 15) + 1, np.int64)
        for i in range(count):
            starts[((codes[order[i]] >> shift) & 0x7FFF) + 1] += 1
        for digit in range(1 << 15):
            starts[digit + 1] += starts[digit]
        placed = np.empty(count, np.int32)
        for i in range(count):
            digit = (codes[order[i]] >> shift) & 0x7FFF
            placed[starts[digit]] = order[i]
            starts[digit] += 1
        order = placed
    return order


def coherent_order(points: np.ndarray) -> np.ndarray:
    """int32 order[i]: the place of the i-th point along a 30-bit Morton curve of the points' box (in
    compiled passes: numpy's codes and argsort took 5 to 10 times as long)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    extent = hi - lo
    cells = float((1 << POINT_BITS) - 1)  # the box's far faces in the last cell
    scale = np.where(extent > 0, cells / np.where(extent > 0, extent, 1.0), 0.0)
    return _point_order(np.ascontiguousarray(points, np.float64), lo.astype(np.float64), scale.astype(np.float64))


@numba.njit(cache=True, nogil=True)
def _nearest_faces(points, lo, hi, faces):
    count = points.shape[0]
    out = np.empty((count, 3))
    lx, ly, lz, hx, hy, hz = lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
    for i in range(count):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        # the six faces' gaps in numpy's argmin's order (-x, -y, -z, +x, +y, +z): the first nearest
        # face (written out: the loop over faces with its index arithmetic took 3x as long)
        best, face = x - lx, 0
        gap = y - ly
        if gap < best:
            best, face = gap, 1
        gap = z - lz
        if gap < best:
            best, face = gap, 2
        gap = hx - x
        if gap < best:
            best, face = gap, 3
        gap = hy - y
        if gap < best:
            best, face = gap, 4
        gap = hz - z
        if gap < best:
            face = 5
        out[i, 0] = faces[face, 0]
        out[i, 1] = faces[face, 1]
        out[i, 2] = faces[face, 2]
    return out


def nearest_face_directions(points: np.ndarray, lo: np.ndarray, hi: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(N, 3) float64: per point the row of faces (6, 3: -x, -y, -z, +x, +y, +z) of the box (lo, hi)'s
    face nearest to it, in one pass."""
    return _nearest_faces(np.ascontiguousarray(points, np.float64), np.asarray(lo, np.float64),
                          np.asarray(hi, np.float64), np.ascontiguousarray(faces, np.float64))
