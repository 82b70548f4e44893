"""The exact inside of the few points whose parity ray the count kernel cannot decide (a crossing
within rounding of the point: kernels/mesh_blocks.cl, MESH_BLOCK_DOUBT), from the point as given
(float64) and the mesh's float64 triangles, in exact arithmetic where float64's rounding could
change a sign (fractions.Fraction), on the host:

- which triangles the point's line crosses: the kernel's edge functions and tie rule, exactly
  (pyclray.model.shapes.mesh_oracle.crossed), each crossing of the line with the surface once;
- on which side of the point each crossing lies: the sign of t = n . (a - p) / n . d (n the
  triangle's normal (b - a) x (c - a)), exactly signed;
- whether the point lies on a triangle: its plane's n . (a - p) exactly 0 and the point inside the
  closed triangle (exact orientations in the plane of the two axes the normal is least along).

Inside: an odd number of crossings at t > 0, or on the surface (a point on the surface is inside).
The cost is a pass over every triangle per point (a few ms on a mesh of 100,000 triangles): only for
the points the kernel leaves undecided, a few in a million of points near a surface.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np

from ...model.shapes.mesh_oracle import crossed

# a float64 sign trusted where the value exceeds this fraction of the size of its terms (the
# products of its coordinates' magnitudes): float64's rounding of these few products and sums is a
# few 2^-53 of that size; below it the sign is computed exactly
SURE = 2.0**-40


def exact_inside(mesh, points: np.ndarray, directions: np.ndarray, nearest=None) -> np.ndarray:
    """(N,) bool: each point (float64, (N, 3)) inside the closed mesh or on its surface, exactly,
    by the crossings of its line along its direction (N, 3). nearest: per point a triangle that
    may hold it (the closest-point query's), tested first: a point on it is inside without a pass
    over the mesh."""
    inside = np.zeros(len(points), bool)
    if nearest is not None:
        a, b, c = (x[nearest] for x in mesh.corners())
        inside = _on_triangles(a, b, c, points)
    rest = np.flatnonzero(~inside)
    count, _, on = exact_crossings(mesh, points[rest], directions[rest])
    inside[rest] = (count & 1).astype(bool) | on
    return inside


def exact_crossings(mesh, points: np.ndarray, directions: np.ndarray):
    """(count, signed, on) per point: its ray's crossings of the mesh at t > 0 (int64), those out
    of it less those into it (int64: +1 where the ray leaves through a triangle, its outward normal
    along the ray, -1 where it enters) and whether the point lies on the surface (bool), exactly."""
    a, b, c = mesh.corners()
    valid = np.any(mesh.face_normals() != 0, axis=1)
    a, b, c = a[valid], b[valid], c[valid]
    lo, hi = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    count, signed, on = np.zeros(len(points), np.int64), np.zeros(len(points), np.int64), np.zeros(len(points), bool)
    for i, (p, d) in enumerate(zip(points, directions)):
        rows = _reached(lo, hi, p, d)
        count[i], signed[i], on[i] = _crossings(a[rows], b[rows], c[rows], p, d)
    return count, signed, on


def _reached(lo, hi, p, d) -> np.ndarray:
    """The triangles (of boxes lo, hi) the ray p + t d may cross at t >= 0: its interval in each box,
    widened by far more than float64's rounding of the slabs (2^-30 of the coordinates' size), ends
    at t >= 0. A triangle crossed at t >= 0 has that point in its box."""
    margin = 2.0**-30 * (np.abs(lo).sum(axis=1) + np.abs(hi).sum(axis=1) + float(np.abs(p).sum()))
    widened_lo, widened_hi = lo - margin[:, None], hi + margin[:, None]
    within = (widened_lo <= p) & (p <= widened_hi)  # along an axis the ray does not move: in the slab or never
    with np.errstate(divide="ignore", invalid="ignore"):
        near, far = (widened_lo - p) / d, (widened_hi - p) / d
    enter = np.where(d != 0, np.minimum(near, far), np.where(within, -np.inf, np.inf))
    leave = np.where(d != 0, np.maximum(near, far), np.where(within, np.inf, -np.inf))
    first, last = enter.max(axis=1), leave.min(axis=1)
    return np.flatnonzero((first <= last + margin) & (last >= -margin))


def _crossings(a, b, c, p, d) -> tuple[int, int, bool]:
    rows = crossed(a, b, c, np.ones(len(a), bool), p, d)
    sides = _plane_signs(a[rows], b[rows], c[rows], p)  # sign of n . (p - a)
    if (sides == 0).any():  # the line crosses a triangle at the point: on the surface
        return 0, 0, True
    along = _normal_signs(a[rows], b[rows], c[rows], d)  # sign of n . d (not 0: the line crosses)
    # t = n . (a - p) / n . d > 0: the point behind the triangle's plane as seen along d
    ahead = sides * along < 0
    count = int(np.count_nonzero(ahead))
    return count, int(along[ahead].sum()), _on_surface(a, b, c, p)


def _plane_signs(a, b, c, p) -> np.ndarray:
    """Per triangle the exact sign of n . (p - a), n = (b - a) x (c - a)."""
    e, f, g = b - a, c - a, p - a
    value = np.einsum("ij,ij->i", np.cross(e, f), g)
    size = _size(e) * _size(f) * _size(g)
    signs = np.sign(value)
    for i in np.flatnonzero(~(np.abs(value) > SURE * size)):
        signs[i] = _exact_triple(a[i], b[i], c[i], p)
    return signs


def _normal_signs(a, b, c, d) -> np.ndarray:
    """Per triangle the exact sign of n . d."""
    e, f = b - a, c - a
    value = np.cross(e, f) @ d
    size = _size(e) * _size(f) * float(np.abs(d).sum())
    signs = np.sign(value)
    for i in np.flatnonzero(~(np.abs(value) > SURE * size)):
        signs[i] = _exact_triple(a[i], b[i], c[i], direction=d)
    return signs


def _size(v) -> np.ndarray:
    return np.abs(v).sum(axis=1)


def _exact_triple(a, b, c, point=None, direction=None) -> float:
    """The sign of ((b - a) x (c - a)) . (point - a), or . direction, in rational arithmetic."""
    a, b, c = ([Fraction(float(x)) for x in v] for v in (a, b, c))
    e, f = [y - x for x, y in zip(a, b)], [y - x for x, y in zip(a, c)]
    if direction is not None:
        g = [Fraction(float(x)) for x in direction]
    else:
        g = [Fraction(float(y)) - x for x, y in zip(a, point)]
    n = (e[1] * f[2] - e[2] * f[1], e[2] * f[0] - e[0] * f[2], e[0] * f[1] - e[1] * f[0])
    value = n[0] * g[0] + n[1] * g[1] + n[2] * g[2]
    return float((value > 0) - (value < 0))


def exact_on_surface(meshes, points: np.ndarray, ids: np.ndarray, primitives: np.ndarray) -> np.ndarray:
    """(N,) bool: each point on a triangle of the meshes, exactly: first its nearest triangle (the
    closest-point query's id and primitive), then every triangle whose box holds it."""
    out = np.zeros(len(points), bool)
    for index, mesh in enumerate(meshes):
        mine = np.flatnonzero(ids == index)
        if len(mine):
            a, b, c = (x[primitives[mine]] for x in mesh.corners())
            out[mine] = _on_triangles(a, b, c, points[mine])
    for i in np.flatnonzero(~out):
        out[i] = any(_on_surface(*mesh.corners(), points[i]) for mesh in meshes)
    return out


def _on_surface(a, b, c, p) -> bool:
    """Whether the point lies on one of the triangles (closed), exactly: the triangles whose box
    holds it are tested (_on_triangles)."""
    holds = np.all((np.minimum(np.minimum(a, b), c) <= p) & (p <= np.maximum(np.maximum(a, b), c)), axis=1)
    rows = np.flatnonzero(holds)
    return bool(len(rows)) and bool(_on_triangles(a[rows], b[rows], c[rows], np.broadcast_to(p, (len(rows), 3))).any())


def _on_triangles(a, b, c, p) -> np.ndarray:
    """Per row whether point p lies on triangle (a, b, c) (closed), exactly: a plane's n . (p - a)
    beyond float64's rounding says no, the others are tested in rational arithmetic."""
    e, f, g = b - a, c - a, p - a
    value = np.einsum("ij,ij->i", np.cross(e, f), g)
    maybe = ~(np.abs(value) > SURE * _size(e) * _size(f) * _size(g))
    out = np.zeros(len(a), bool)
    for i in np.flatnonzero(maybe):
        out[i] = _exact_on_triangle(a[i], b[i], c[i], p[i])
    return out


def _exact_on_triangle(a, b, c, p) -> bool:
    a, b, c, p = ([Fraction(float(x)) for x in v] for v in (a, b, c, p))
    e, f, g = ([y - x for x, y in zip(a, q)] for q in (b, c, p))
    n = (e[1] * f[2] - e[2] * f[1], e[2] * f[0] - e[0] * f[2], e[0] * f[1] - e[1] * f[0])
    if n[0] * g[0] + n[1] * g[1] + n[2] * g[2] != 0 or not any(n):
        return False
    drop = max(range(3), key=lambda k: abs(n[k]))  # the plane seen along the axis its normal is most along
    i, j = [k for k in range(3) if k != drop]

    def orient(u, v):  # (u - p) x (v - p) in the plane (i, j)
        return (u[i] - p[i]) * (v[j] - p[j]) - (u[j] - p[j]) * (v[i] - p[i])

    o = [orient(a, b), orient(b, c), orient(c, a)]
    return all(x >= 0 for x in o) or all(x <= 0 for x in o)
