"""What only some shape types do, behind capabilities: meshes' triangles held as shared vertices and
faces, tested by cast in blocks, packed as instances where meshes share their arrays, and shaded
with their own normals; mesh instances' shared arrays. The base interface (pyclray.model.shapes.base)
a new analytic shape implements knows none of it.

A capability is a mixin that a type takes among its bases, before ``Shape`` (``class Mesh(IndexedTriangles,
..., Shape)``), and implements; the engine asks ``capability(cls, name)`` before it calls the
capability's members. Each mixin has a switch, a class attribute named as the capability, True
there: a test turns one off on a type to compare with the path of the types without it.
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np

from ..layout import Struct


class IndexedTriangles:
    """Capability "indexed": the type's entries are triangles of shared vertices, kept on a device
    with float64 as those vertices and the faces (engine/scene/indexed.py; ``<type>_assemble`` and
    ``<type>_world_normal`` in its kernel file) instead of world entries and a per-view copy.

    A type with it defines ``pack_indexed`` and ``pack_indexed_smooth``."""

    indexed: ClassVar[bool] = True

    @classmethod
    def pack_indexed(cls, shapes) -> tuple[np.ndarray, np.ndarray]:
        """(world vertices (V, 4) float64, faces (F, 4) int32: vertex indices, primitive index or
        ~index where never hit), faces in pack_world's order."""
        raise NotImplementedError

    @classmethod
    def pack_indexed_smooth(cls, shapes, precision: str):
        """The (V, 4) vertex shading normals of pack_indexed's vertices, or None where none of
        these shapes shades with its own normals."""
        raise NotImplementedError


class CastBlocks:
    """Capability "cast_blocks": cast tests a leaf's entries of one shape at once (the mode's
    ``PYCLRAY_CAST_TEST_BLOCKS`` and the rest in its kernel file; engine/queries/cast_blocks.py packs them),
    to the bits of one entry at a time.

    A type with it defines ``pack_cast_blocks``."""

    cast_blocks: ClassVar[bool] = True

    @classmethod
    def pack_cast_blocks(cls, vertices, corners, ids, entries, starts) -> tuple[np.ndarray, np.ndarray]:
        """(blocks float64, places int64): block i of the world entries entries[starts[i]:starts[i + 1]]
        (all of one shape: ids), each at places[i] (in 64-byte units) of the returned array; the
        entries' corners index vertices (-1: never hit)."""
        raise NotImplementedError


class Instancing:
    """Capability "instancing": the prepared scene packs some of the type's shapes as another kind
    (meshes that share their arrays: as instances of one copy, pyclray/model/shapes/instance.py).

    A type with it defines ``packed_as``."""

    instancing: ClassVar[bool] = True

    @classmethod
    def packed_as(cls, shapes, ids) -> dict:
        """{kind: (shapes, ids)}: how the prepared scene packs these shapes of this type (kinds of
        pyclray.model.shapes.KINDS)."""
        raise NotImplementedError


class SharedArrays:
    """Capability "shared": the type's entries share arrays passed to its kernel after its entries'
    array (mesh instances: one copy of a mesh's triangles and BVH, engine/scene/instances.py).

    A type with it defines ``shared``: the arrays' (name, OpenCL C element type), which is its switch."""

    shared: ClassVar[tuple]


class SmoothShading:
    """Capability "smooth_shading": the type's shapes may shade with their own normals (a smooth
    mesh's interpolated vertex normals), passed to the shaded image only when a shape of the type
    asks for it, and ``<type>_shading_normal`` in its kernel file.

    A type with it defines ``smooth_struct`` (one entry's shading data), ``pack_smooth`` and, for
    the float64 reference, ``oracle_shading_normal``; for a render by casting, ``shading_normals``."""

    smooth_shading: ClassVar[bool] = True
    smooth_struct: ClassVar[Struct]

    @classmethod
    def pack_smooth(cls, shapes, precision: str):
        """The smooth_struct array of these shapes' entries (in pack_world's order), or None where
        none of them shades with its own normals."""
        raise NotImplementedError

    def oracle_shading_normal(self, points, normals) -> np.ndarray:
        """The float64 normal the shaded image lights with at these points of the surface, whose
        geometric normals are ``normals`` (where the shape shades with them, else ``normals``)."""
        raise NotImplementedError

    def shading_normals(self, primitives, barycentrics, normals) -> np.ndarray:
        """The float64 normals the shaded image lights with at the hits a cast reports (their
        ``primitive`` and ``barycentric``, geometric ``normals``): the shaded image of a render by
        casting (engine/queries/shade.py), as its kernel's ``<type>_shading_normal`` does."""
        raise NotImplementedError


# capability name -> its mixin
CAPABILITIES = {"indexed": IndexedTriangles, "cast_blocks": CastBlocks, "instancing": Instancing,
                "shared": SharedArrays, "smooth_shading": SmoothShading}


def capability(cls, name: str) -> bool:
    """Whether the shape type ``cls`` has the capability ``name`` (a key of CAPABILITIES): it takes
    the capability's mixin, and its switch (the class attribute ``name``) is on."""
    return issubclass(cls, CAPABILITIES[name]) and bool(getattr(cls, name))
