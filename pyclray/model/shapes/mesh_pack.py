"""A framed scene's meshes as shared vertices and faces (Shape.pack_indexed; pyclray/engine/indexed.py)."""
from __future__ import annotations

import numpy as np


def indexed(meshes):
    """(world vertices (V, 4) float64, faces (F, 4) int32): each mesh's world vertices; its faces offset
    to them, each with its index in its mesh (~index for a zero-area one: never hit). Written in place
    (a million faces' column stack and short-axis reductions cost 40 ms)."""
    vertices = np.zeros((sum(len(m.vertices) for m in meshes), 4))
    faces = np.empty((sum(len(m.faces) for m in meshes), 4), np.int32)
    start = first = 0
    for mesh in meshes:
        count = len(mesh.faces)
        vertices[start:start + len(mesh.vertices), :3] = mesh.world_vertices()
        mine = faces[first:first + count]
        np.add(mesh.faces, start, out=mine[:, :3], casting="unsafe")
        normal = mesh.face_normals()
        hit = (normal[:, 0] != 0) | (normal[:, 1] != 0) | (normal[:, 2] != 0)  # a zero-area triangle's is 0
        index = np.arange(count, dtype=np.int32)
        mine[:, 3] = np.where(hit, index, ~index)
        start += len(mesh.vertices)
        first += count
    return vertices, faces


def indexed_smooth(meshes, precision: str):
    """Mesh.pack_smooth per shared vertex: (V, 4) the smooth meshes' vertex normals, zeros for the
    others' vertices; None without a smooth mesh."""
    if not any(mesh.smooth for mesh in meshes):
        return None
    normals = [mesh.vertex_normals() if mesh.smooth else np.zeros((len(mesh.vertices), 3)) for mesh in meshes]
    out = np.zeros((sum(len(n) for n in normals), 4), np.float64 if precision == "fp64" else np.float32)
    out[:, :3] = np.concatenate(normals)
    return out
