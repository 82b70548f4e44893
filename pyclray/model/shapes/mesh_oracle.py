"""The float64 oracle of a triangle mesh: nearest hits of rays, nearest triangles of points.

A check traces every pixel of an image through meshes of tens of thousands of triangles, so the
oracle is not a loop over triangles: the triangles are sorted along a Morton curve of their
centroids and grouped eight by eight, level after level (a fixed-fanout hierarchy of boxes, built by
one sort, nothing like the device's BVH), and queries descend it for all rays or points at once as
arrays of (node, query) pairs. The tests themselves are plain float64 formulas in coordinates
relative to the ray's origin (Moller and Trumbore's, two-sided), independent of the kernel's
watertight test: agreement between the two is what the tests check.
"""
from __future__ import annotations

import numpy as np

FANOUT = 8
CHUNK = 1 << 15  # queries per pass (bounds the pairs' memory)


def _morton(points: np.ndarray) -> np.ndarray:
    lo = points.min(axis=0)
    extent = np.maximum(points.max(axis=0) - lo, 1e-300)
    q = np.clip((points - lo) / extent * 1023, 0, 1023).astype(np.uint64)
    code = np.zeros(len(points), np.uint64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return code


class Hierarchy:
    """Boxes of 8, 64, 512 ... consecutive triangles of a Morton order (levels[0]: groups of triangles)."""

    def __init__(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, valid: np.ndarray):
        self.order = np.argsort(_morton((a + b + c) / 3.0), kind="stable")
        self.a, self.b, self.c = a[self.order], b[self.order], c[self.order]
        self.valid = valid[self.order]
        lo = np.minimum(np.minimum(self.a, self.b), self.c)
        hi = np.maximum(np.maximum(self.a, self.b), self.c)
        self.levels = []
        while True:
            starts = np.arange(0, len(lo), FANOUT)
            lo, hi = np.minimum.reduceat(lo, starts), np.maximum.reduceat(hi, starts)
            self.levels.append((lo, hi))
            if len(lo) <= FANOUT:
                break

    def _descend(self, count: int, keep) -> tuple[np.ndarray, np.ndarray]:
        """(triangle positions, query indices) of the pairs whose boxes keep(lo, hi, query) accepts
        at every level (keep may also prune with what it learnt: see nearest)."""
        top_lo, _ = self.levels[-1]
        node = np.tile(np.arange(len(top_lo)), count)
        query = np.repeat(np.arange(count), len(top_lo))
        for level in range(len(self.levels) - 1, -1, -1):
            lo, hi = self.levels[level]
            take = keep(lo[node], hi[node], query)
            node, query = node[take], query[take]
            below = len(self.a) if level == 0 else len(self.levels[level - 1][0])
            node = (node[:, None] * FANOUT + np.arange(FANOUT)).reshape(-1)
            query = np.repeat(query, FANOUT)
            inside = node < below
            node, query = node[inside], query[inside]
        return node, query

    # -- rays ----------------------------------------------------------------------------------
    def intersect(self, origins, directions):
        """(t, triangle index in the input order, u, v) of each ray's nearest hit with t > 0
        (inf, -1, 0, 0 on a miss). Rays: float64 (N, 3), directions unit."""
        n = len(directions)
        best = np.full(n, np.inf)
        which = np.full(n, -1, np.int64)
        uv = np.zeros((n, 2))
        for start in range(0, n, CHUNK):
            O, D = origins[start:start + CHUNK], directions[start:start + CHUNK]
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                inverse = 1.0 / D

                def slabs(lo, hi, q):
                    t0, t1 = (lo - O[q]) * inverse[q], (hi - O[q]) * inverse[q]
                    t0 = np.where(np.isnan(t0), -np.inf, t0)  # 0 * inf: a ray on a slab's face
                    t1 = np.where(np.isnan(t1), np.inf, t1)
                    near = np.minimum(t0, t1).max(axis=1)
                    far = np.maximum(t0, t1).min(axis=1)
                    return (near <= far * (1 + 1e-9)) & (far >= 0)

                tri, q = self._descend(len(D), slabs)
                t, u, v = triangle_hits(self.a[tri] - O[q], self.b[tri] - O[q], self.c[tri] - O[q], D[q])
            t = np.where(self.valid[tri], t, np.inf)
            hit = np.isfinite(t)
            tri, q, t, u, v = tri[hit], q[hit], t[hit], u[hit], v[hit]
            first = np.lexsort((self.order[tri], t, q))  # per ray, the nearest (lowest index on a tie)
            q_sorted = q[first]
            lead = np.ones(len(first), bool)
            lead[1:] = q_sorted[1:] != q_sorted[:-1]
            pick = first[lead]
            rows = start + q[pick]
            best[rows], which[rows] = t[pick], self.order[tri[pick]]
            uv[rows, 0], uv[rows, 1] = u[pick], v[pick]
        return best, which, uv

    # -- points --------------------------------------------------------------------------------
    def nearest(self, points):
        """(distance, triangle index in the input order, distance to that triangle's nearest edge)
        of each point's nearest triangle."""
        n = len(points)
        out = np.full(n, np.inf), np.full(n, -1, np.int64), np.full(n, np.inf)
        for start in range(0, n, CHUNK):
            P = points[start:start + CHUNK]
            bound = np.full(len(P), np.inf)

            def near_boxes(lo, hi, q):
                gap = np.maximum(np.maximum(lo - P[q], P[q] - hi), 0.0)
                low = np.sqrt(np.einsum("ij,ij->i", gap, gap))
                span = np.maximum(np.abs(P[q] - lo), np.abs(P[q] - hi))
                high = np.sqrt(np.einsum("ij,ij->i", span, span))  # every point of the box is nearer
                np.minimum.at(bound, q, high)
                return low <= bound[q]

            tri, q = self._descend(len(P), near_boxes)
            d, edge = point_triangle(P[q], self.a[tri], self.b[tri], self.c[tri])
            first = np.lexsort((self.order[tri], d, q))
            q_sorted = q[first]
            lead = np.ones(len(first), bool)
            lead[1:] = q_sorted[1:] != q_sorted[:-1]
            pick = first[lead]
            rows = start + q[pick]
            out[0][rows], out[1][rows], out[2][rows] = d[pick], self.order[tri[pick]], edge[pick]
        return out


def barycentrics(points, a, b, c):
    """(u, v) per row of the points' projections onto their triangles' planes, p = a + u (b - a)
    + v (c - a) (the 2x2 normal equations, float64; nan for a zero-area triangle)."""
    e1, e2, f = b - a, c - a, points - a
    d11, d12, d22 = _dot(e1, e1), _dot(e1, e2), _dot(e2, e2)
    f1, f2 = _dot(f, e1), _dot(f, e2)
    det = d11 * d22 - d12 * d12
    with np.errstate(invalid="ignore", divide="ignore"):
        return (d22 * f1 - d12 * f2) / det, (d11 * f2 - d12 * f1) / det


def _cross(x, y):
    return np.stack([x[:, 1] * y[:, 2] - x[:, 2] * y[:, 1], x[:, 2] * y[:, 0] - x[:, 0] * y[:, 2],
                     x[:, 0] * y[:, 1] - x[:, 1] * y[:, 0]], axis=1)


def _dot(x, y):
    return np.einsum("ij,ij->i", x, y)


def triangle_hits(A, B, C, D):
    """Moller-Trumbore, two-sided, for vertices relative to the ray's origin: (t, u, v) per pair,
    t = inf where the ray misses (t > 0 only)."""
    e1, e2 = B - A, C - A
    p = _cross(D, e2)
    det = _dot(e1, p)
    s = -A  # origin - a
    u = _dot(s, p) / det
    q = _cross(s, e1)
    v = _dot(D, q) / det
    t = _dot(e2, q) / det
    hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & np.isfinite(t)
    return np.where(hit, t, np.inf), u, v


def _segment(P, X, Y):
    d = Y - X
    length2 = _dot(d, d)
    s = np.clip(np.where(length2 > 0, _dot(P - X, d) / np.where(length2 > 0, length2, 1), 0.0), 0.0, 1.0)
    r = P - (X + s[:, None] * d)
    return np.sqrt(_dot(r, r))


def point_triangle(P, a, b, c):
    """(distance from P to the triangle, distance from P to the triangle's nearest edge) per row."""
    edges = np.minimum(np.minimum(_segment(P, a, b), _segment(P, b, c)), _segment(P, c, a))
    n = _cross(b - a, c - a)
    n2 = _dot(n, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        # the barycentric coordinates of P's projection: inside when all three are >= 0
        w_a = _dot(_cross(b - P, c - P), n) / n2
        w_b = _dot(_cross(c - P, a - P), n) / n2
        w_c = _dot(_cross(a - P, b - P), n) / n2
        plane = np.abs(_dot(P - a, n)) / np.sqrt(n2)
    inside = (n2 > 0) & (w_a >= 0) & (w_b >= 0) & (w_c >= 0)
    return np.where(inside, plane, edges), edges


def closest_on_triangles(P, a, b, c):
    """(position, (u, v)) per row: the point of triangle a, b, c nearest P (float64), position =
    (1 - u - v) a + u b + v c: the projection where it falls inside, else the nearest point of
    the three edges (a zero-area triangle: its edges alone)."""
    u, v = barycentrics(P, a, b, c)
    n = _cross(b - a, c - a)
    inside = (_dot(n, n) > 0) & (u >= 0) & (v >= 0) & (u + v <= 1)
    best = np.full(len(P), np.inf)
    uv = np.zeros((len(P), 2))
    for X, Y, weights in ((a, b, lambda s: (s, 0 * s)), (b, c, lambda s: (1 - s, s)), (c, a, lambda s: (0 * s, 1 - s))):
        d = Y - X
        length2 = _dot(d, d)
        s = np.clip(np.where(length2 > 0, _dot(P - X, d) / np.where(length2 > 0, length2, 1), 0.0), 0.0, 1.0)
        r = P - (X + s[:, None] * d)
        dist = _dot(r, r)
        nearer = dist < best
        best = np.where(nearer, dist, best)
        su, sv = weights(s)
        uv[nearer] = np.stack([su, sv], axis=1)[nearer]
    uv[inside] = np.stack([u, v], axis=1)[inside]
    position = a + uv[:, :1] * (b - a) + uv[:, 1:] * (c - a)
    return position, uv


def winding_numbers(P, a, b, c, chunk: int = 1 << 22) -> np.ndarray:
    """The generalized winding number of the triangles at each point (float64): the sum of their
    solid angles (van Oosterom and Strackee) over 4 pi, every triangle for every point."""
    out = np.zeros(len(P))
    step = max(1, chunk // max(len(a), 1))
    for start in range(0, len(P), step):
        Q = P[start:start + step, None, :]
        A, B, C = a[None] - Q, b[None] - Q, c[None] - Q
        la, lb, lc = (np.linalg.norm(X, axis=-1) for X in (A, B, C))
        numerator = np.einsum("pti,pti->pt", A, np.cross(B, C))
        denominator = (la * lb * lc + np.einsum("pti,pti->pt", A, B) * lc + np.einsum("pti,pti->pt", B, C) * la
                       + np.einsum("pti,pti->pt", C, A) * lb)
        out[start:start + step] = 2.0 * np.arctan2(numerator, denominator).sum(axis=1) / (4 * np.pi)
    return out
# -- every crossing, with the tie rule (the float64 oracle of count_hits and all_hits) -------------
def _projected(A, D, kx, ky, kz):
    """The homogeneous shear of kernels/mesh.cl: each vertex A (from the origin) to
    (A_x d_z - A_z d_x, A_y d_z - A_z d_y) with the ray's largest component as z."""
    return A[..., kx] * D[kz] - A[..., kz] * D[kx], A[..., ky] * D[kz] - A[..., kz] * D[ky]


def _axes(D):
    """(kx, ky, kz): kernels/mesh.cl's cyclic permutation, the largest |component| as z (ties: z, then y)."""
    ax, ay, az = np.abs(D)
    if ax > ay and ax > az:
        return 1, 2, 0
    if not ax > ay and ay > az:
        return 2, 0, 1
    return 0, 1, 2


def crossings(a, b, c, valid, origin, direction):
    """(t, triangle) of every triangle the ray origin + t direction (t > 0) crosses, by
    kernels/mesh.cl's test and tie rule in exact arithmetic: the projected vertices and edge functions
    in float64 where their rounding cannot change a sign (an error bound of 2^-40 of their terms'
    size), else exactly (fractions.Fraction of the float64 vertices, origin and direction). So a ray
    through a shared edge or vertex crosses exactly one triangle there where it crosses the surface,
    and the parity from a point is exact. t is float64 (the plane's). valid: the triangles of area."""
    from fractions import Fraction

    O = np.asarray(origin, np.float64)
    D = np.asarray(direction, np.float64)
    kx, ky, kz = _axes(D)
    A, B, C = a - O, b - O, c - O
    (ax, ay), (bx, by), (cx, cy) = (_projected(X, D, kx, ky, kz) for X in (A, B, C))
    e0, e1, e2 = bx * cy - by * cx, cx * ay - cy * ax, ax * by - ay * bx

    def size(X):
        m = np.abs(X[..., kx] * D[kz]) + np.abs(X[..., kz] * D[kx]) + np.abs(X[..., ky] * D[kz]) + np.abs(X[..., kz] * D[ky])
        return m + np.abs(X).sum(axis=-1) * np.abs(D).sum()

    sa, sb, sc = size(A), size(B), size(C)
    bound = 2.0**-40
    sure0, sure1, sure2 = (np.abs(e0) > bound * sb * sc), (np.abs(e1) > bound * sc * sa), (np.abs(e2) > bound * sa * sb)
    s0, s1, s2 = np.sign(e0), np.sign(e1), np.sign(e2)
    inside = valid & sure0 & sure1 & sure2 & (s0 == s1) & (s1 == s2)
    unsure = valid & ~(sure0 & sure1 & sure2)
    # a sure pair of opposite signs is a sure miss
    unsure &= ~((sure0 & sure1 & (s0 * s1 < 0)) | (sure1 & sure2 & (s1 * s2 < 0)) | (sure0 & sure2 & (s0 * s2 < 0)))
    inside = inside.copy()
    Of = [Fraction(float(x)) for x in O]
    Df = [Fraction(float(x)) for x in D]
    for i in np.flatnonzero(unsure):
        P = []
        for X in (a[i], b[i], c[i]):
            V = [Fraction(float(X[k])) - Of[k] for k in range(3)]
            P.append((V[kx] * Df[kz] - V[kz] * Df[kx], V[ky] * Df[kz] - V[kz] * Df[ky]))
        (pax, pay), (pbx, pby), (pcx, pcy) = P
        f0, f1, f2 = pbx * pcy - pby * pcx, pcx * pay - pcy * pax, pax * pby - pay * pbx
        signs = [_exact_tie(f, px, py, qx, qy) for f, (px, py), (qx, qy) in
                 ((f0, (pbx, pby), (pcx, pcy)), (f1, (pcx, pcy), (pax, pay)), (f2, (pax, pay), (pbx, pby)))]
        inside[i] = signs[0] != 0 and signs[0] == signs[1] == signs[2]
    rows = np.flatnonzero(inside)
    n = np.cross(b[rows] - a[rows], c[rows] - a[rows])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (n * (a[rows] - O)).sum(axis=1) / (n @ D)
    keep = np.isfinite(t) & (t > 0)
    return t[keep], rows[keep]


def _exact_tie(f, px, py, qx, qy) -> int:
    """The sign of an exact edge function f = p x q under the tie rule (_tie_signs)."""
    if f != 0:
        return 1 if f > 0 else -1
    if py != qy:
        return 1 if py > qy else -1
    return (qx > px) - (qx < px)
