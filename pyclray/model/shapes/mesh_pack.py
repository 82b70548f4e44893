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


def cast_blocks(world, ids, entries, starts):
    """Mesh.pack_cast_blocks: per block (entries[starts[i]:starts[i + 1]], triangles of one mesh) at
    a 64-byte boundary, 1 + 9 count float64: a header (count, the mesh's id: two int32), then the
    rows a.x, a.y, a.z, b.x, ..., c.z of its count triangles (kernels/mesh.cl's cast blocks); zero-area
    triangles (a zero world normal) are left out, as the kernel would never hit them. Returns
    (blocks, places: each block's start in 64-byte units), the blocks padded by eight doubles (the
    kernel reads whole 8-wide rows)."""
    entries = np.asarray(entries, np.int64)
    starts = np.asarray(starts, np.int64)
    block_of = np.repeat(np.arange(len(starts) - 1), np.diff(starts))
    hit = (world["a"][entries, 3] != 0) | (world["b"][entries, 3] != 0) | (world["c"][entries, 3] != 0)
    kept, block_of = entries[hit], block_of[hit]
    count = np.bincount(block_of, minlength=len(starts) - 1)
    first = np.concatenate([[0], np.cumsum(count)])
    size = -(-(1 + 9 * count) // 8)  # in units of 8 doubles (64 bytes)
    places = np.concatenate([[0], np.cumsum(size)])
    out = np.zeros(8 * int(places[-1]) + 8)
    words = out.view(np.int32)  # the header's two ints: the first double's (little-endian) halves
    words[16 * places[:-1]] = count
    words[16 * places[:-1] + 1] = ids[entries[starts[:-1]]]
    lane = np.arange(len(kept)) - first[block_of]
    base = 8 * places[block_of] + 1 + lane
    for row, (name, axis) in enumerate((n, a) for n in "abc" for a in range(3)):
        out[base + row * count[block_of]] = world[name][kept, axis]
    return out, places[:-1]
