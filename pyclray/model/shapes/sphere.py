"""The sphere: the points p with |p - center| = radius."""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from ..errors import number, vector3
from ..exact import dot2
from ..layout import Struct
from .base import Shape, distance, object_matrix
from .device import in_space
from .reference import exact_at_most, plain_closest, rational


def eye_term(F, radius):
    """c = |F|^2 - r^2 (F: centre minus ray origin) from error-free products and sums: the eye's
    squared distance to the surface, without the cancellation of a plain float64 formula."""
    F_r = np.concatenate([F, np.broadcast_to(radius, F.shape[:-1])[..., None]], axis=-1)
    return dot2(F_r, F_r * np.array([1.0, 1.0, 1.0, -1.0]))


@dataclass(frozen=True)
class Sphere(Shape):
    center: tuple[float, float, float]
    radius: float
    name: str = "sphere"

    type = "sphere"
    c_type = "Sphere"
    solid = True
    keys = ("center", "radius")
    required = ("center", "radius")
    struct = Struct(
        "Sphere",
        (
            ("center", "real4"),  # centre in the space; w: radius squared
            ("c", "real"),  # |centre - space origin|^2 - radius^2, from float64 error-free sums
            ("id", "int"),
            ("primitive", "int"),  # its index in its batch (pyclray.Spheres), 0 for a Sphere
        ),
        "Sphere: center.xyz in the space, center.w = r^2, c = |center|^2 - r^2.",
    )
    world = Struct(
        "SphereWorld",
        (
            ("center", "double4"),  # world centre; w: radius
        ),
        "A sphere in world coordinates: center.xyz, center.w = radius.",
    )
    kernel_files = ("sphere.cl",)
    inside_test = True  # its inside: <type>_inside (the closest-point query)
    tested_from_world = True  # rebased on the eye where tested: no per-view copy (Shape.tested_from_world)

    def object_pose(self) -> np.ndarray:
        """The sphere's own space: its centre at 0, the world's axes."""
        return object_matrix(np.eye(3), self.center)

    def __post_init__(self):
        object.__setattr__(self, "center", vector3("center", self.center))
        object.__setattr__(self, "radius", number("radius", self.radius, positive=True))

    @classmethod
    def _from_table(cls, table, name):
        return cls(table["center"], table["radius"], name)

    def lengths(self, eye) -> dict[str, float]:
        return {"center": distance(self.center, eye), "radius": self.radius}

    @classmethod
    def _pack_world(cls, out, spheres):
        out["center"][:, :3] = [s.center for s in spheres]
        out["center"][:, 3] = [s.radius for s in spheres]

    @classmethod
    def _rebase(cls, out, world, origin, rotation):
        center, radius = world["center"][:, :3], world["center"][:, 3]
        F = center - origin
        out["center"][:, :3] = in_space(F, rotation)
        out["center"][:, 3] = radius * radius
        out["c"] = eye_term(F, radius)

    # -- float64 oracle ----------------------------------------------------------------------
    def oracle_distance(self, origins, directions):
        """Distance t > 0 along unit directions to the nearest crossing, inf where there is none."""
        C = np.array(self.center)
        r = self.radius
        F = C - origins  # origin to centre
        b = np.einsum("...k,...k", F, directions)
        c = eye_term(F, r)  # |F|^2 - r^2 without cancellation
        perp = F - b[..., None] * directions  # from the ray's closest point to the centre
        perp2 = np.einsum("...k,...k", perp, perp)
        # the better conditioned of b^2 - c and r^2 - |perp|^2 (equal in exact arithmetic)
        disc = np.where(b * b + np.abs(c) < r * r + perp2, b * b - c, r * r - perp2)
        with np.errstate(invalid="ignore", divide="ignore"):
            q = b + np.copysign(np.sqrt(disc), b)
            roots = np.stack([q, c / q])
        roots = np.where(np.isfinite(roots) & (roots > 0), roots, np.inf)
        return np.where(disc >= 0, roots.min(axis=0), np.inf)

    def oracle_crossings(self, origins, directions):
        """Both roots t > 0 where the ray crosses the sphere (disc > 0); a tangent ray (disc = 0) none."""
        C = np.array(self.center)
        r = self.radius
        F = C - np.asarray(origins, np.float64)
        b = np.einsum("...k,...k", F, directions)
        c = eye_term(F, r)
        perp = F - b[..., None] * directions
        perp2 = np.einsum("...k,...k", perp, perp)
        disc = np.where(b * b + np.abs(c) < r * r + perp2, b * b - c, r * r - perp2)
        with np.errstate(invalid="ignore", divide="ignore"):
            q = b + np.copysign(np.sqrt(disc), b)
            roots = np.sort(np.stack([q, c / q], axis=-1), axis=-1)
        t = np.where((disc > 0)[..., None] & np.isfinite(roots) & (roots > 0), roots, np.inf).reshape(-1, 2)
        return t, np.zeros(t.shape, np.int64)

    def oracle_normal(self, points):
        n = points - np.array(self.center)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    @classmethod
    def random(cls, rng, shift=0.0):
        """A random instance near ``shift`` (for the generic property tests, tests/test_shapes.py)."""
        return cls(tuple(rng.uniform(-3, 3, 3) + shift), float(10 ** rng.uniform(-1.3, 0.5)))

    def surface_distance(self, points):
        return np.abs(np.linalg.norm(np.asarray(points, np.float64) - np.array(self.center), axis=-1) - self.radius)


    def oracle_closest(self, points):
        points = np.asarray(points, np.float64)
        F = points - np.array(self.center)
        length = np.linalg.norm(F, axis=-1)
        n = np.where(length[:, None] > 0, F / np.where(length > 0, length, 1.0)[:, None], [0.0, 0.0, 1.0])
        out = plain_closest(points, np.array(self.center) + self.radius * n, n)
        return out[:4] + (np.abs(length - self.radius),)

    def oracle_inside(self, points, sign="parity"):
        """|p - C|^2 <= r^2."""
        points = np.asarray(points, np.float64)
        F = points - np.array(self.center)
        value = (F * F).sum(axis=-1) - self.radius ** 2
        size = (F * F).sum(axis=-1) + self.radius ** 2

        def exact(i):
            c, r = rational(self.center), rational([self.radius])[0]
            return sum((p - q) ** 2 for p, q in zip(rational(points[i]), c)) - r * r

        return exact_at_most(value, size, exact)

    # -- bounds --------------------------------------------------------------------------------
    @classmethod
    def bounds_of(cls, world):
        centre, radius = cls.spheres_of(world)
        return np.stack([centre - radius[:, None], centre + radius[:, None]], axis=1)

    @classmethod
    def spheres_of(cls, world):
        # rounding of lo = c - r: one float64 ulp, widened
        return world["center"][:, :3].reshape(-1, 3), world["center"][:, 3] * (1 + 1e-12)

    # -- the error model -----------------------------------------------------------------------
    def anchor(self, point):
        return np.array(self.center)

    def curvature_radius(self) -> float:
        return self.radius

    def extent_from(self, point) -> float:
        return float(np.linalg.norm(np.subtract(self.center, point))) + self.radius

    # -- Mitsuba 3 -----------------------------------------------------------------------------
    mitsuba_plugins = ("sphere",)

    @classmethod
    def from_mitsuba(cls, props, folder):
        """Mitsuba's sphere: center and radius, placed by a to_world that keeps it a sphere."""
        center = props.take("center", "point", np.zeros(3))
        radius = props.take("radius", "float", 1.0)
        to_world = props.to_world()
        scale = to_world.similarity(props.element, "a sphere stays a sphere")
        return partial(cls, tuple(to_world.point(center)), radius * scale)

    def mitsuba_shapes(self, scene):
        return [{"type": "sphere", "center": list(self.center), "radius": self.radius}]
