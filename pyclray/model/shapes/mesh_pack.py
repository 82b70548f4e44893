"""A from-world scene's meshes as shared vertices and faces (IndexedTriangles.pack_indexed; pyclray/engine/scene/indexed.py)."""
from __future__ import annotations

import numpy as np


def indexed(meshes):
    """(world vertices (V, 4) float64, faces (F, 4) int32): each mesh's world vertices; its faces offset
    to them, each with its index in its mesh (~index for a zero-area one: never hit). Written in place
    (no column stack, no short-axis reductions: docs/benchmarks.md, "Why the engine does what it
    does")."""
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


def cast_blocks(vertices, corners, ids, entries, starts):
    """Mesh.pack_cast_blocks: per block (entries[starts[i]:starts[i + 1]], triangles of one mesh) at
    a 64-byte boundary of float64s: a header (two int32: count | unique << 8, the mesh's id), the
    block's unique vertices as rows x, y, z (unique float64s each), then its triangles' corners as
    rows a, b, c (count bytes each: indices into those vertices) (kernels/mesh.cl's cast blocks).
    vertices (V, 3+) float64; corners (F, 3) the entries' vertex indices, -1 for a zero-area
    triangle (left out: the kernel would never hit it). Returns (blocks, places: each block's start
    in 64-byte units), padded by eight doubles."""
    entries = np.asarray(entries, np.int64)
    starts = np.asarray(starts, np.int64)
    n_blocks = len(starts) - 1
    block_of = np.repeat(np.arange(n_blocks), np.diff(starts))
    hit = corners[entries, 0] >= 0
    kept, block_of = entries[hit], block_of[hit]
    count = np.bincount(block_of, minlength=n_blocks)
    first = np.concatenate([[0], np.cumsum(count)])
    # each block's vertices once (by index: a vertex shared by its triangles is one row entry)
    vertex_count = max(len(vertices), 1)
    keys = (block_of[:, None] * vertex_count + corners[kept]).ravel()
    unique_keys, local = np.unique(keys, return_inverse=True)
    unique_block = unique_keys // vertex_count
    unique = np.bincount(unique_block, minlength=n_blocks)
    unique_first = np.concatenate([[0], np.cumsum(unique)])
    local = (local - unique_first[np.repeat(block_of, 3)]).reshape(-1, 3)
    size = -(-(1 + 3 * unique + -(-3 * count // 8)) // 8)  # in units of 8 doubles (64 bytes)
    places = np.concatenate([[0], np.cumsum(size)])
    out = np.zeros(8 * int(places[-1]) + 8)
    words = out.view(np.int32)  # the header's two ints: the first double's (little-endian) halves
    words[16 * places[:-1]] = count | (unique << 8)
    words[16 * places[:-1] + 1] = ids[entries[starts[:-1]]]
    base = 8 * places[:-1] + 1  # each block's rows
    j = np.arange(len(unique_keys)) - unique_first[unique_block]
    for axis in range(3):
        out[base[unique_block] + axis * unique[unique_block] + j] = vertices[unique_keys % vertex_count, axis]
    corner_bytes = out.view(np.uint8)
    lane = np.arange(len(kept)) - first[block_of]
    at = 8 * (base + 3 * unique)  # each block's corner rows, in bytes
    for k in range(3):
        corner_bytes[at[block_of] + k * count[block_of] + lane] = local[:, k]
    return out, places[:-1]
