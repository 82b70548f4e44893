"""What every shape type provides (see pyclray/model/shapes/__init__.py).

A shape module owns everything about its shape, so that nothing outside pyclray/model/shapes/ asks which
type a shape is (pbrt-v4's Shape interface, Mitsuba's plugins):

- scene file: ``type``, ``keys``, ``required``, ``_from_table`` and the dataclass's validation;
- device: ``world`` and ``_pack_world`` (the world-space float64 entries, packed once), ``c_type``,
  ``struct`` and ``_rebase`` (the entries in a camera's frame, in float64 on the host), and
  engine/kernels/<type>.cl with ``<type>_rebase`` (the same on the device), ``<type>_hit`` and
  ``<type>_normal``;
- bounds: ``bounded`` and ``bounds_of`` (culling, the BVH), ``spheres_of``;
- the float64 oracle: ``oracle_distance``, ``oracle_normal``, ``surface_distance``,
  ``edge_distance`` (where a ray may go either way);
- the error model (pyclray.reference.error_model): ``anchor`` (the point its coordinates are measured from)
  and ``curvature_radius`` (how a position error turns the normal);
- Mitsuba 3 (pyclray.mitsuba): ``mitsuba_shapes`` (its counterpart, one or more Mitsuba shapes that
  all map back to this shape's id) and ``mitsuba_covers`` (where that counterpart ends); Mitsuba's
  XML files (pyclray.model.mitsuba_xml): ``mitsuba_plugins`` (the plugins read as this type) and
  ``from_mitsuba`` (how one is read), ``mitsuba_in_groups``;
- optional: ``silhouette_radius`` (the silhouette rule's radius: inf for flat pieces),
  ``oracle_primitives`` (primitives of many), ``leaf_size`` (entries per BVH leaf), and for shapes
  lit by their own normals ``smooth_struct``, ``pack_smooth``, ``oracle_shading_normal`` and
  ``<type>_shading_normal`` in the kernel file (a smooth mesh).
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from ..errors import integer, no_unknown_keys, text
from ..exact import dot2
from ..layout import Struct, layout
from ..lights import MATERIAL_KEYS, Material


@dataclass(frozen=True, kw_only=True)
class Shape:
    """Base of the shape dataclasses.

    Every shape has a ``material`` (keyword only; its scene-file keys color, specular and shininess
    belong to every shape type and are read here, not by the shape's module).

    Each subclass sets ``type`` (its name in scene files), ``c_type`` (its struct in OpenCL C; the
    kernel functions are ``<type>_hit`` and ``<type>_normal`` in ``kernels/<type>.cl``), ``struct``
    (its packed layout, declared once) and ``keys`` (the keys of its scene table besides type and
    name), and implements the methods below that raise NotImplementedError.

    ``_rebase(out, world, origin, rotation)`` must accept ``origin`` of shape (3,) (one frame for
    every entry: render) or (N, 3) (one frame per entry, each at its own anchor: cast).
    """

    type: ClassVar[str]
    c_type: ClassVar[str]
    struct: ClassVar[Struct]
    keys: ClassVar[tuple[str, ...]]
    required: ClassVar[tuple[str, ...]] = ()
    material: Material = field(default=Material(), compare=True)
    # an optional class label (an integer >= 0) beside the shape's id, for the `label` AOV: class
    # masks beside instance masks. Not animated (a class does not change between frames).
    label: int | None = field(default=None, metadata={"animatable": False})
    # False for shapes without finite bounds (the plane): visited by every ray, outside the BVH
    bounded: ClassVar[bool] = True
    # a solid has an inside: a ray starting there sees its far side (only t > 0 counts)
    solid: ClassVar[bool] = False

    # -- scene file ----------------------------------------------------------------------------
    # True for a type whose table may name files (read relative to the scene file's folder)
    reads_files: ClassVar[bool] = False

    @classmethod
    def from_table(cls, table: dict, index: int, folder=None):
        no_unknown_keys(table, ("type", "name", "label") + cls.keys + MATERIAL_KEYS, required=cls.required)
        name = text("name", table.get("name", f"{cls.type}{index}"))
        material = Material.from_table(table)
        label = check_label(table.get("label"))
        own = {k: v for k, v in table.items() if k not in MATERIAL_KEYS and k != "label"}
        shape = cls._from_table(own, name, folder) if cls.reads_files else cls._from_table(own, name)
        common = {k: v for k, v in (("material", material), ("label", label)) if v != getattr(shape, k)}
        return replace(shape, **common) if common else shape

    @classmethod
    def _from_table(cls, table: dict, name: str):
        raise NotImplementedError

    @classmethod
    def random(cls, rng, shift=0.0):
        """A random instance of about unit size near ``shift`` (numpy Generator ``rng``), for the
        generic property tests over the registry (tests/test_shapes.py)."""
        raise NotImplementedError

    def describe(self) -> str:
        return f"{self.type} '{self.name}'"

    # -- device --------------------------------------------------------------------------------
    # The scene lives on the device in world coordinates (``world``: float64 fields, packed once per
    # scene by ``pack_world``); for each view the engine rebases it into the frame of the camera
    # (``struct``: what the kernel's shape test reads) with ``<type>_rebase`` of the shape's kernel
    # file, or on the host with ``rebase`` (devices without float64, and cast's per-shape frames).
    # Both compute what every ray from the frame's origin shares in float64 (error-free sums where
    # a difference cancels), from the world fields.
    world: ClassVar[Struct]
    # True for a type whose kernel file has <type>_barycentric(shape, ray, &u, &v) (triangles): the
    # barycentric image's (u, v); the other types give (0, 0)
    barycentric: ClassVar[bool] = False
    # the kernel files this type needs, in order (a batch type reuses its single shape's code)
    kernel_files: ClassVar[tuple[str, ...]] = ()
    # In a framed scene (engine/scene/prepared.py's FRAMED_FROM) a render frames each entry of a type with
    # frames_in_render on the eye where it tests it, from its world entry (<type>_rebase): no per-view
    # copy (struct) of them, no pass over them for a new camera; an indexed type's triangles are kept
    # as shared vertices and faces (pack_indexed, engine/scene/indexed.py; <type>_assemble and
    # <type>_world_normal in its kernel file). The others keep the per-view pass's copy.
    frames_in_render: ClassVar[bool] = False
    indexed: ClassVar[bool] = False

    @classmethod
    def pack_indexed(cls, shapes) -> tuple[np.ndarray, np.ndarray]:
        """(world vertices (V, 4) float64, faces (F, 4) int32: vertex indices, primitive index or
        ~index where never hit), faces in pack_world's order."""
        raise NotImplementedError

    @classmethod
    def pack_indexed_smooth(cls, shapes, precision: str):
        """An indexed type's (V, 4) vertex shading normals (pack_indexed's vertices), or None."""
        return None
    # the most entries of this type per BVH leaf (None: engine/bvh/tree.py's LEAF_SIZE); a scene's tree
    # takes the largest of its bounded types'
    leaf_size: ClassVar[int | None] = None
    # a type whose shapes may shade with their own normals (a smooth mesh's interpolated vertex
    # normals): the struct of one entry's shading data (a buffer passed to the shaded image only when
    # a shape of the type asks for it: pack_smooth) and <type>_shading_normal in its kernel file
    smooth_struct: ClassVar[Struct | None] = None

    # cast: True for a type whose kernel file tests a leaf's entries of one shape at once
    # (PYCLRAY_CAST_TEST_BLOCKS and the rest of that mode, kernels/rays.h); cast_blocks packs them
    cast_blocks: ClassVar[bool] = False

    @classmethod
    def pack_cast_blocks(cls, vertices, corners, ids, entries, starts) -> tuple[np.ndarray, np.ndarray]:
        """(blocks float64, places int64): the blocks of a cast_blocks type, block i of the world
        entries entries[starts[i]:starts[i + 1]] (all of one shape: ids), each at places[i] (in
        64-byte units) of the returned array; the entries' corners index vertices (-1: never hit)."""
        raise NotImplementedError

    # the arrays a type shares among its entries (name, OpenCL C element type), passed to the kernel
    # after its entries' array (mesh instances: one copy of a mesh's triangles and BVH)
    shared: ClassVar[tuple] = ()
    # the structs of other types its kernel file uses (mesh instances: the mesh's triangles)
    kernel_structs: ClassVar[tuple] = ()

    @classmethod
    def packed_as(cls, shapes, ids) -> dict:
        """{kind: (shapes, ids)}: how the prepared scene packs these shapes of this type (a kind of
        pyclray.model.shapes.KINDS); by default as themselves."""
        return {cls.type: (shapes, ids)}

    @classmethod
    def entries_of(cls, shapes, ids) -> tuple[np.ndarray, np.ndarray]:
        """(id, primitive) per world entry of these shapes (see entries)."""
        return entries(shapes, ids)

    @classmethod
    def pack_smooth(cls, shapes, precision: str):
        """The smooth_struct array of these shapes' entries (in pack_world's order), or None where
        none of them shades with its own normals."""
        return None

    def oracle_shading_normal(self, points, normals) -> np.ndarray:
        """The float64 normal the shaded image lights with at these points of the surface, whose
        geometric normals are ``normals``: the geometric normal (a smooth mesh: its interpolated
        vertex normal)."""
        return normals

    def primitive_count(self) -> int:
        """How many entries of the packed arrays this shape is (a batch: one per primitive)."""
        return 1

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
    def rebase(cls, world, origin, rotation, precision: str, ids=None, primitives=None) -> np.ndarray:
        """The packed array (``struct``) of these world entries in a frame: origin (world, float64;
        (3,) for every entry, or (N, 3) one per entry) and rotation (rows: the frame's axes in world
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
        """The packed array of these shapes in a frame (pack_world, then rebase)."""
        entry_ids, primitives = entries(shapes, ids)
        return cls.rebase(cls.pack_world(shapes), origin, rotation, precision, entry_ids, primitives)

    @classmethod
    def world_within(cls, world, eye, limit: float) -> bool:
        """For a type without bounds (the BVH's box bounds the others): whether every length its
        kernel squares from this eye stays within limit (see lengths)."""
        return True

    def lengths(self, eye) -> dict[str, float]:
        """Scene key -> the size of what the kernel computes from it in the camera's frame (e.g. a
        centre's distance from the eye, a radius), which the kernel may square: the range check
        (scene.check_renderable) refuses a scene whose lengths exceed the precision's range."""
        return {}

    # -- bounds --------------------------------------------------------------------------------
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

    def box(self) -> np.ndarray:
        """(2, 3) [lo, hi]: the box holding the whole shape (every primitive of a batch)."""
        bounds = self.world_bounds([self])
        return np.stack([bounds[:, 0].min(axis=0), bounds[:, 1].max(axis=0)])

    @classmethod
    def bounding_spheres(cls, shapes) -> tuple[np.ndarray, np.ndarray]:
        """(centres, radii) of spheres holding these shapes' primitives (see spheres_of)."""
        return cls.spheres_of(cls.pack_world(shapes))

    # -- the float64 oracle --------------------------------------------------------------------
    def oracle_distance(self, origins, directions) -> np.ndarray:
        """Distance t > 0 along unit directions (N, 3) to the nearest crossing, inf where none."""
        raise NotImplementedError

    def oracle_normal(self, points) -> np.ndarray:
        """Unit world normal (as the contract says: outward, never flipped) at points on the surface."""
        raise NotImplementedError

    def surface_distance(self, points) -> np.ndarray:
        """Unsigned distance from points (N, 3) to the surface."""
        raise NotImplementedError

    def oracle_primitives(self, origins, directions):
        """The index of the primitive each ray's nearest hit is on (-1 on a miss), float64; None for
        a shape of one primitive."""
        return None

    def edge_distance(self, points) -> np.ndarray:
        """Distance from points on the surface to its nearest edge (a rim, a border, a box's edge),
        where a ray within rounding may go either way; inf for a shape without edges."""
        return np.full(np.shape(points)[:-1], np.inf)

    # -- the error model -----------------------------------------------------------------------
    def anchor(self, point) -> np.ndarray:
        """The point this shape's intersection measures coordinates from, for rays from ``point``
        (the sphere's centre, a plane's foot of the point, a cylinder's farther end ...): the error
        model's coordinate size is max(|point|, |anchor|, |point - anchor|)."""
        raise NotImplementedError

    # how much larger than the model's K eps (t + L) its Mitsuba counterpart's error may be (the
    # engine's own formulas are the shape's business: see the cylinder)
    mitsuba_error_scale: ClassVar[float] = 1.0

    def curvature_radius(self) -> float:
        """The smallest radius of curvature (inf for flat shapes): a position error e along the
        surface turns the normal by e / radius."""
        return np.inf

    def silhouette_radius(self) -> float:
        """The radius of curvature at its silhouettes, for the silhouette rule's square-root law
        (error_model.silhouettes): the curvature radius, unless the surface is flat pieces (a mesh),
        whose silhouettes lie on edges that the edge rule judges."""
        return self.curvature_radius()

    def extent_from(self, point) -> float:
        """How far from ``point`` the shape reaches (for Mitsuba's clip range)."""
        bounds = self.box()
        corners = np.array([[bounds[i][0], bounds[j][1], bounds[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        return float(np.linalg.norm(corners - np.asarray(point, np.float64), axis=1).max())

    # -- Mitsuba 3 -----------------------------------------------------------------------------
    def mitsuba_shapes(self, scene) -> list[dict]:
        """Mitsuba scene dicts of this shape's counterpart (one or more; they all map back to this
        shape's id). A ``to_world`` value is a 4x4 float64 numpy matrix (the bridge converts it)."""
        raise NotImplementedError

    # True where the Mitsuba counterpart is one shape numbering its primitives as this type does
    # (a mesh's triangles: Mitsuba's prim_index is pyclray's primitive), so checks compare them
    mitsuba_primitives: ClassVar[bool] = False

    def mitsuba_covers(self, scene, points) -> np.ndarray:
        """Whether Mitsuba's counterpart holds these points of the shape (False where a stand-in
        ends, such as the plane's disk)."""
        return np.ones(np.shape(points)[:-1], bool)

    # the <shape type=...> plugins of Mitsuba's XML read as this type (pyclray.model.mitsuba_xml),
    # each by from_mitsuba; none for a type Mitsuba has no plugin for
    mitsuba_plugins: ClassVar[tuple[str, ...]] = ()
    # True where a <shapegroup> may hold it (an <instance> places it anew: ``placed(matrix=...)``)
    mitsuba_in_groups: ClassVar[bool] = False

    @classmethod
    def from_mitsuba(cls, props, folder):
        """The shape of one of mitsuba_plugins: its properties taken from props (the plugin's
        pyclray.model.mitsuba_xml.properties.Properties; what it cannot map is props.element.error),
        the constructor with its arguments bound, called with the name and material by the reader.
        folder: the one a file named by the plugin is relative to."""
        raise NotImplementedError


LABEL_MAX = 2**31 - 1  # labels are int32 in the label image


def check_label(value) -> int | None:
    """A shape's label: None (no label) or a whole number 0 <= label <= 2^31 - 1 (a SceneError at
    the key 'label' otherwise)."""
    return None if value is None else integer("label", value, minimum=0, maximum=LABEL_MAX)


def labels_of(shapes) -> np.ndarray:
    """(N,) int32: each shape's label, -1 for a shape without one."""
    return np.array([-1 if shape.label is None else shape.label for shape in shapes], np.int32).reshape(-1)


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


def frame_columns(normal) -> np.ndarray:
    """(t1, t2, n): a right-handed orthonormal frame around the unit vector n, float64."""
    n = np.asarray(normal, np.float64)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(helper, n)
    t1 /= np.linalg.norm(t1)
    return np.stack([t1, np.cross(n, t1), n])


def to_world(columns, origin) -> np.ndarray:
    """The 4x4 matrix with these three columns and this translation."""
    matrix = np.eye(4)
    for k, column in enumerate(columns):
        matrix[:3, k] = column
    matrix[:3, 3] = origin
    return matrix


def in_frame(x, rotation) -> np.ndarray:
    """The coordinates of vectors x (N, 3) along a frame's axes (rotation's rows), each summed as
    (r0 x0 + r1 x1) + r2 x2: the order kernels/rebase.cl's to_frame sums in, so that the host's and
    the device's rebase round alike (numpy's matrix product may sum in another order)."""
    x = np.asarray(x, np.float64).reshape(-1, 3)
    rotation = np.asarray(rotation, np.float64)
    return (x[:, 0:1] * rotation[:, 0] + x[:, 1:2] * rotation[:, 1]) + x[:, 2:3] * rotation[:, 2]


def rebase_flat(out, world, origin, rotation) -> None:
    """The fields a flat shape (disk, rectangle) rebases alike: its centre and unit normal in the
    frame, the frame origin's signed distance to its plane (normal.w, from float64 with an exact
    dot), and its world normal, as is."""
    center, normal = world["center"][:, :3], world["normal"][:, :3]
    F = center - origin
    out["center"][:, :3] = in_frame(F, rotation)
    out["normal"][:, :3] = in_frame(normal, rotation)
    out["normal"][:, 3] = -dot2(normal, F)
    out["world_normal"][:, :3] = normal


def flat_hits(center, normal, origins, directions, inside) -> np.ndarray:
    """A flat shape's float64 oracle: the distance t > 0 at which each ray meets the plane through
    center with unit normal, where inside(P) holds (P the hit point from the centre), else +inf."""
    F = np.array(center) - origins
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (F @ normal) / (directions @ normal)
        P = t[..., None] * directions - F
        hit = (t > 0) & np.isfinite(t) & inside(P)
    return np.where(hit, t, np.inf)


def dot_rows(a, b) -> np.ndarray:
    return np.einsum("...k,...k", a, b)


def padded_bounds(lo, hi) -> np.ndarray:
    """(N, 2, 3) bounds [lo, hi] widened by a few float64 ulps of their size, so that the rounding
    of their own computation never leaves a point of the shape outside."""
    lo = np.asarray(lo, np.float64).reshape(-1, 3)
    hi = np.asarray(hi, np.float64).reshape(-1, 3)
    pad = 1e-12 * (np.abs(lo) + np.abs(hi)) + 1e-300
    return np.stack([lo - pad, hi + pad], axis=1)


def unit_rows(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def flag(key: str, value) -> bool:
    """A TOML boolean (true or false); 1, 0 and strings are not."""
    from ..errors import SceneError, _shown

    if not isinstance(value, bool):
        raise SceneError(f"expected true or false, got {_shown(value)}", key=key)
    return value


def distance(point, eye) -> float:
    """|point - eye| in float64, inf where it overflows (the range check refuses it)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return float(math.hypot(*np.subtract(point, eye)))
