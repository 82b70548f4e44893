"""What every shape type provides (see pyclray/model/shapes/__init__.py).

A shape module owns everything about its shape, so that nothing outside pyclray/model/shapes/ asks which
type a shape is (pbrt-v4's Shape interface, Mitsuba's plugins):

- scene file: ``type``, ``keys``, ``required``, ``_from_table`` and the dataclass's validation;
- device: ``c_type``, ``struct`` and ``_pack`` (host work in float64, in the kernel's frame), and
  kernels/<type>.cl with ``<type>_hit`` and ``<type>_normal``;
- bounds: ``bounded`` and ``world_bounds`` (culling, the BVH), ``bounding_spheres``;
- the float64 oracle: ``oracle_distance``, ``oracle_normal``, ``surface_distance``,
  ``edge_distance`` (where a ray may go either way);
- the error model (pyclray.reference.error_model): ``anchor`` (the point its coordinates are measured from)
  and ``curvature_radius`` (how a position error turns the normal);
- Mitsuba 3 (pyclray.mitsuba): ``mitsuba_shapes`` (its counterpart, one or more Mitsuba shapes that
  all map back to this shape's id) and ``mitsuba_covers`` (where that counterpart ends).
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

    ``_pack(out, shapes, origin, rotation)`` must accept ``origin`` of shape (3,) (one frame for
    every shape: render) or (N, 3) (one frame per shape, each at its own anchor: cast).
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
    @classmethod
    def from_table(cls, table: dict, index: int):
        no_unknown_keys(table, ("type", "name", "label") + cls.keys + MATERIAL_KEYS, required=cls.required)
        name = text("name", table.get("name", f"{cls.type}{index}"))
        material = Material.from_table(table)
        label = check_label(table.get("label"))
        shape = cls._from_table({k: v for k, v in table.items() if k not in MATERIAL_KEYS and k != "label"}, name)
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
    @classmethod
    def pack(cls, shapes, ids, origin, rotation, precision: str) -> np.ndarray:
        """The packed array of these shapes in a frame: origin (world, float64) and rotation
        (rows: the frame's axes in world coordinates). What every ray from the frame's origin
        shares is computed here once, in float64, from the world coordinates."""
        out = np.zeros(len(shapes), dtype=layout(cls.struct, precision).dtype)
        out["id"] = ids
        if len(shapes):
            cls._pack(out, shapes, np.asarray(origin, np.float64), np.asarray(rotation, np.float64))
        return out

    @classmethod
    def _pack(cls, out, shapes, origin, rotation) -> None:
        raise NotImplementedError

    def lengths(self, eye) -> dict[str, float]:
        """Scene key -> the size of what the kernel computes from it in the camera's frame (e.g. a
        centre's distance from the eye, a radius), which the kernel may square: the range check
        (scene.check_renderable) refuses a scene whose lengths exceed the precision's range."""
        return {}



    # -- bounds --------------------------------------------------------------------------------
    @classmethod
    def world_bounds(cls, shapes) -> np.ndarray:
        """(N, 2, 3) float64: [lo, hi] of each shape, conservative (every point of the shape lies
        inside, whatever the rounding). Only for ``bounded`` types."""
        raise NotImplementedError(f"a {cls.type} has no bounds")

    @classmethod
    def bounding_spheres(cls, shapes) -> tuple[np.ndarray, np.ndarray]:
        """(centres (N, 3), radii (N,)) of spheres holding each shape: by default the spheres
        around the world bounds."""
        bounds = cls.world_bounds(shapes).reshape(-1, 2, 3)
        centre = 0.5 * (bounds[:, 0] + bounds[:, 1])
        return centre, 0.5 * np.linalg.norm(bounds[:, 1] - bounds[:, 0], axis=1) * (1 + 1e-12)

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

    def extent_from(self, point) -> float:
        """How far from ``point`` the shape reaches (for Mitsuba's clip range)."""
        bounds = self.world_bounds([self])[0]
        corners = np.array([[bounds[i][0], bounds[j][1], bounds[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        return float(np.linalg.norm(corners - np.asarray(point, np.float64), axis=1).max())

    # -- Mitsuba 3 -----------------------------------------------------------------------------
    def mitsuba_shapes(self, scene) -> list[dict]:
        """Mitsuba scene dicts of this shape's counterpart (one or more; they all map back to this
        shape's id). A ``to_world`` value is a 4x4 float64 numpy matrix (the bridge converts it)."""
        raise NotImplementedError

    def mitsuba_covers(self, scene, points) -> np.ndarray:
        """Whether Mitsuba's counterpart holds these points of the shape (False where a stand-in
        ends, such as the plane's disk)."""
        return np.ones(np.shape(points)[:-1], bool)


LABEL_MAX = 2**31 - 1  # labels are int32 in the label image


def check_label(value) -> int | None:
    """A shape's label: None (no label) or a whole number 0 <= label <= 2^31 - 1 (a SceneError at
    the key 'label' otherwise)."""
    return None if value is None else integer("label", value, minimum=0, maximum=LABEL_MAX)


def labels_of(shapes) -> np.ndarray:
    """(N,) int32: each shape's label, -1 for a shape without one."""
    return np.array([-1 if shape.label is None else shape.label for shape in shapes], np.int32).reshape(-1)


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


def pack_flat(out, center, normal, origin, rotation) -> None:
    """The fields a flat shape (disk, rectangle) packs alike: its centre and unit normal in the frame,
    the frame origin's signed distance to its plane (normal.w, from float64 with an exact dot), and
    its world normal, packed as is."""
    F = center - origin
    out["center"][:, :3] = F @ rotation.T
    out["normal"][:, :3] = normal @ rotation.T
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
