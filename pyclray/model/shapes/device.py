"""The device part of a shape type: how the engine packs its shapes and what its kernel file reads
(one of the three parts of pyclray.model.shapes.base.Shape; besides it, the engine reads only the
scene part's ``bounded`` and primitive counts, and the capabilities of capabilities.py).

The scene lives on the device in world coordinates (``world``: float64 fields, packed once per scene
by ``pack_world``); for each view the engine rebases it into the space of the camera (``struct``: what
the kernel's shape test reads) with ``<type>_rebase`` of the shape's kernel file, or on the host with
``rebase`` (devices without float64, and cast's per-shape spaces). Both compute what every ray from
the space's origin shares in float64 (error-free sums where a difference cancels), from the world
fields.
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np

from ..exact import dot2
from ..layout import Struct, layout


class DevicePacking:
    """The device part of the shape interface: the contract a shape type implements for the engine.

    A shape type defines (``required_members``):

    - ``c_type``: its struct's name in OpenCL C;
    - ``struct``: the packed layout of one entry in a space (what ``<type>_hit`` and
      ``<type>_normal`` read), declared once; its fields ``id`` and ``primitive`` included;
    - ``world``: the layout of one world entry (float64 fields, camera-independent);
    - ``kernel_files``: its kernel files under engine/kernels/, in order (a batch type reuses its
      single shape's: ``("sphere.cl", "spheres.cl")``); the file has ``<type>_rebase`` (under
      ``PYCLRAY_REBASE``: ``_rebase`` on the device, the same float64 operations in the same
      order), ``<type>_hit`` and ``<type>_normal``;
    - ``_pack_world(out, shapes)``: writes the world entries of these shapes into ``out`` (one per
      primitive: the scene part's ``primitive_count``);
    - ``_rebase(out, world, origin, rotation)``: writes the entries in a space from the world ones,
      in float64 on the host; ``origin`` is (3,) (one space for every entry: render) or (N, 3) (one
      space per entry, each at its own anchor: cast);
    - for a ``bounded`` type (the scene part's), ``bounds_of(world)``: the conservative box of each
      world entry (culling, the BVH).

    Optional, with defaults here: ``spheres_of`` (culling's bounding spheres: around the boxes),
    ``cast_anchors`` (where cast rebases each entry: the centre of its box), ``world_within`` (an
    unbounded type's range check), ``entries_of`` (the id and primitive index of each entry),
    ``barycentric`` (its kernel file has ``<type>_barycentric``), ``tested_from_world`` (a large
    scene rebases it where tested), ``leaf_size`` (entries per BVH leaf), ``kernel_structs`` (the
    structs of other types its kernel file uses), and for the closest-point query ``inside_test`` and
    ``winding_number`` (how its inside is decided).
    """

    required_members: ClassVar[tuple[str, ...]] = ("c_type", "struct", "world", "kernel_files", "_pack_world", "_rebase")

    c_type: ClassVar[str]
    struct: ClassVar[Struct]
    world: ClassVar[Struct]
    # the kernel files this type needs, in order (a batch type reuses its single shape's code)
    kernel_files: ClassVar[tuple[str, ...]]
    # True for a type whose kernel file has <type>_barycentric(shape, ray, &u, &v) (triangles): the
    # barycentric image's (u, v); the other types give (0, 0)
    barycentric: ClassVar[bool] = False
    # In a from-world scene (engine/scene/prepared.py's FROM_WORLD_FROM) a render rebases each entry of a type with
    # tested_from_world on the eye where it tests it, from its world entry (<type>_rebase): no per-view
    # copy (struct) of them, no pass over them for a new camera. The others keep the per-view pass's copy.
    tested_from_world: ClassVar[bool] = False
    # the most entries of this type per BVH leaf (None: engine/bvh/tree.py's LEAF_SIZE); a scene's tree
    # takes the largest of its bounded types'
    leaf_size: ClassVar[int | None] = None
    # the structs of other types its kernel file uses (mesh instances: the mesh's triangles)
    kernel_structs: ClassVar[tuple] = ()
    # The closest-point query (kernels/closest.cl): every type's kernel file has <type>_closest and
    # <type>_inside (kernels/closest.h); inside_test is True for a type whose <type>_inside decides
    # its inside (an analytic solid: a sphere, a box, a capped cylinder, a plane's half-space), False
    # for one without an inside (disks, rectangles) or decided otherwise; winding_number is True for a
    # type whose inside is its triangles' parity or generalized winding number (<type>_solid_angle: meshes)
    inside_test: ClassVar[bool] = False
    winding_number: ClassVar[bool] = False

    # -- world entries ---------------------------------------------------------------------------
    @classmethod
    def pack_world(cls, shapes) -> np.ndarray:
        """The world array of these shapes (float64 geometry, the world struct's dtype): one entry
        per primitive (see ``entries`` for their ids and primitive indices)."""
        counts = primitive_counts(shapes)
        out = np.zeros(int(counts.sum()), dtype=layout(cls.world, "fp64").dtype)
        if len(out):
            cls._pack_world(out, shapes)
        return out

    @classmethod
    def _pack_world(cls, out, shapes) -> None:
        raise NotImplementedError

    @classmethod
    def entries_of(cls, shapes, ids) -> tuple[np.ndarray, np.ndarray]:
        """(id, primitive) per world entry of these shapes (see entries)."""
        return entries(shapes, ids)

    # -- entries in a space ----------------------------------------------------------------------
    @classmethod
    def rebase(cls, world, origin, rotation, precision: str, ids=None, primitives=None) -> np.ndarray:
        """The packed array (``struct``) of these world entries in a space: origin (world, float64;
        (3,) for every entry, or (N, 3) one per entry) and rotation (rows: the space's axes in world
        coordinates), computed on the host in float64; ids and primitive indices as given (default 0)."""
        out = np.zeros(len(world), dtype=layout(cls.struct, precision).dtype)
        out["id"] = 0 if ids is None else ids
        out["primitive"] = 0 if primitives is None else primitives
        if len(world):
            cls._rebase(out, world, np.asarray(origin, np.float64), np.asarray(rotation, np.float64))
        return out

    @classmethod
    def _rebase(cls, out, world, origin, rotation) -> None:
        raise NotImplementedError

    @classmethod
    def pack(cls, shapes, ids, origin, rotation, precision: str) -> np.ndarray:
        """The packed array of these shapes in a space (pack_world, then rebase)."""
        entry_ids, primitives = entries(shapes, ids)
        return cls.rebase(cls.pack_world(shapes), origin, rotation, precision, entry_ids, primitives)

    @classmethod
    def world_within(cls, world, eye, limit: float) -> bool:
        """For a type without bounds (the BVH's box bounds the others): whether every length its
        kernel squares from this eye stays within limit (see the scene part's lengths)."""
        return True

    # -- bounds ----------------------------------------------------------------------------------
    @classmethod
    def bounds_of(cls, world) -> np.ndarray:
        """(N, 2, 3) float64: [lo, hi] of each world entry, conservative (every point of the
        primitive lies inside, whatever the rounding). Only for ``bounded`` types."""
        raise NotImplementedError(f"a {cls.type} has no bounds")

    @classmethod
    def spheres_of(cls, world) -> tuple[np.ndarray, np.ndarray]:
        """(centres (N, 3), radii (N,)) of spheres holding each world entry: by default the spheres
        around its bounds."""
        bounds = cls.bounds_of(world).reshape(-1, 2, 3)
        centre = 0.5 * (bounds[:, 0] + bounds[:, 1])
        return centre, 0.5 * np.linalg.norm(bounds[:, 1] - bounds[:, 0], axis=1) * (1 + 1e-12)

    @classmethod
    def cast_anchors(cls, world, ids):
        """(N, 4) float64 per world entry (ids: their shapes' ids): the point cast packs the entry
        relative to (xyz) and a radius about it holding the entry (w), or None for the default, the
        centre of each entry's own box (pyclray.engine.bvh.scene.SceneBVH.anchors)."""
        return None

    @classmethod
    def world_bounds(cls, shapes) -> np.ndarray:
        """(N, 2, 3) bounds of these shapes' primitives (see bounds_of)."""
        return cls.bounds_of(cls.pack_world(shapes))

    @classmethod
    def bounding_spheres(cls, shapes) -> tuple[np.ndarray, np.ndarray]:
        """(centres, radii) of spheres holding these shapes' primitives (see spheres_of)."""
        return cls.spheres_of(cls.pack_world(shapes))


def primitive_counts(shapes) -> np.ndarray:
    """How many world entries each shape is (a batch: its primitives)."""
    return np.fromiter((shape.primitive_count() for shape in shapes), np.int64, len(shapes))


def entries(shapes, ids) -> tuple[np.ndarray, np.ndarray]:
    """(id, primitive) int32 per world entry of these shapes (of these ids): each entry carries its
    shape's id and its index within its shape."""
    counts = primitive_counts(shapes)
    starts = np.cumsum(counts) - counts
    total = int(counts.sum())
    return (np.repeat(np.asarray(ids, np.int32).reshape(-1), counts),
            (np.arange(total) - np.repeat(starts, counts)).astype(np.int32))


def in_space(x, rotation) -> np.ndarray:
    """The coordinates of vectors x (N, 3) along a space's axes (rotation's rows), each summed as
    (r0 x0 + r1 x1) + r2 x2: the order kernels/rebase.cl's to_space sums in, so that the host's and
    the device's rebase round alike (numpy's matrix product may sum in another order)."""
    x = np.asarray(x, np.float64).reshape(-1, 3)
    rotation = np.asarray(rotation, np.float64)
    return (x[:, 0:1] * rotation[:, 0] + x[:, 1:2] * rotation[:, 1]) + x[:, 2:3] * rotation[:, 2]


def in_space_low(x, rotation, rounded) -> np.ndarray:
    """What the rounding of in_space(x, rotation) to the kernel's precision (``rounded``, the
    packed coordinates) left out, in float64 (rounded again where it is packed): a space direction
    as a float pair, for the fp32 camera rays' exact n . d (kernels/lanes.h: pixel_dot; the
    device's to_space_low, the same bits); 0 in fp64."""
    return in_space(x, rotation) - np.asarray(rounded, np.float64)


def rebase_flat(out, world, origin, rotation) -> None:
    """The fields a flat shape (disk, rectangle) rebases alike: its centre and unit normal in the
    space, the space origin's signed distance to its plane (normal.w, from float64 with an exact
    dot), and its world normal, as is."""
    center, normal = world["center"][:, :3], world["normal"][:, :3]
    F = center - origin
    out["center"][:, :3] = in_space(F, rotation)
    out["normal"][:, :3] = in_space(normal, rotation)
    out["normal_low"][:, :3] = in_space_low(normal, rotation, out["normal"][:, :3])
    out["normal"][:, 3] = -dot2(normal, F)
    out["world_normal"][:, :3] = normal


def padded_bounds(lo, hi) -> np.ndarray:
    """(N, 2, 3) bounds [lo, hi] widened by a few float64 ulps of their size, so that the rounding
    of their own computation never leaves a point of the shape outside."""
    lo = np.asarray(lo, np.float64).reshape(-1, 3)
    hi = np.asarray(hi, np.float64).reshape(-1, 3)
    pad = 1e-12 * (np.abs(lo) + np.abs(hi)) + 1e-300
    return np.stack([lo - pad, hi + pad], axis=1)
