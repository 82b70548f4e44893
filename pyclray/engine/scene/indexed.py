"""Meshes as shared vertices and faces (the capability "indexed": IndexedTriangles.pack_indexed), on every device with float64: the render
kernel assembles each triangle it tests from its face and the per-view pass's vertices in the eye's
space (kernels/entries.h, INDEXED), and computes the winner's world normal from the float64 vertices.

A closed mesh has about half as many vertices as triangles, so per triangle this holds a face (16
bytes: three vertex indices and its primitive index, ~index for a zero-area triangle), half a
float64 vertex (32 bytes each) and half a vertex in the space (16 bytes each in fp32), and its id
(4 bytes): 44 bytes, against the per-view copy's 64 and the world entry's 96 (and the BVH's nodes
either way). The per-view pass rebases vertices, not triangles: a vertex shared by two triangles is
one vertex, the same bits in both (watertightness), as in the copy, which rounds each corner of each
triangle alike. A scene's few vertices are rebased on the host (the same float64 operations: no
rebase program to build for a small scene's first view); many, on the device."""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from ...model.shapes.device import in_space
from ..opencl.buffers import aligned, aligned_empty, device_buffer as _buffer

# entries from which the bounds are computed by the compiled loop (numba is imported by then anyway:
# bvh.SAH_FROM); below, numpy's gathers (no numba import in a small scene's cold start)
COMPILED_FROM = 16_384


def indexed_bounds(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 2, 3) float64: each face's triangle's box, padded as Shape.bounds_of pads its world entry's
    (device.padded_bounds of the corners' min and max): the same bits, without packing the 96-byte world
    entries (docs/benchmarks.md, "Why the engine does what it does": bvh_fast's compiled passes)."""
    if len(faces) >= COMPILED_FROM:
        from ..bvh.passes import triangle_bounds  # numba: large scenes only

        out = np.empty((len(faces), 2, 3))
        triangle_bounds(np.ascontiguousarray(vertices, np.float64), np.ascontiguousarray(faces, np.int32), out)
        return out
    from ...model.shapes.device import padded_bounds

    a, b, c = (vertices[faces[:, k], :3] for k in range(3))
    return padded_bounds(np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c))


class IndexedEntries:
    """One type's shared vertices (world, float64 (V, 4); in the space of the last view, real (V, 4))
    and its faces in the BVH's leaf order ((F, 4) int32), on the host and the device."""

    def __init__(self, prepared, cls, shapes, vertices, faces, shape_ids, order, ids):
        real = np.float64 if prepared.precision == "fp64" else np.float32
        # each shape's vertices (by its index in the scene): where they start, how many (an animation's moves)
        counts = [len(shape.vertices) for shape in shapes]
        self.vertex_range = dict(zip(shape_ids, zip(np.cumsum([0] + counts[:-1]).tolist(), counts)))
        # each shape's place among the type's shapes (Kind.shapes, which cast packs its entries from)
        self.slots = {index: slot for slot, index in enumerate(shape_ids)}
        self.world_vertices = aligned(np.ascontiguousarray(vertices, np.float64))
        # the faces in leaf order, gathered straight into aligned memory (no copy after)
        self.faces = aligned_empty(faces.shape, np.int32)
        if order is None:
            self.faces[:] = faces
        else:
            np.take(np.ascontiguousarray(faces, np.int32), order, axis=0, out=self.faces)
        self.ids = aligned(np.ascontiguousarray(ids, np.int32))
        self.vertices_host = aligned_empty((len(vertices), 4), real)
        self.vertices_host[:] = 0
        ctx = prepared.ctx
        self.world_buffer = _buffer(ctx, self.world_vertices)
        self.faces_buffer = _buffer(ctx, self.faces)
        self.ids_buffer = _buffer(ctx, self.ids)
        self.vertices = _buffer(ctx, self.vertices_host, writable=True)
        # smooth shading's vertex normals (IndexedTriangles.pack_indexed_smooth), if a shape shades with them
        smooth = cls.pack_indexed_smooth(shapes, prepared.precision)
        self.smooth_host = None if smooth is None else aligned(smooth)
        self.smooth = None if smooth is None else _buffer(ctx, self.smooth_host)

    @property
    def primitives(self) -> np.ndarray:
        """Each face's index in its shape (its face's w, ~index where never hit), in leaf order."""
        w = self.faces[:, 3]
        return np.where(w >= 0, w, ~w).astype(np.int32)

    def nbytes(self) -> int:
        return self.world_vertices.nbytes + self.faces.nbytes + self.ids.nbytes + self.vertices_host.nbytes

    def rebase(self, prepared, eye, rows) -> None:
        """The per-view pass over the vertices: each in the eye's space, on the device
        (kernels/rebase_kernels.cl; indexed entries exist on devices with float64 only)."""
        from ..launch.programs import Variant, kernels_for

        count = len(self.world_vertices)
        kernels = kernels_for(prepared.ctx, Variant("rebase", prepared.types, (), prepared.precision))
        space = [np.append(v, 0.0).view(cl.cltypes.double4)[0] for v in (eye, *rows)]
        kernels["rebase_vertices"](prepared.ctx.queue, *prepared._groups(count), self.world_buffer, self.vertices,
                                   np.int32(count), *space)

    # -- an animation's frame (pyclray.engine.scene.refit) ---------------------------------------------
    def holds(self, index: int, shape) -> bool:
        """Whether the shape at this scene index can take this one's vertices in place (as many)."""
        return self.vertex_range[index][1] == len(shape.vertices)

    def moved_bounds(self, index: int, shape, positions) -> tuple[np.ndarray, np.ndarray]:
        """(its new world vertices (count, 4), the bounds of its faces at these positions of the
        leaf order): a moved shape's, nothing written yet."""
        start, count = self.vertex_range[index]
        world = np.zeros((count, 4))
        world[:, :3] = shape.world_vertices()
        local = self.faces[positions].copy()
        local[:, :3] -= start
        return world, indexed_bounds(world, local)

    def move(self, prepared, index: int, world: np.ndarray, shared: bool) -> None:
        """Write a moved shape's world vertices, on the host and the device, and, where the prepared
        scene holds a view, its vertices in that view's space (in_space: the device pass's bits)."""
        start, count = self.vertex_range[index]
        self.world_vertices[start:start + count] = world
        queue = prepared.ctx.queue
        if not shared:
            cl.enqueue_copy(queue, self.world_buffer, self.world_vertices[start:start + count], dst_offset=start * 32)
        if prepared.view is not None:
            eye, rows = prepared.view
            self.vertices_host[start:start + count, :3] = in_space(world[:, :3] - eye, rows)
            if not shared:
                cl.enqueue_copy(queue, self.vertices, self.vertices_host[start:start + count],
                                dst_offset=start * self.vertices_host.itemsize * 4)
