"""The infinite plane: the points p with normal . p + offset = 0."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError, norm3, number, vector3
from ..exact import dot2
from ..layout import Struct
from .base import Shape, space_columns, object_matrix, to_world
from .device import in_space, in_space_low
from .reference import exact_at_most, plain_closest, rational

# Mitsuba has no infinite plane: a disk of this many times the scene's extent stands in for it (a
# disk's error does not depend on its size; a rectangle's, two float32 triangles, does)
DISK_SCALE = 1e4


@dataclass(frozen=True)
class Plane(Shape):
    normal: tuple[float, float, float]
    offset: float = 0.0
    name: str = "plane"

    type = "plane"
    c_type = "Plane"
    bounded = False
    keys = ("normal", "offset", "point")
    required = ("normal",)
    struct = Struct(
        "Plane",
        (
            ("normal", "real4"),  # unit normal in the space; w: signed distance of the space origin
            ("normal_low", "real4"),  # the rest of the space normal, rounded (n = normal + normal_low: fp32 camera rays)
            ("world_normal", "real4"),  # unit normal in world space (the normal image's value)
            ("id", "int"),
            ("primitive", "int"),  # 0
            ("exact", "ulong4"),  # unit normal and offset in world space, the bits of float64 numbers
        ),
        "Plane n.p + h = 0: normal.xyz = n in the space, normal.w = h at the space's origin.",
    )
    world = Struct(
        "PlaneWorld",
        (
            ("normal", "double4"),  # unit normal; w: the offset h (n.p + h = 0)
        ),
        "A plane in world coordinates: n.p + h = 0 with normal.xyz = n (unit), normal.w = h.",
    )
    kernel_files = ("plane.cl",)
    flat_camera_depth = True  # its camera rays' n . d is error-free (ReferenceShape.flat_camera_depth)
    inside_test = True  # its inside: <type>_inside (the closest-point query)

    def object_pose(self) -> np.ndarray:
        """The plane's own space: the point nearest the world's origin at 0, z along its normal."""
        n = np.asarray(self.normal, np.float64)
        length = np.linalg.norm(n)
        return object_matrix(space_columns(n / length), -self.offset * n / length**2)

    def __post_init__(self):
        normal = vector3("normal", self.normal)
        if norm3(normal) == 0:
            raise SceneError("expected a non-zero normal vector, got [0, 0, 0]", key="normal")
        object.__setattr__(self, "normal", normal)
        object.__setattr__(self, "offset", number("offset", self.offset))

    @classmethod
    def through(cls, point, normal, name: str = "plane") -> "Plane":
        """The plane with this normal through this point."""
        normal = vector3("normal", normal)
        point = vector3("point", point)
        cls(normal, 0.0, name)  # the normal's own checks come first
        with np.errstate(over="ignore", invalid="ignore"):
            offset = -float(dot2(np.array(normal), np.array(point)))
            if not math.isfinite(offset):
                # beyond float64 (or beyond the ~1e292 where error-free products overflow in their
                # splitting): the same plane with a unit normal (normal and offset scale together),
                # and if even that overflows, an error rather than an inf offset
                length = norm3(normal)
                normal = tuple(component / length for component in normal)
                offset = -float(dot2(np.array(normal), np.array(point)))
                if not math.isfinite(offset):
                    offset = -float(np.dot(normal, point))
        if not math.isfinite(offset):
            raise SceneError("expected normal . point within the range of float64, got an overflow", key="point")
        return cls(normal, offset, name)

    @classmethod
    def _from_table(cls, table, name):
        if ("offset" in table) == ("point" in table):
            raise SceneError(
                "expected exactly one of 'offset' or 'point', got "
                + ("both" if "offset" in table else "neither"),
                key="offset",
            )
        if "point" in table:
            return cls.through(table["point"], table["normal"], name)
        return cls(table["normal"], table["offset"], name)

    def unit(self) -> tuple[np.ndarray, float]:
        """(n, h): unit normal and offset scaled together, in float64."""
        length = norm3(self.normal)
        return np.array(self.normal) / length, self.offset / length

    @classmethod
    def world_within(cls, world, eye, limit: float) -> bool:
        with np.errstate(over="ignore", invalid="ignore"):  # the eye's distance to each plane
            return bool(np.all(np.abs(world["normal"][:, :3] @ np.asarray(eye, np.float64) + world["normal"][:, 3]) <= limit))

    def lengths(self, eye) -> dict[str, float]:
        n, h = self.unit()
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is an inf, which the range check refuses
            return {"offset": abs(float(np.dot(n, eye) + h))}  # the eye's distance to the plane

    @classmethod
    def _pack_world(cls, out, planes):
        out["normal"][:, :3] = [p.unit()[0] for p in planes]
        out["normal"][:, 3] = [p.unit()[1] for p in planes]

    @classmethod
    def _rebase(cls, out, world, origin, rotation):
        n_h = world["normal"]
        n = n_h[:, :3]
        # signed distance of the space origin: n . origin + h, compensated (a far origin cancels)
        origin_1 = np.concatenate([np.broadcast_to(origin, n.shape), np.ones((len(n), 1))], axis=1)
        out["normal"][:, :3] = in_space(n, rotation)
        out["normal_low"][:, :3] = in_space_low(n, rotation, out["normal"][:, :3])
        out["normal"][:, 3] = dot2(n_h, origin_1)
        out["world_normal"][:, :3] = n
        out["exact"] = np.ascontiguousarray(n_h).view(np.uint64)

    # -- float64 oracle ----------------------------------------------------------------------
    def oracle_distance(self, origins, directions):
        """Distance t > 0 along unit directions to the plane, inf where there is none."""
        n, h = self.unit()
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -(origins @ n + h) / (directions @ n)
        return np.where(t > 0, t, np.inf)

    def oracle_normal(self, points):
        n, _ = self.unit()
        return np.broadcast_to(n, points.shape)

    @classmethod
    def random(cls, rng, shift=0.0):
        """A random instance near ``shift`` (for the generic property tests, tests/test_shapes.py)."""
        normal = rng.normal(size=3) * 10 ** rng.uniform(-1, 1)
        return cls(tuple(normal), float(-normal @ np.broadcast_to(shift, 3) + rng.uniform(-2, 2) * np.linalg.norm(normal)))

    def surface_distance(self, points):
        n, h = self.unit()
        return np.abs(np.asarray(points, np.float64) @ n + h)


    def oracle_closest(self, points):
        points = np.asarray(points, np.float64)
        n, h = self.unit()
        s = points @ n + h
        out = plain_closest(points, points - s[:, None] * n, n)
        return out[:4] + (np.abs(s),)

    def oracle_inside(self, points, sign="parity"):
        """The half-space behind it: normal . p + offset <= 0."""
        points = np.asarray(points, np.float64)
        normal = np.array(self.normal)
        value = points @ normal + self.offset
        size = np.abs(points) @ np.abs(normal) + abs(self.offset)
        exact = lambda i: sum(a * b for a, b in zip(rational(points[i]), rational(normal))) + rational([self.offset])[0]
        return exact_at_most(value, size, exact)

    # -- the error model -----------------------------------------------------------------------
    def foot(self, point) -> np.ndarray:
        """The point of the plane nearest to ``point``."""
        n, h = self.unit()
        point = np.asarray(point, np.float64)
        return point - (point @ n + h) * n

    def anchor(self, point):
        """The foot of the point on the plane: the kernel's offset h is measured from the space's
        origin, Mitsuba's disk is centred at the eye's foot."""
        return self.foot(point)

    def extent_from(self, point) -> float:
        return float(self.surface_distance(np.asarray(point, np.float64)[None])[0])

    # -- Mitsuba 3 -----------------------------------------------------------------------------
    def mitsuba_disk(self, scene):
        """(centre, space columns (t1, t2, n), radius) of the disk standing in for the plane:
        centred at the eye's foot, DISK_SCALE times the scene's extent."""
        n, _ = self.unit()
        return self.foot(scene.camera.eye), space_columns(n), DISK_SCALE * scene.extent()

    def mitsuba_shapes(self, scene):
        centre, (t1, t2, n), radius = self.mitsuba_disk(scene)
        return [{"type": "disk", "to_world": to_world((t1 * radius, t2 * radius, n * radius), centre)}]

    def mitsuba_covers(self, scene, points):
        """Within the stand-in disk; beyond its edge (near the horizon) Mitsuba sees nothing."""
        centre, _, radius = self.mitsuba_disk(scene)
        return np.linalg.norm(np.asarray(points) - centre, axis=-1) <= radius * (1 - 1e-6)
