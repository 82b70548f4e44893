"""Error-free transformations in float64 numpy (Ogita, Rump and Oishi, "Accurate sum and dot
product", 2005): dot products as accurate as if computed in twice the precision.

They let the host compute, once per shape, what every primary ray shares, such as the eye's
squared distance to a huge sphere's surface, without the cancellation a plain float64 formula has.
"""
from __future__ import annotations

import numpy as np

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
