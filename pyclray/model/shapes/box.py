"""The box: a solid of edge lengths ``size`` along its own axes, the world's axes rotated by
``angle`` degrees about ``axis`` (right-handed), centred at ``center``."""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from ..errors import SceneError, vector3
from ..exact import dot2
from ..layout import Struct
from .base import Shape, to_world, distance
from .device import in_space, in_space_low, padded_bounds
from .rotations import axis_angle, rotation, rotation_axis_angle
from .reference import exact_at_most, plain_closest, rational


@dataclass(frozen=True)
class Box(Shape):
    center: tuple[float, float, float]
    size: tuple[float, float, float]
    axis: tuple[float, float, float] | None = None
    angle: float = 0.0
    name: str = "box"

    type = "box"
    c_type = "Box"
    keys = ("center", "size", "axis", "angle")
    required = ("center", "size")
    solid = True
    struct = Struct(
        "Box",
        (
            ("axis0", "real4"),  # the box's first axis in the space; w: its slab's low offset
            ("axis1", "real4"),
            ("axis2", "real4"),
            ("high", "real4"),  # the three slabs' high offsets
            ("center", "real4"),  # the centre in the space; w unused
            ("half_size", "real4"),  # half the edge lengths
            ("axis_low0", "real4"),  # the rest of each space axis, rounded (axis = axisK + axis_lowK: fp32 camera rays)
            ("axis_low1", "real4"),
            ("axis_low2", "real4"),
            ("world_axis0", "real4"),  # the box's axes in world space (the faces' normals)
            ("world_axis1", "real4"),
            ("world_axis2", "real4"),
            ("id", "int"),
            ("primitive", "int"),  # 0
        ),
        "Box: a ray o + s D is inside slab k where lo_k <= s (D . axis_k) <= hi_k, lo_k and hi_k = "
        "(center - o) . axis_k -+ size_k / 2, exact for the space origin; center and half for the "
        "slab test from the ray's point nearest the centre.",
    )
    world = Struct(
        "BoxWorld",
        (
            ("center", "double4"),
            ("half_size", "double4"),  # half the edge lengths
            ("axis0", "double4"),  # the box's unit axes in world space
            ("axis1", "double4"),
            ("axis2", "double4"),
        ),
        "A box in world coordinates: centre, half sizes and its three unit axes.",
    )
    kernel_files = ("box.cl",)
    flat_camera_depth = True  # its camera rays' n . d is error-free (ReferenceShape.flat_camera_depth)
    inside_test = True  # its inside: <type>_inside (the closest-point query)

    def object_pose(self) -> np.ndarray:
        """The box's own space: its centre at 0, its edges along the axes (its rotation's columns)."""
        out = np.eye(4)
        out[:3, :3] = rotation(self.axis, self.angle)
        out[:3, 3] = self.center
        return out

    def __post_init__(self):
        object.__setattr__(self, "center", vector3("center", self.center))
        size = vector3("size", self.size)
        if not all(s > 0 for s in size):
            raise SceneError(f"expected three numbers > 0, got {list(size)}", key="size")
        object.__setattr__(self, "size", size)
        axis, angle = axis_angle(self.axis, self.angle)
        object.__setattr__(self, "axis", axis)
        object.__setattr__(self, "angle", angle)

    @classmethod
    def _from_table(cls, table, name):
        return cls(table["center"], table["size"], table.get("axis"), table.get("angle", 0.0), name)

    def lengths(self, eye) -> dict[str, float]:
        return {"center": distance(self.center, eye), "size": distance(self.size, 0.0)}

    @classmethod
    def random(cls, rng, shift=0.0):
        """A random instance near ``shift`` (for the generic property tests, tests/test_shapes.py):
        axis-aligned one time in four, else rotated."""
        size = tuple(10 ** rng.uniform(-1, 0.4, 3))
        centre = tuple(rng.uniform(-3, 3, 3) + shift)
        if rng.integers(0, 4) == 0:
            return cls(centre, size)
        return cls(centre, size, tuple(rng.normal(size=3)), float(rng.uniform(-180, 180)))

    def axes(self) -> np.ndarray:
        """world_from_box: the box's unit axes as columns, float64."""
        return rotation(self.axis, self.angle)

    def half(self) -> np.ndarray:
        return np.array(self.size) / 2

    @classmethod
    def _pack_world(cls, out, boxes):
        out["center"][:, :3] = [b.center for b in boxes]
        out["half_size"][:, :3] = [b.half() for b in boxes]
        axes = np.array([b.axes() for b in boxes]).reshape(-1, 3, 3)
        for axis in range(3):
            out[f"axis{axis}"][:, :3] = axes[:, :, axis]

    @classmethod
    def _rebase(cls, out, world, origin, rotation_rows):
        F = world["center"][:, :3] - origin
        half = world["half_size"][:, :3]
        out["center"][:, :3] = in_space(F, rotation_rows)
        out["half_size"][:, :3] = half
        for axis in range(3):
            e = world[f"axis{axis}"][:, :3]
            out[f"axis{axis}"][:, :3] = in_space(e, rotation_rows)
            out[f"axis_low{axis}"][:, :3] = in_space_low(e, rotation_rows, out[f"axis{axis}"][:, :3])
            out[f"world_axis{axis}"][:, :3] = e
            # the slab offsets (centre - origin) . e -+ h, without cancellation for an eye near a face
            ones = np.ones((len(e), 1))
            h = half[:, axis:axis + 1]
            out[f"axis{axis}"][:, 3] = dot2(np.concatenate([F, -h], axis=1), np.concatenate([e, ones], axis=1))
            out["high"][:, axis] = dot2(np.concatenate([F, h], axis=1), np.concatenate([e, ones], axis=1))

    # -- bounds --------------------------------------------------------------------------------
    @classmethod
    def bounds_of(cls, world):
        center = world["center"][:, :3]
        axes = np.stack([world[f"axis{k}"][:, :3] for k in range(3)], axis=2)  # columns: the axes
        reach = np.einsum("nij,nj->ni", np.abs(axes), world["half_size"][:, :3])
        return padded_bounds(center - reach, center + reach)

    # -- the float64 oracle --------------------------------------------------------------------
    def _slabs(self, origins, directions):
        """(entry, exit, entry axis, exit axis) of the slab test, as the kernel does it."""
        R = self.axes()
        F = (np.array(self.center) - origins) @ R  # the centre from the origin, in box coordinates
        D = directions @ R
        h = self.half()
        with np.errstate(divide="ignore", invalid="ignore"):
            t_low, t_high = (F - h) / D, (F + h) / D
        near, far = np.fmin(t_low, t_high), np.fmax(t_low, t_high)
        return near.max(axis=-1), far.min(axis=-1), near.argmax(axis=-1), far.argmin(axis=-1)

    def oracle_distance(self, origins, directions):
        entry, exit_, _, _ = self._slabs(origins, directions)
        t = np.where(entry > 0, entry, exit_)
        return np.where((entry <= exit_) & (t > 0) & np.isfinite(t), t, np.inf)

    def oracle_crossings(self, origins, directions):
        """The entry and the exit where the slabs overlap with entry < exit (a ray grazing an edge or
        a corner: none), each where t > 0."""
        entry, exit_, _, _ = self._slabs(origins, directions)
        t = np.stack([entry, exit_], axis=-1)
        t = np.where((entry < exit_)[..., None] & np.isfinite(t) & (t > 0), t, np.inf).reshape(-1, 2)
        return t, np.zeros(t.shape, np.int64)

    def _local(self, points):
        return (np.asarray(points, np.float64) - np.array(self.center)) @ self.axes()

    def oracle_normal(self, points):
        local = self._local(points)
        beyond = np.abs(local) - self.half()  # ~0 on the face hit, < 0 on the others
        face = beyond.argmax(axis=-1)
        sign = np.sign(np.take_along_axis(local, face[..., None], axis=-1))
        return sign * self.axes().T[face]

    def surface_distance(self, points):
        beyond = np.abs(self._local(points)) - self.half()
        outside = np.linalg.norm(np.maximum(beyond, 0), axis=-1)
        return np.abs(outside + np.minimum(beyond.max(axis=-1), 0))


    def oracle_closest(self, points):
        """Outside: each box coordinate clamped to the half sizes; inside: onto the nearest face. The
        normal: the face along which the point lies farthest beyond (least within) it, the lowest
        axis on a tie (as kernels/box.cl)."""
        points = np.asarray(points, np.float64)
        local, half = self._local(points), self.half()
        beyond = np.abs(local) - half
        face = beyond.argmax(axis=-1)
        rows = np.arange(len(points))
        sign = np.where(local[rows, face] < 0, -1.0, 1.0)
        inside = (beyond <= 0).all(axis=-1)
        q = np.clip(local, -half, half)
        q[rows[inside], face[inside]] = sign[inside] * half[face[inside]]
        axes = self.axes()
        position = np.array(self.center) + q @ axes.T
        normal = sign[:, None] * axes.T[face]
        distance = np.where(inside, -beyond[rows, face], np.linalg.norm(np.maximum(beyond, 0), axis=-1))
        out = plain_closest(points, position, normal)
        return out[:4] + (distance,)

    def oracle_inside(self, points, sign="parity"):
        """|(p - C) . e_k| <= h_k on each of its axes (float64: its axes are rounded already)."""
        points = np.asarray(points, np.float64)
        return (np.abs(self._local(points)) <= self.half()).all(axis=-1)

    def edge_distance(self, points):
        """For points on the surface: the distance to the nearest edge, where two of the three
        slab distances vanish."""
        beyond = np.sort(np.abs(np.abs(self._local(points)) - self.half()), axis=-1)
        return np.hypot(beyond[..., 0], beyond[..., 1])

    # -- the error model -----------------------------------------------------------------------
    def anchor(self, point):
        return np.array(self.center)

    # -- Mitsuba 3 -----------------------------------------------------------------------------
    mitsuba_plugins = ("cube",)

    @classmethod
    def from_mitsuba(cls, props, folder):
        """Mitsuba's cube is a 12-triangle mesh of [-1, 1]^3: a box where to_world keeps its faces
        square to each other and does not mirror it; under any other affine to_world (a shear, a
        mirror, which turns the mesh's triangles and so their normals inward) that very mesh
        (mesh_shapes.MITSUBA_CUBE), as Mitsuba renders it."""
        to_world = props.to_world()
        columns = to_world.columns()
        half = np.linalg.norm(columns, axis=1)
        gram = columns @ columns.T / np.outer(half, half)
        R = (columns / half[:, None]).T  # the box's unit axes as columns
        if np.abs(gram - np.eye(3)).max() > 1e-9 or np.linalg.det(R) < 0:
            from .mesh import Mesh
            from .mesh_shapes import MITSUBA_CUBE

            return partial(Mesh, *MITSUBA_CUBE, matrix=tuple(map(tuple, to_world.matrix.tolist())))
        axis, angle = rotation_axis_angle(R)
        return partial(cls, tuple(to_world.point(np.zeros(3))), tuple(2 * half), axis, angle)

    def mitsuba_shapes(self, scene):
        """Mitsuba's cube is [-1, 1]^3: columns the half edges along the box's axes."""
        R = self.axes()
        return [{"type": "cube", "to_world": to_world((R[:, k] * self.half()[k] for k in range(3)), self.center)}]
