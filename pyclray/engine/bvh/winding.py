"""The generalized winding number's hierarchy (Barill, Dickson, Schmidt, Levin and Jacobson 2018,
"Fast winding numbers for soups and clouds"): per child slot of the wide BVH, the far-field expansion
of its triangles' solid angles, which the closest-point kernel (kernels/closest.cl) sums instead of
the triangles wherever the point is farther than WINDING_BETA times the slot's radius from its
centre.

A triangle's solid angle seen from q is the integral over it of g(x) . n dA, g(x) = (x - q) / |x - q|^3.
About a slot's centre c (its triangles' area-weighted centroid), g(x) = g(c) + J (x - c) + ..., J the
Jacobian I / |d|^3 - 3 d d^T / |d|^5 with d = c - q; summed over the triangles (their centroid x_i,
area vector a_i = area n, for which the first moment is exact):
    sum_i a_i . g(c) + sum_jk J_jk M_jk,   A = sum_i a_i,   M = sum_i a_i (x_i - c)^T,
and the next order, with the Hessian of g and the triangles' second moments about c,
    C_jkl = sum_i a_ij (integral over triangle i of (x - c)_k (x - c)_l dA / area_i)
(a triangle's: (x_i - c)(x_i - c)^T plus its covariance, the sum over its vertices v of
(v - x_i)(v - x_i)^T / 12), the second order of Barill et al.'s expansion. Its error falls as
(radius / |d|)^3.
"""
from __future__ import annotations

import numba
import numpy as np

from ...model.layout import Struct

WINDING_SLOT = Struct(
    "WindingSlot",
    (
        ("center", "double4"),  # the triangles' area-weighted centroid c; w: the radius of the slot's box about c
        ("area", "double4"),  # A, the sum of the area vectors; w: the triangles' total area (0: none, skipped)
        ("m0", "double4"),  # rows of M = sum_i a_i (x_i - c)^T (w: 0)
        ("m1", "double4"),
        ("m2", "double4"),
        # C_j = sum_i a_ij (integral over triangle i of (x - c)(x - c)^T dA) for j = x, y, z: each
        # symmetric 3x3 as (xx, yy, zz, xy, xz, yz), the 18 one after the other (2 spare)
        ("second0", "double4"),
        ("second1", "double4"),
        ("second2", "double4"),
        ("second3", "double4"),
        ("second4", "double4"),
    ),
    "A wide BVH child's far-field expansion of its triangles' solid angles (kernels/closest.cl).",
)

# a slot's expansion stands for its triangles where the point is farther than this many radii from
# its centre (Barill et al. take 2; with the second-order term, 3 keeps the sum's error below
# 1e-3, 2 does not: 3e-4 and 1.8e-3 on the bunny, tests/test_sdf.py)
WINDING_BETA = 3.0

_SLOT_DOUBLES = 40


@numba.njit(cache=True, nogil=True)
def _aggregate(first, count, lo, hi, a, b, c):  # pragma: no cover - compiled
    """Per binary node, its triangles' expansion (the rows of WINDING_SLOT, 40 doubles): each node's
    leaf positions are one range (its subtree's, contiguous in the tree's leaf order), summed about
    the node's own centroid."""
    nodes = len(first)
    start = np.zeros(nodes, np.int64)
    end = np.zeros(nodes, np.int64)
    done = np.zeros(nodes, np.bool_)
    stack = np.empty(max(nodes, 2) + 64, np.int64)
    top = 1
    stack[0] = 0
    while top > 0:  # post-order: each node's range from its children's
        node = stack[top - 1]
        if count[node] > 0:
            start[node], end[node] = first[node], first[node] + count[node]
            done[node] = True
            top -= 1
        elif done[first[node]] and done[first[node] + 1]:
            left, right = first[node], first[node] + 1
            if end[left] != start[right]:
                raise ValueError("a BVH subtree whose leaves are not one range")
            start[node], end[node] = start[left], end[right]
            done[node] = True
            top -= 1
        else:
            stack[top] = first[node]
            stack[top + 1] = first[node] + 1
            top += 2
    out = np.zeros((nodes, _SLOT_DOUBLES))
    for node in range(nodes):
        W = 0.0
        A = np.zeros(3)
        P = np.zeros(3)
        for q in range(start[node], end[node]):
            n = 0.5 * np.cross(b[q] - a[q], c[q] - a[q])
            w = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
            W += w
            A += n
            P += w * (a[q] + b[q] + c[q]) / 3.0
        if W <= 0.0:
            continue
        center = P / W
        M = np.zeros((3, 3))
        C = np.zeros((3, 6))
        for q in range(start[node], end[node]):
            n = 0.5 * np.cross(b[q] - a[q], c[q] - a[q])
            x = (a[q] + b[q] + c[q]) / 3.0
            dx = x - center
            # the triangle's second moment about the centre: (x - c)(x - c)^T plus its own covariance
            S = np.outer(dx, dx)
            for v in (a[q], b[q], c[q]):
                S += np.outer(v - x, v - x) / 12.0
            for j in range(3):
                for k in range(3):
                    M[j, k] += n[j] * dx[k]
                C[j, 0] += n[j] * S[0, 0]
                C[j, 1] += n[j] * S[1, 1]
                C[j, 2] += n[j] * S[2, 2]
                C[j, 3] += n[j] * S[0, 1]
                C[j, 4] += n[j] * S[0, 2]
                C[j, 5] += n[j] * S[1, 2]
        radius = 0.0
        for corner in range(8):
            d2 = 0.0
            for j in range(3):
                v = hi[node, j] if (corner >> j) & 1 else lo[node, j]
                d2 += (v - center[j]) * (v - center[j])
            radius = max(radius, np.sqrt(d2))
        out[node, 0:3] = center
        out[node, 3] = radius
        out[node, 4:7] = A
        out[node, 7] = W
        for j in range(3):
            out[node, 8 + 4 * j:11 + 4 * j] = M[j]
        out[node, 20:38] = C.reshape(-1)
    return out


def winding_slots(tree, wide, triangles_by_position: np.ndarray) -> np.ndarray:
    """(W * 8, 40) float64, WINDING_SLOT's fields per child slot of the wide tree (empty slots and
    slots without triangles: area.w = 0). triangles_by_position: (N, 3, 3) per leaf position its
    triangle's vertices a, b, c, all 0 for a position that holds another shape (no solid angle)."""
    a, b, c = (np.ascontiguousarray(triangles_by_position[:, v]) for v in range(3))
    per_node = _aggregate(np.ascontiguousarray(tree.first, np.int64), np.ascontiguousarray(tree.count, np.int64),
                          np.ascontiguousarray(tree.lo), np.ascontiguousarray(tree.hi), a, b, c)
    binary = wide.binary.reshape(-1)
    out = np.zeros((len(binary), _SLOT_DOUBLES))
    held = binary >= 0
    out[held] = per_node[binary[held]]
    return out
