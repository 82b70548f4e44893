"""The exact inside of the few points whose parity ray the count kernel cannot decide (a crossing
within rounding of the point: kernels/mesh_blocks.cl, MESH_BLOCK_DOUBT), from the point as given
(float64) and the mesh's float64 triangles, in exact arithmetic where float64's rounding could
change a sign (fractions.Fraction), on the host:

- which triangles the point's line crosses: the kernel's edge functions and tie rule, exactly
  (the float64 oracle's test, pyclray.model.shapes.mesh_oracle.crossings, per pair), each crossing
  of the line with the surface once;
- on which side of the point each crossing lies: the sign of t = n . (a - p) / n . d (n the
  triangle's normal (b - a) x (c - a)), exactly signed;
- whether the point lies on a triangle: its plane's n . (a - p) exactly 0 and the point inside the
  closed triangle (exact orientations in the plane of the two axes the normal is least along).

Inside: an odd number of crossings at t > 0, or on the surface (a point on the surface is inside).
The cost is a box test of every triangle per point (about 1 ms on a mesh of 100,000 triangles),
then the pairs it keeps, all points at once: only for the points the kernel leaves undecided.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np


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
    along the ray, -1 where it enters) and whether the point lies on the surface (bool), exactly.
    All the points' (point, triangle) pairs that their rays' box tests reach at once."""
    a, b, c = mesh.corners()
    valid = np.any(mesh.face_normals() != 0, axis=1)
    a, b, c = a[valid], b[valid], c[valid]
    lo, hi = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    if len(a):
        box = lo.min(axis=0), hi.max(axis=0)
        reached = [_reached(lo, hi, box, p, d) for p, d in zip(points, directions)]
    else:
        reached = [np.zeros(0, np.int64)] * len(points)
    owner = np.repeat(np.arange(len(points)), [len(r) for r in reached])
    rows = np.concatenate(reached + [np.zeros(0, np.int64)]).astype(np.int64)
    A, B, C, P, D = a[rows], b[rows], c[rows], points[owner], directions[owner]
    # on a triangle: the pairs whose box holds the point, tested exactly
    holds = np.all((lo[rows] <= P) & (P <= hi[rows]), axis=1)
    on_pairs = np.flatnonzero(holds)
    on = np.zeros(len(points), bool)
    on[owner[on_pairs[_on_triangles(A[on_pairs], B[on_pairs], C[on_pairs], P[on_pairs])]]] = True
    # the crossings: the exact edge functions with the tie rule, then each one's side of the point
    hit = np.flatnonzero(_crossed_pairs(A, B, C, P, D))
    sides = _plane_signs(A[hit], B[hit], C[hit], P[hit])  # sign of n . (p - a)
    on[owner[hit[sides == 0]]] = True  # the line crosses a triangle at the point
    along = _normal_signs(A[hit], B[hit], C[hit], D[hit])  # sign of n . d (not 0: the line crosses)
    ahead = sides * along < 0  # t = n . (a - p) / n . d > 0
    count = np.bincount(owner[hit[ahead]], minlength=len(points)).astype(np.int64)
    signed = np.rint(np.bincount(owner[hit[ahead]], weights=along[ahead], minlength=len(points))).astype(np.int64)
    return count, signed, on


def _reached(lo, hi, box, p, d) -> np.ndarray:
    """The triangles (of boxes lo, hi; box: the mesh's) the ray p + t d may cross at t >= 0: its interval in each box,
    widened by far more than float64's rounding of the slabs (2^-30 of the coordinates' size), ends
    at t >= 0. A triangle crossed at t >= 0 has that point in its box."""
    # first the boxes that meet the box of the ray's part within the mesh's box (a thin one for a
    # parity ray, along an axis: few of them)
    reach = float(np.max(np.concatenate([np.abs(box[1] - p), np.abs(p - box[0])])))
    extent = float(np.abs(box[1] - box[0]).sum() + np.abs(p).sum())
    length = 2.0 * reach / float(np.abs(d).max())  # past the mesh's box along the ray
    start, end = p - 2.0**-30 * extent, p + 2.0**-30 * extent
    ends = np.stack([p, p + length * d])
    low, high = np.minimum(ends.min(axis=0), start), np.maximum(ends.max(axis=0), end)
    near_ray = np.flatnonzero((lo[:, 0] <= high[0]) & (hi[:, 0] >= low[0]) & (lo[:, 1] <= high[1]) & (hi[:, 1] >= low[1])
                              & (lo[:, 2] <= high[2]) & (hi[:, 2] >= low[2]))
    lo, hi = lo[near_ray], hi[near_ray]
    margin = 2.0**-30 * (np.abs(lo).sum(axis=1) + np.abs(hi).sum(axis=1) + float(np.abs(p).sum()))
    widened_lo, widened_hi = lo - margin[:, None], hi + margin[:, None]
    within = (widened_lo <= p) & (p <= widened_hi)  # along an axis the ray does not move: in the slab or never
    with np.errstate(divide="ignore", invalid="ignore"):
        near, far = (widened_lo - p) / d, (widened_hi - p) / d
    enter = np.where(d != 0, np.minimum(near, far), np.where(within, -np.inf, np.inf))
    leave = np.where(d != 0, np.maximum(near, far), np.where(within, np.inf, -np.inf))
    first, last = enter.max(axis=1), leave.min(axis=1)
    return near_ray[(first <= last + margin) & (last >= -margin)]


def _crossed_pairs(a, b, c, p, d) -> np.ndarray:
    """Per row whether the line p + t d (any t) crosses triangle (a, b, c): kernels/mesh.cl's edge
    functions (its axes per row: the direction's largest component as z) and tie rule, their signs
    in float64 where rounding cannot change them (mesh_oracle.crossed's bound), else exactly."""
    magnitude = np.abs(d)
    z_is_x = (magnitude[:, 0] > magnitude[:, 1]) & (magnitude[:, 0] > magnitude[:, 2])
    z_is_y = ~(magnitude[:, 0] > magnitude[:, 1]) & (magnitude[:, 1] > magnitude[:, 2])
    axes = np.where(z_is_x[:, None], [1, 2, 0], np.where(z_is_y[:, None], [2, 0, 1], [0, 1, 2]))

    def permuted(v):
        return np.take_along_axis(v, axes, axis=1)

    D = permuted(d)
    corners = [permuted(x - p) for x in (a, b, c)]
    projected = [(X[:, 0] * D[:, 2] - X[:, 2] * D[:, 0], X[:, 1] * D[:, 2] - X[:, 2] * D[:, 1]) for X in corners]
    (ax, ay), (bx, by), (cx, cy) = projected
    e = [bx * cy - by * cx, cx * ay - cy * ax, ax * by - ay * bx]
    size_d = np.abs(d).sum(axis=1)
    sizes = [np.abs(X[:, 0] * D[:, 2]) + np.abs(X[:, 2] * D[:, 0]) + np.abs(X[:, 1] * D[:, 2]) + np.abs(X[:, 2] * D[:, 1])
             + np.abs(X).sum(axis=1) * size_d for X in corners]
    bound = 2.0**-40
    sure = [np.abs(e[0]) > bound * sizes[1] * sizes[2], np.abs(e[1]) > bound * sizes[2] * sizes[0],
            np.abs(e[2]) > bound * sizes[0] * sizes[1]]
    signs = [np.sign(x) for x in e]
    inside = sure[0] & sure[1] & sure[2] & (signs[0] == signs[1]) & (signs[1] == signs[2])
    unsure = ~(sure[0] & sure[1] & sure[2])
    for i, j in ((0, 1), (1, 2), (0, 2)):  # a sure pair of opposite signs is a sure miss
        unsure &= ~(sure[i] & sure[j] & (signs[i] * signs[j] < 0))
    for k in np.flatnonzero(unsure):
        inside[k] = _exact_crossed(a[k], b[k], c[k], p[k], d[k], axes[k])
    return inside


def _exact_crossed(a, b, c, p, d, axes) -> bool:
    """_crossed_pairs' test of one row in rational arithmetic."""
    kx, ky, kz = (int(k) for k in axes)
    P, Dv = [Fraction(float(x)) for x in p], [Fraction(float(x)) for x in d]
    projected = []
    for X in (a, b, c):
        V = [Fraction(float(X[k])) - P[k] for k in range(3)]
        projected.append((V[kx] * Dv[kz] - V[kz] * Dv[kx], V[ky] * Dv[kz] - V[kz] * Dv[ky]))
    (ax, ay), (bx, by), (cx, cy) = projected
    signs = [_tie_sign(bx * cy - by * cx, bx, by, cx, cy), _tie_sign(cx * ay - cy * ax, cx, cy, ax, ay),
             _tie_sign(ax * by - ay * bx, ax, ay, bx, by)]
    return signs[0] != 0 and signs[0] == signs[1] == signs[2]


def _tie_sign(f, px, py, qx, qy) -> int:
    """The sign of an exact edge function f = p x q under kernels/mesh.cl's tie rule (the ray's
    projected point moved by (eps, eps^2)): that of py - qy where f is 0, or of qx - px."""
    if f != 0:
        return 1 if f > 0 else -1
    if py != qy:
        return 1 if py > qy else -1
    return (qx > px) - (qx < px)


def _plane_signs(a, b, c, p) -> np.ndarray:
    """Per triangle the exact sign of n . (p - a), n = (b - a) x (c - a)."""
    return _triple_signs(a, b, c, point=np.broadcast_to(p, a.shape))


def _normal_signs(a, b, c, d) -> np.ndarray:
    """Per triangle the exact sign of n . d."""
    return _triple_signs(a, b, c, direction=np.broadcast_to(d, a.shape))


def _triple_signs(a, b, c, point=None, direction=None) -> np.ndarray:
    """Per triangle the exact sign of n . (point - a), or n . direction: float64's where its value
    is beyond its rounding (SURE of the terms' magnitudes), else in rational arithmetic."""
    e, f = b - a, c - a
    g = direction if direction is not None else point - a
    value = np.einsum("ij,ij->i", np.cross(e, f), g)
    size = _size(e) * _size(f) * _size(g)
    signs = np.sign(value)
    for i in np.flatnonzero(~(np.abs(value) > SURE * size)):
        signs[i] = _exact_triple(a[i], b[i], c[i], point=None if point is None else point[i],
                                 direction=None if direction is None else direction[i])
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
