"""The disk: the points p with normal . (p - center) = 0 and |p - center| <= radius."""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from ..errors import SceneError, norm3, number, vector3
from ..layout import Struct
from .base import Shape, distance, space_columns, object_matrix, to_world, unit_rows
from .device import padded_bounds, rebase_flat
from .reference import dot_rows, flat_hits, exact_at_most, plain_closest, rational


@dataclass(frozen=True)
class Disk(Shape):
    center: tuple[float, float, float]
    normal: tuple[float, float, float]
    radius: float
    name: str = "disk"

    type = "disk"
    c_type = "Disk"
    keys = ("center", "normal", "radius")
    required = ("center", "normal", "radius")
    struct = Struct(
        "Disk",
        (
            ("center", "real4"),  # centre in the space; w: radius squared
            ("normal", "real4"),  # unit normal in the space; w: n . (space origin - centre), exact
            ("normal_low", "real4"),  # the rest of the space normal, rounded (n = normal + normal_low: fp32 camera rays)
            ("world_normal", "real4"),  # unit normal in world space (the normal image's value)
            ("id", "int"),
            ("primitive", "int"),  # 0
        ),
        "Disk: center.xyz, center.w = r^2; normal.xyz = n, normal.w = h = n.(origin - center).",
    )
    world = Struct(
        "DiskWorld",
        (
            ("center", "double4"),  # w: radius
            ("normal", "double4"),  # unit normal
        ),
        "A disk in world coordinates: center.xyz, center.w = radius, normal.xyz unit.",
    )
    kernel_files = ("disk.cl",)
    flat_camera_depth = True  # its camera rays' n . d is error-free (ReferenceShape.flat_camera_depth)

    def object_pose(self) -> np.ndarray:
        """The disk's own pose: its centre at 0, z along its normal (x, y: space_columns')."""
        return object_matrix(space_columns(self.unit_normal()), self.center)

    def __post_init__(self):
        object.__setattr__(self, "center", vector3("center", self.center))
        normal = vector3("normal", self.normal)
        if norm3(normal) == 0:
            raise SceneError("expected a non-zero normal vector, got [0, 0, 0]", key="normal")
        object.__setattr__(self, "normal", normal)
        object.__setattr__(self, "radius", number("radius", self.radius, positive=True))

    @classmethod
    def _from_table(cls, table, name):
        return cls(table["center"], table["normal"], table["radius"], name)

    def lengths(self, eye) -> dict[str, float]:
        return {"center": distance(self.center, eye), "radius": self.radius}

    @classmethod
    def random(cls, rng, shift=0.0):
        """A random instance near ``shift`` (for the generic property tests, tests/test_shapes.py)."""
        return cls(tuple(rng.uniform(-3, 3, 3) + shift), tuple(rng.normal(size=3)), float(10 ** rng.uniform(-1, 0.5)))

    def unit_normal(self) -> np.ndarray:
        return unit_rows(self.normal)

    @classmethod
    def _pack_world(cls, out, disks):
        out["center"][:, :3] = [d.center for d in disks]
        out["center"][:, 3] = [d.radius for d in disks]
        out["normal"][:, :3] = [d.unit_normal() for d in disks]

    @classmethod
    def _rebase(cls, out, world, origin, rotation):
        rebase_flat(out, world, origin, rotation)
        out["center"][:, 3] = world["center"][:, 3] ** 2

    # -- bounds --------------------------------------------------------------------------------
    @classmethod
    def bounds_of(cls, world):
        center, radius, n = world["center"][:, :3], world["center"][:, 3], world["normal"][:, :3]
        # a circle of radius r around n reaches r sqrt(1 - n_k^2) along axis k
        reach = radius[:, None] * np.sqrt(np.clip(1 - n * n, 0, 1))
        return padded_bounds(center - reach, center + reach)

    # -- the float64 oracle --------------------------------------------------------------------
    def oracle_distance(self, origins, directions):
        return flat_hits(self.center, self.unit_normal(), origins, directions,
                         lambda P: dot_rows(P, P) <= self.radius**2)

    def oracle_normal(self, points):
        return np.broadcast_to(self.unit_normal(), np.shape(points))

    def _plane_coordinates(self, points):
        """(distance from the disk's plane, distance from the centre within the plane)."""
        P = np.asarray(points, np.float64) - np.array(self.center)
        height = P @ self.unit_normal()
        return height, np.linalg.norm(P - height[..., None] * self.unit_normal(), axis=-1)

    def surface_distance(self, points):
        height, rho = self._plane_coordinates(points)
        return np.hypot(height, np.maximum(rho - self.radius, 0.0))


    def oracle_closest(self, points):
        points = np.asarray(points, np.float64)
        n = self.unit_normal()
        P = points - np.array(self.center)
        height = P @ n
        rho_vector = P - height[:, None] * n
        rho = np.linalg.norm(rho_vector, axis=-1)
        scale = np.where(rho > self.radius, self.radius / np.where(rho > 0, rho, 1.0), 1.0)
        out = plain_closest(points, np.array(self.center) + scale[:, None] * rho_vector, n)
        return out[:4] + (self.surface_distance(points),)

    def edge_distance(self, points):
        height, rho = self._plane_coordinates(points)
        return np.hypot(height, rho - self.radius)

    # -- the error model -----------------------------------------------------------------------
    def anchor(self, point):
        return np.array(self.center)

    # -- Mitsuba 3 -----------------------------------------------------------------------------
    mitsuba_plugins = ("disk",)

    @classmethod
    def from_mitsuba(cls, props, folder):
        """Mitsuba's disk is the unit disk in z = 0: to_world must keep it round."""
        center, u, v, normal = props.to_world().flat_axes()
        ru, rv = np.linalg.norm(u), np.linalg.norm(v)
        if abs(np.dot(u, v)) > 1e-9 * ru * rv or abs(ru - rv) > 1e-9 * max(ru, rv):
            raise props.element.error("to_world turns the disk into an ellipse: pyclray's disks are round")
        return partial(cls, tuple(center), tuple(normal), float(0.5 * (ru + rv)))

    def mitsuba_shapes(self, scene):
        t1, t2, n = space_columns(self.unit_normal())
        r = self.radius
        return [{"type": "disk", "to_world": to_world((t1 * r, t2 * r, n * r), self.center)}]
