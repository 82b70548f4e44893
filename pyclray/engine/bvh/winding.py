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
the second order of Barill et al.'s expansion. Its error falls as (radius / |d|)^3.
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
        ("m0", "double4"),  # rows of M = sum_i a_i (x_i - c)^T
        ("m1", "double4"),
        ("m2", "double4"),
    ),
    "A wide BVH child's far-field expansion of its triangles' solid angles (kernels/closest.cl).",
)

# a slot's expansion stands for its triangles where the point is farther than this many radii from
# its centre (Barill et al. take 2; 3 keeps the second order's error near 1e-3 of a slot's own term)
WINDING_BETA = 3.0


@numba.njit(cache=True, nogil=True)
def _aggregate(first, count, lo, hi, area_vectors, centroids):  # pragma: no cover - compiled
    nodes = len(first)
    A = np.zeros((nodes, 3))
    W = np.zeros(nodes)
    P = np.zeros((nodes, 3))
    S = np.zeros((nodes, 3, 3))
    # post-order without recursion: each node after its children
    stack = np.empty(max(nodes, 2) + 64, np.int64)
    done = np.zeros(nodes, np.bool_)
    top = 0
    stack[top] = 0
    top += 1
    while top > 0:
        node = stack[top - 1]
        if count[node] > 0:
            for q in range(first[node], first[node] + count[node]):
                a = area_vectors[q]
                x = centroids[q]
                w = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
                W[node] += w
                for j in range(3):
                    A[node, j] += a[j]
                    P[node, j] += w * x[j]
                    for k in range(3):
                        S[node, j, k] += a[j] * x[k]
            done[node] = True
            top -= 1
        elif done[first[node]] and done[first[node] + 1]:
            for child in (first[node], first[node] + 1):
                W[node] += W[child]
                for j in range(3):
                    A[node, j] += A[child, j]
                    P[node, j] += P[child, j]
                    for k in range(3):
                        S[node, j, k] += S[child, j, k]
            done[node] = True
            top -= 1
        else:
            stack[top] = first[node]
            stack[top + 1] = first[node] + 1
            top += 2
    out = np.zeros((nodes, 5, 4))
    for node in range(nodes):
        if W[node] <= 0.0:
            continue
        c = P[node] / W[node]
        radius = 0.0
        for corner in range(8):
            d2 = 0.0
            for j in range(3):
                v = hi[node, j] if (corner >> j) & 1 else lo[node, j]
                d2 += (v - c[j]) * (v - c[j])
            radius = max(radius, np.sqrt(d2))
        out[node, 0, :3] = c
        out[node, 0, 3] = radius
        out[node, 1, :3] = A[node]
        out[node, 1, 3] = W[node]
        for j in range(3):
            for k in range(3):
                out[node, 2 + j, k] = S[node, j, k] - A[node, j] * c[k]
    return out


def winding_slots(tree, wide, triangles_by_position: np.ndarray) -> np.ndarray:
    """(W * 8, 5, 4) float64, WINDING_SLOT's rows per child slot of the wide tree (empty slots and
    slots without triangles: area.w = 0). triangles_by_position: (N, 3, 3) per leaf position its
    triangle's vertices a, b, c, all 0 for a position that holds another shape (no solid angle)."""
    a, b, c = triangles_by_position[:, 0], triangles_by_position[:, 1], triangles_by_position[:, 2]
    area_vectors = np.ascontiguousarray(0.5 * np.cross(b - a, c - a))
    centroids = np.ascontiguousarray((a + b + c) / 3.0)
    per_node = _aggregate(np.ascontiguousarray(tree.first, np.int64), np.ascontiguousarray(tree.count, np.int64),
                          np.ascontiguousarray(tree.lo), np.ascontiguousarray(tree.hi), area_vectors, centroids)
    binary = wide.binary.reshape(-1)
    out = np.zeros((len(binary), 5, 4))
    held = binary >= 0
    out[held] = per_node[binary[held]]
    return out
