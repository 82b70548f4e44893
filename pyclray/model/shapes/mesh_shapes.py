"""Meshes made in code, for tests, benchmarks and examples: perturbed spheres, grids and tori, as
(vertices (V, 3) float64, faces (F, 3) int64), closed ones wound outward (counter-clockwise seen from
outside: cross(b - a, c - a) points out)."""
from __future__ import annotations

import numpy as np


def _wrap(rows: int, columns: int, closed_rows: bool) -> np.ndarray:
    """The two triangles of each cell of a rows x columns grid of vertices whose columns wrap
    around (and whose rows too with closed_rows)."""
    i, j = np.meshgrid(np.arange(rows if closed_rows else rows - 1), np.arange(columns), indexing="ij")
    i, j = i.reshape(-1), j.reshape(-1)
    a = i * columns + j
    b = i * columns + (j + 1) % columns
    c = ((i + 1) % rows) * columns + (j + 1) % columns
    d = ((i + 1) % rows) * columns + j
    return np.concatenate([np.stack([a, d, c], 1), np.stack([a, c, b], 1)]).reshape(-1, 3)


def uv_sphere(rings: int, segments: int, radius: float = 1.0):
    """A closed UV sphere: rings - 1 rows of segments vertices between the two poles."""
    theta = np.pi * np.arange(1, rings) / rings
    phi = 2 * np.pi * np.arange(segments) / segments
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack([st * np.cos(phi), st * np.sin(phi), ct * np.ones(segments)], -1)
    vertices = np.concatenate([[[0.0, 0.0, 1.0]], ring.reshape(-1, 3), [[0.0, 0.0, -1.0]]]) * radius
    body = _wrap(rings - 1, segments, False) + 1
    j = np.arange(segments)
    top = np.stack([np.zeros(segments, int), 1 + j, 1 + (j + 1) % segments], 1)
    last = 1 + (rings - 2) * segments
    bottom = np.stack([np.full(segments, len(vertices) - 1), last + (j + 1) % segments, last + j], 1)
    faces = np.concatenate([top, body, bottom]).astype(np.int64)
    # outward: the top fan goes (pole, j, j + 1), seen from above counter-clockwise
    return vertices, faces


def perturbed_sphere(rings: int, segments: int, radius: float, noise: float, rng):
    """A closed sphere whose vertices lie at radius (1 + noise * uniform(-1, 1)) each."""
    vertices, faces = uv_sphere(rings, segments, radius)
    vertices = vertices * (1 + noise * rng.uniform(-1, 1, (len(vertices), 1)))
    return vertices, faces


def grid(rows: int, columns: int, size: float = 1.0):
    """A flat square grid in the xz plane (y = 0), normals +y, of rows x columns cells."""
    x, z = np.meshgrid(np.linspace(-size / 2, size / 2, columns + 1), np.linspace(-size / 2, size / 2, rows + 1))
    vertices = np.stack([x.reshape(-1), np.zeros(x.size), z.reshape(-1)], 1)
    i, j = np.meshgrid(np.arange(rows), np.arange(columns), indexing="ij")
    a = (i * (columns + 1) + j).reshape(-1)
    b, c, d = a + 1, a + columns + 2, a + columns + 1
    faces = np.concatenate([np.stack([a, d, c], 1), np.stack([a, c, b], 1)])
    return vertices, faces.astype(np.int64)


def torus(rings: int, segments: int, major: float = 1.0, minor: float = 0.3):
    """A closed torus about the z axis."""
    u = 2 * np.pi * np.arange(rings) / rings
    v = 2 * np.pi * np.arange(segments) / segments
    U, V = np.meshgrid(u, v, indexing="ij")
    r = major + minor * np.cos(V)
    vertices = np.stack([r * np.cos(U), r * np.sin(U), minor * np.sin(V)], -1).reshape(-1, 3)
    return vertices, _wrap(rings, segments, True).astype(np.int64)


def _shared(vertices, faces):
    vertices, faces = np.array(vertices, np.float64), np.array(faces, np.int64)
    vertices.setflags(write=False)
    faces.setflags(write=False)
    return vertices, faces


# Mitsuba 3's own meshes of its cube ([-1, 1]^3: 4 vertices per face, 2 triangles each, in its
# order) and rectangle ([-1, 1]^2 in z = 0), read from Mitsuba 3.9's shapes: what its `cube` and
# `rectangle` plugins are under any to_world. One read-only pair each, shared by every use (so
# that several are instances of one mesh on the device).
MITSUBA_CUBE = _shared(
    [[1, -1, -1], [1, -1, 1], [-1, -1, 1], [-1, -1, -1], [1, 1, -1], [-1, 1, -1], [-1, 1, 1], [1, 1, 1],
     [1, -1, -1], [1, 1, -1], [1, 1, 1], [1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1], [-1, -1, 1],
     [-1, -1, 1], [-1, 1, 1], [-1, 1, -1], [-1, -1, -1], [1, 1, -1], [1, -1, -1], [-1, -1, -1], [-1, 1, -1]],
    [[0, 1, 2], [3, 0, 2], [4, 5, 6], [7, 4, 6], [8, 9, 10], [11, 8, 10], [12, 13, 14], [15, 12, 14],
     [16, 17, 18], [19, 16, 18], [20, 21, 22], [23, 20, 22]])
MITSUBA_RECTANGLE = _shared([[-1, -1, 0], [1, -1, 0], [-1, 1, 0], [1, 1, 0]], [[1, 2, 0], [1, 3, 2]])
