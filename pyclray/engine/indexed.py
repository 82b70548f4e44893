"""A framed scene's triangles as shared vertices and faces (Shape.pack_indexed): the render kernel
assembles each triangle it tests from its face and the per-view pass's vertices in the eye's frame
(kernels/pyclray.cl, INDEXED), and computes the winner's world normal from the float64 vertices.

A closed mesh has about half as many vertices as triangles, so per triangle this holds a face (16
bytes: three vertex indices and its primitive index, ~index for a zero-area triangle), half a
float64 vertex (32 bytes each) and half a vertex in the frame (16 bytes each in fp32), and its id
(4 bytes): 44 bytes, against the per-view copy's 64 and the world entry's 96 (and the BVH's nodes
either way). The per-view pass frames vertices, not triangles: a vertex shared by two triangles is
one vertex, the same bits in both (watertightness), as in the copy, which rounds each corner of each
triangle alike."""
from __future__ import annotations

import numpy as np

from .buffers import aligned, device_buffer as _buffer


class IndexedEntries:
    """One type's shared vertices (world, float64 (V, 4); in the frame of the last view, real (V, 4))
    and its faces in the BVH's leaf order ((F, 4) int32), on the host and the device."""

    def __init__(self, prepared, cls, shapes, order, ids):
        world_vertices, faces = cls.pack_indexed(shapes)
        real = np.float64 if prepared.precision == "fp64" else np.float32
        self.world_vertices = aligned(np.ascontiguousarray(world_vertices, np.float64))
        self.faces = aligned(np.ascontiguousarray(faces[order], np.int32))
        self.ids = aligned(np.ascontiguousarray(ids, np.int32))
        self.vertices_host = aligned(np.zeros((len(world_vertices), 4), real))
        ctx = prepared.ctx
        self.world_buffer = _buffer(ctx, self.world_vertices)
        self.faces_buffer = _buffer(ctx, self.faces)
        self.ids_buffer = _buffer(ctx, self.ids)
        self.vertices = _buffer(ctx, self.vertices_host, writable=True)
        # smooth shading's vertex normals (Shape.pack_indexed_smooth), if a shape shades with them
        smooth = cls.pack_indexed_smooth(shapes, prepared.precision)
        self.smooth_host = None if smooth is None else aligned(smooth)
        self.smooth = None if smooth is None else _buffer(ctx, self.smooth_host)

    def nbytes(self) -> int:
        return self.world_vertices.nbytes + self.faces.nbytes + self.ids.nbytes + self.vertices_host.nbytes

    def kernel_args(self) -> list:
        """The render kernel's arguments of the type (kernels/pyclray.cl: PYCLRAY_ENTRIES_INDEXED)."""
        return [self.faces_buffer, self.vertices, self.world_buffer, self.ids_buffer]

    def rebase(self, prepared, kernels, frame) -> None:
        """The per-view pass over the vertices: each in the eye's frame (kernels/rebase_kernels.cl)."""
        count = len(self.world_vertices)
        kernels["rebase_vertices"](prepared.ctx.queue, *prepared._groups(count), self.world_buffer, self.vertices,
                                   np.int32(count), *frame)
