"""Error-free transformations in float64 numpy (Ogita, Rump and Oishi, "Accurate sum and dot
product", 2005): dot products as accurate as if computed in twice the precision.

They let the host compute, once per shape, what every primary ray shares, such as the eye's
squared distance to a huge sphere's surface, without the cancellation a plain float64 formula has.
"""
from __future__ import annotations

import numpy as np

_CHUNK = 1 << 14
_SPLIT = 134217729.0  # 2**27 + 1, Dekker's splitter for float64


def two_sum(a, b):
    """a + b = s + e exactly."""
    s = a + b
    z = s - a
    e = (a - (s - z)) + (b - z)
    return s, e


def two_prod(a, b):
    """a * b = p + e exactly (Dekker; no FMA in numpy)."""
    p = a * b
    t = _SPLIT * a
    a_hi = t - (t - a)
    a_lo = a - a_hi
    t = _SPLIT * b
    b_hi = t - (t - b)
    b_lo = b - b_hi
    e = ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo
    return p, e


def dot2(x, y):
    """sum(x * y) over the last axis, as accurate as if computed in twice float64's precision."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    p, s = two_prod(x[..., 0], y[..., 0])
    for k in range(1, x.shape[-1]):
        h, r = two_prod(x[..., k], y[..., k])
        p, q = two_sum(p, h)
        s = s + (q + r)
    return p + s


def cross_norm2_minus(F, A, r):
    """|F x A|^2 - r^2 over the last axis (F, A: (..., 3); r: (...)), as accurate as if computed
    in twice float64's precision: each component of F x A is an exact sum of four floats (two
    error-free products), and the sum of all their pairwise products and -r^2 goes through dot2."""
    F = np.asarray(F, dtype=np.float64)
    A = np.asarray(A, dtype=np.float64)
    if F.ndim == 2 and len(F) > _CHUNK:  # many rays: in chunks, the expansion holds 49 terms each
        A, r = np.broadcast_to(A, F.shape), np.broadcast_to(np.asarray(r, np.float64), F.shape[:1])
        return np.concatenate([cross_norm2_minus(F[k:k + _CHUNK], A[k:k + _CHUNK], r[k:k + _CHUNK])
                               for k in range(0, len(F), _CHUNK)])
    terms = []
    for i, j in ((1, 2), (2, 0), (0, 1)):  # (F x A)_k = F_i A_j - F_j A_i
        p1, e1 = two_prod(F[..., i], A[..., j])
        p2, e2 = two_prod(F[..., j], A[..., i])
        terms.append(np.stack([p1, e1, -p2, -e2], axis=-1))
    expanded = np.stack(terms, axis=-2)  # (..., 3, 4): the components' exact terms
    x = (expanded[..., :, :, None] * np.ones(4)).reshape(*expanded.shape[:-2], 48)
    y = (expanded[..., :, None, :] * np.ones((4, 1))).reshape(*expanded.shape[:-2], 48)
    r = np.broadcast_to(np.asarray(r, dtype=np.float64), x.shape[:-1])
    return dot2(np.concatenate([x, r[..., None]], axis=-1), np.concatenate([y, -r[..., None]], axis=-1))
