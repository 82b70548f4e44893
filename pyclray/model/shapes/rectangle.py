"""The rectangle: the points center + a u + b v with |a| <= 1 and |b| <= 1 (u, v: half sides)."""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from ..errors import SceneError, norm3, vector3
from ..layout import Struct
from .base import Shape, distance, object_matrix, to_world, unit_rows
from .device import in_space, padded_bounds, rebase_flat
from .reference import flat_hits, exact_at_most, plain_closest, rational

# u and v count as orthogonal when |u.v| <= ORTHOGONAL |u| |v| (scene-format.md)
ORTHOGONAL = 1e-6


@dataclass(frozen=True)
class Rectangle(Shape):
    center: tuple[float, float, float]
    u: tuple[float, float, float]
    v: tuple[float, float, float]
    name: str = "rectangle"

    type = "rectangle"
    c_type = "Rectangle"
    keys = ("center", "u", "v")
    required = ("center", "u", "v")
    struct = Struct(
        "Rectangle",
        (
            ("center", "real4"),  # centre in the space
            ("normal", "real4"),  # unit normal in the space; w: n . (space origin - centre), exact
            ("normal_low", "real4"),  # the rest of the space normal, rounded (n = normal + normal_low: fp32 camera rays)
            ("u_dual", "real4"),  # (P - centre) . u_dual = a: the dual basis of (u, v) in the plane
            ("v_dual", "real4"),  # (P - centre) . v_dual = b
            ("world_normal", "real4"),  # normalize(u x v) in world space
            ("id", "int"),
            ("primitive", "int"),  # 0
        ),
        "Rectangle: hit where |a| <= 1 and |b| <= 1, a and b from the dual vectors of u and v.",
    )
    world = Struct(
        "RectangleWorld",
        (
            ("center", "double4"),
            ("normal", "double4"),  # normalize(u x v)
            ("u_dual", "double4"),
            ("v_dual", "double4"),
            ("u", "double4"),  # the half sides (for the bounds)
            ("v", "double4"),
        ),
        "A rectangle in world coordinates: centre, unit normal, the dual vectors of u and v, u and v.",
    )
    kernel_files = ("rectangle.cl",)
    flat_camera_depth = True  # its camera rays' n . d is error-free (ReferenceShape.flat_camera_depth)

    def object_pose(self) -> np.ndarray:
        """The rectangle's own pose: its centre at 0, x along u, y along v, z along u x v (unit
        axes: coordinates in scene units)."""
        u, v = np.asarray(self.u, np.float64), np.asarray(self.v, np.float64)
        x = u / np.linalg.norm(u)
        z = np.cross(u, v)
        z /= np.linalg.norm(z)
        return object_matrix([x, np.cross(z, x), z], self.center)

    def __post_init__(self):
        object.__setattr__(self, "center", vector3("center", self.center))
        for key in ("u", "v"):
            side = vector3(key, getattr(self, key))
            if norm3(side) == 0:
                raise SceneError(f"expected a non-zero half side, got [0, 0, 0]", key=key)
            object.__setattr__(self, key, side)
        u, v = np.array(self.u), np.array(self.v)
        if norm3(np.cross(u / norm3(u), v / norm3(v))) == 0:
            raise SceneError("expected v not parallel to u", key="v")
        cosine = abs((u / norm3(u)) @ (v / norm3(v)))  # of unit vectors: u . v may overflow float64
        if cosine > ORTHOGONAL:
            raise SceneError(f"expected v orthogonal to u (|u.v| <= {ORTHOGONAL:g} |u| |v|), got |u.v| = "
                             f"{cosine:.3g} |u| |v|", key="v")

    @classmethod
    def _from_table(cls, table, name):
        return cls(table["center"], table["u"], table["v"], name)

    def lengths(self, eye) -> dict[str, float]:
        return {"center": distance(self.center, eye), "u": distance(self.u, 0.0), "v": distance(self.v, 0.0)}

    @classmethod
    def random(cls, rng, shift=0.0):
        """A random instance near ``shift`` (for the generic property tests, tests/test_shapes.py)."""
        u = rng.normal(size=3)
        v = np.cross(u, rng.normal(size=3))
        u *= 10 ** rng.uniform(-1, 0.3) / np.linalg.norm(u)
        v *= 10 ** rng.uniform(-1, 0.3) / np.linalg.norm(v)
        return cls(tuple(rng.uniform(-3, 3, 3) + shift), tuple(u), tuple(v))

    def unit_normal(self) -> np.ndarray:
        return unit_rows(np.cross(self.u, self.v))

    def dual(self) -> tuple[np.ndarray, np.ndarray]:
        """(u*, v*): u*.u = v*.v = 1, u*.v = v*.u = 0, both in the plane (float64)."""
        u, v, n = np.array(self.u), np.array(self.v), self.unit_normal()
        vn, nu = np.cross(v, n), np.cross(n, u)
        return vn / (u @ vn), nu / (v @ nu)

    @classmethod
    def _pack_world(cls, out, rectangles):
        out["center"][:, :3] = [r.center for r in rectangles]
        out["normal"][:, :3] = [r.unit_normal() for r in rectangles]
        duals = [r.dual() for r in rectangles]
        out["u_dual"][:, :3] = [d[0] for d in duals]
        out["v_dual"][:, :3] = [d[1] for d in duals]
        out["u"][:, :3] = [r.u for r in rectangles]
        out["v"][:, :3] = [r.v for r in rectangles]

    @classmethod
    def _rebase(cls, out, world, origin, rotation):
        rebase_flat(out, world, origin, rotation)
        out["u_dual"][:, :3] = in_space(world["u_dual"][:, :3], rotation)
        out["v_dual"][:, :3] = in_space(world["v_dual"][:, :3], rotation)

    # -- bounds --------------------------------------------------------------------------------
    @classmethod
    def bounds_of(cls, world):
        center = world["center"][:, :3]
        reach = np.abs(world["u"][:, :3]) + np.abs(world["v"][:, :3])
        return padded_bounds(center - reach, center + reach)

    # -- the float64 oracle --------------------------------------------------------------------
    def _coordinates(self, points):
        """(height above the plane, a, b) of points."""
        P = np.asarray(points, np.float64) - np.array(self.center)
        u_dual, v_dual = self.dual()
        return P @ self.unit_normal(), P @ u_dual, P @ v_dual

    def oracle_distance(self, origins, directions):
        u_dual, v_dual = self.dual()
        return flat_hits(self.center, self.unit_normal(), origins, directions,
                         lambda P: (np.abs(P @ u_dual) <= 1) & (np.abs(P @ v_dual) <= 1))

    def oracle_normal(self, points):
        return np.broadcast_to(self.unit_normal(), np.shape(points))

    def _border(self, points):
        """(height, signed distances beyond the two pairs of sides, in scene units)."""
        height, a, b = self._coordinates(points)
        return height, (np.abs(a) - 1) * norm3(self.u), (np.abs(b) - 1) * norm3(self.v)

    def surface_distance(self, points):
        height, qa, qb = self._border(points)
        return np.hypot(height, np.hypot(np.maximum(qa, 0), np.maximum(qb, 0)))


    def oracle_closest(self, points):
        points = np.asarray(points, np.float64)
        _, a, b = self._coordinates(points)
        position = np.array(self.center) + np.clip(a, -1, 1)[:, None] * np.array(self.u) + np.clip(b, -1, 1)[:, None] * np.array(self.v)
        out = plain_closest(points, position, self.unit_normal())
        return out[:4] + (self.surface_distance(points),)

    def edge_distance(self, points):
        height, qa, qb = self._border(points)
        inside = (qa <= 0) & (qb <= 0)
        within = np.where(inside, np.minimum(-qa, -qb), np.hypot(np.maximum(qa, 0), np.maximum(qb, 0)))
        return np.hypot(height, within)

    # -- the error model -----------------------------------------------------------------------
    def anchor(self, point):
        return np.array(self.center)

    # -- Mitsuba 3 -----------------------------------------------------------------------------
    mitsuba_plugins = ("rectangle",)

    @classmethod
    def from_mitsuba(cls, props, folder):
        """Mitsuba's rectangle is [-1, 1]^2 in z = 0 (a 2-triangle mesh): centre, u and v are
        to_world's image of it where that keeps its corners square (a mirroring to_world swaps u and
        v, so that cross(u, v) stays along Mitsuba's normal); under any other affine to_world (a
        shear) a parallelogram, Mitsuba's two triangles (mesh_shapes.MITSUBA_RECTANGLE)."""
        to_world = props.to_world()
        center, u, v, normal = to_world.flat_axes()
        if abs(np.dot(u, v)) > ORTHOGONAL * np.linalg.norm(u) * np.linalg.norm(v):
            from .mesh import Mesh
            from .mesh_shapes import MITSUBA_RECTANGLE

            return partial(Mesh, *MITSUBA_RECTANGLE, matrix=tuple(map(tuple, to_world.matrix.tolist())))
        if np.dot(np.cross(u, v), normal) < 0:
            u, v = v, u
        return partial(cls, tuple(center), tuple(u), tuple(v))

    def mitsuba_shapes(self, scene):
        """Mitsuba's rectangle is [-1, 1]^2 in z = 0 with normal +z: columns u, v and the normal."""
        return [{"type": "rectangle", "to_world": to_world((self.u, self.v, self.unit_normal()), self.center)}]
