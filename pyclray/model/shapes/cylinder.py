"""The cylinder: the points within radius of the segment p0-p1, a solid closed by two caps
(caps = true, the default), or the open tube without them (caps = false, as Mitsuba's cylinder)."""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from ..errors import SceneError, number, vector3
from ..exact import cross_norm2_minus, dot2
from ..layout import Struct
from .base import Shape, distance, flag, space_columns, object_matrix, to_world
from .device import in_space, in_space_low, padded_bounds
from .reference import dot_rows, exact_at_most, plain_closest, rational


@dataclass(frozen=True)
class Cylinder(Shape):
    p0: tuple[float, float, float]
    p1: tuple[float, float, float]
    radius: float
    caps: bool = True
    name: str = "cylinder"

    type = "cylinder"
    c_type = "Cylinder"
    keys = ("p0", "p1", "radius", "caps")
    required = ("p0", "p1", "radius")
    struct = Struct(
        "Cylinder",
        (
            ("p0", "real4"),  # centre of one end in the space; w: radius squared
            ("p1", "real4"),  # centre of the other end in the space; w: the length |p1 - p0|
            ("axis", "real4"),  # unit axis (p1 - p0) / length in the space; w: c, see below
            ("axis_low", "real4"),  # the rest of the space axis, rounded (axis + axis_low: fp32 camera rays' D . A)
            ("world_axis", "real4"),  # the unit axis in world space (the caps' normals); w: d0
            ("d1", "real"),  # (p1 - space origin) . axis
            ("caps", "int"),  # 1: closed by its two caps (a solid), 0: an open tube
            ("id", "int"),
            ("primitive", "int"),  # 0
        ),
        "Cylinder: for rays from the space origin, c = |(p0 - o) x axis|^2 - r^2 (the eye's squared "
        "distance from the axis minus r^2) and d0, d1 = (p0 - o).axis, (p1 - o).axis, exact.",
    )
    world = Struct(
        "CylinderWorld",
        (
            ("p0", "double4"),  # w: radius
            ("p1", "double4"),  # w: length |p1 - p0|
            ("axis", "double4"),  # unit axis (p1 - p0) / length
            ("caps", "int"),
        ),
        "A cylinder in world coordinates: p0.w = radius, p1.w = length, unit axis.",
    )
    kernel_files = ("cylinder.cl",)
    inside_test = True  # its inside: <type>_inside (the closest-point query)

    def object_pose(self) -> np.ndarray:
        """The cylinder's own pose: p0 at 0, z along p1 - p0 (x, y: space_columns')."""
        axis = np.subtract(self.p1, self.p0, dtype=np.float64)
        return object_matrix(space_columns(axis / np.linalg.norm(axis)), self.p0)

    def __post_init__(self):
        object.__setattr__(self, "p0", vector3("p0", self.p0))
        object.__setattr__(self, "p1", vector3("p1", self.p1))
        if self.p0 == self.p1:
            raise SceneError("expected p1 != p0 (the axis is undefined)", key="p1")
        object.__setattr__(self, "radius", number("radius", self.radius, positive=True))
        object.__setattr__(self, "caps", flag("caps", self.caps))

    @classmethod
    def _from_table(cls, table, name):
        return cls(table["p0"], table["p1"], table["radius"], table.get("caps", True), name)

    def lengths(self, eye) -> dict[str, float]:
        return {"p0": distance(self.p0, eye), "p1": distance(self.p1, eye), "radius": self.radius}

    @classmethod
    def random(cls, rng, shift=0.0):
        """A random instance near ``shift`` (for the generic property tests, tests/test_shapes.py):
        short and fat to long and thin, capped or open."""
        p0 = rng.uniform(-3, 3, 3) + shift
        return cls(tuple(p0), tuple(p0 + rng.normal(size=3) * 10 ** rng.uniform(-0.7, 0.5)),
                   float(10 ** rng.uniform(-1.3, 0.2)), bool(rng.integers(0, 4) > 0))

    @property
    def solid(self) -> bool:
        return self.caps

    def axis(self) -> tuple[np.ndarray, float]:
        """(unit axis from p0 to p1, length), float64."""
        d = np.subtract(self.p1, self.p0)
        length = float(np.linalg.norm(d))
        return d / length, length

    @classmethod
    def _pack_world(cls, out, cylinders):
        axes = [c.axis() for c in cylinders]
        out["p0"][:, :3] = [c.p0 for c in cylinders]
        out["p0"][:, 3] = [c.radius for c in cylinders]
        out["p1"][:, :3] = [c.p1 for c in cylinders]
        out["p1"][:, 3] = [length for _, length in axes]
        out["axis"][:, :3] = [a for a, _ in axes]
        out["caps"] = [int(c.caps) for c in cylinders]

    @classmethod
    def _rebase(cls, out, world, origin, rotation):
        p0 = world["p0"][:, :3] - origin
        p1 = world["p1"][:, :3] - origin
        A = world["axis"][:, :3]
        radius = world["p0"][:, 3]
        out["p0"][:, :3] = in_space(p0, rotation)
        out["p0"][:, 3] = radius * radius
        out["p1"][:, :3] = in_space(p1, rotation)
        out["p1"][:, 3] = world["p1"][:, 3]
        out["axis"][:, :3] = in_space(A, rotation)
        out["axis_low"][:, :3] = in_space_low(A, rotation, out["axis"][:, :3])
        # what every ray from the space origin shares, from error-free products and sums
        out["axis"][:, 3] = cross_norm2_minus(p0, A, radius)
        out["world_axis"][:, :3] = A
        out["world_axis"][:, 3] = dot2(p0, A)
        out["d1"] = dot2(p1, A)
        out["caps"] = world["caps"]

    # -- bounds --------------------------------------------------------------------------------
    @classmethod
    def bounds_of(cls, world):
        p0, p1, A = world["p0"][:, :3], world["p1"][:, :3], world["axis"][:, :3]
        # each end's circle of radius r around the axis reaches r sqrt(1 - A_k^2) along axis k
        reach = world["p0"][:, 3][:, None] * np.sqrt(np.clip(1 - A * A, 0, 1))
        return padded_bounds(np.minimum(p0, p1) - reach, np.maximum(p0, p1) + reach)

    # -- the float64 oracle --------------------------------------------------------------------
    def _candidates(self, origins, directions):
        """The four candidate distances (side near, side far, cap p0, cap p1) of each ray and which
        are hits (on the surface, t > 0), in the same terms as the kernel."""
        A, _ = self.axis()
        r = self.radius
        F = np.array(self.p0) - origins  # from the ray's origin to p0
        FxA = np.cross(F, A)
        DxA = np.cross(directions, A)
        a = dot_rows(DxA, DxA)  # |D_perp|^2
        b = dot_rows(FxA, DxA)  # F_perp . D_perp
        c = cross_norm2_minus(F, np.broadcast_to(A, F.shape), r)  # |F_perp|^2 - r^2
        triple = dot_rows(F, DxA)  # |F_perp x D_perp| (signed)
        # the better conditioned of b^2 - a c and a r^2 - |F_perp x D_perp|^2 (equal in exact arithmetic)
        disc = np.where(b * b + np.abs(a * c) < a * r * r + triple * triple, b * b - a * c, a * r * r - triple * triple)
        d0 = dot_rows(F, A)
        d1 = dot_rows(np.array(self.p1) - origins, A)
        dA = directions @ A
        with np.errstate(invalid="ignore", divide="ignore"):
            q = b + np.copysign(np.sqrt(disc), b)
            roots = np.sort(np.stack([q / a, c / q]), axis=0)
            caps = np.stack([d0 / dA, d1 / dA])
            side_ok = (disc >= 0) & (d0 <= roots * dA) & (roots * dA <= d1)
            radial = caps[..., None] * DxA - FxA
            cap_ok = self.caps & (dot_rows(radial, radial) <= r * r)
        t = np.concatenate([roots, caps])
        ok = np.concatenate([side_ok, cap_ok]) & (t > 0) & np.isfinite(t)
        return np.where(ok, t, np.inf)

    def oracle_distance(self, origins, directions):
        return self._candidates(origins, directions).min(axis=0)

    def oracle_crossings(self, origins, directions):
        """Capped (a convex solid): the entry and exit of the overlap of the side's interval (between
        its roots; a ray along the axis: all of it inside, none outside) and the end planes' (between
        them; parallel to them: all of it or none), where entry < exit. An open tube: each side root
        between the end planes where the ray crosses the side (disc > 0). Each where t > 0."""
        A, _ = self.axis()
        r = self.radius
        origins = np.asarray(origins, np.float64)
        F = np.array(self.p0) - origins
        FxA = np.cross(F, A)
        DxA = np.cross(directions, A)
        a = dot_rows(DxA, DxA)
        b = dot_rows(FxA, DxA)
        c = cross_norm2_minus(F, np.broadcast_to(A, F.shape), r)
        triple = dot_rows(F, DxA)
        disc = np.where(b * b + np.abs(a * c) < a * r * r + triple * triple, b * b - a * c, a * r * r - triple * triple)
        d0 = dot_rows(F, A)
        d1 = dot_rows(np.array(self.p1) - origins, A)
        dA = directions @ A
        with np.errstate(invalid="ignore", divide="ignore"):
            q = b + np.copysign(np.sqrt(disc), b)
            roots = np.sort(np.stack([q / a, c / q], axis=-1), axis=-1)
            ends = np.sort(np.stack([d0 / dA, d1 / dA], axis=-1), axis=-1)
        if self.caps:
            along = a == 0
            inside = np.where(c < 0, 1.0, -1.0) * np.inf
            side_lo = np.where(along, -inside, roots[..., 0])
            side_hi = np.where(along, inside, roots[..., 1])
            between = np.where((d0 <= 0) & (d1 >= 0), 1.0, -1.0) * np.inf
            parallel = dA == 0
            end_lo = np.where(parallel, -between, ends[..., 0])
            end_hi = np.where(parallel, between, ends[..., 1])
            entry, exit_ = np.maximum(side_lo, end_lo), np.minimum(side_hi, end_hi)
            crosses = (along | (disc > 0)) & (entry < exit_)
            t = np.stack([entry, exit_], axis=-1)
            t = np.where(crosses[..., None] & np.isfinite(t) & (t > 0), t, np.inf)
        else:
            z = roots * dA[..., None]
            ok = (disc > 0)[..., None] & (a > 0)[..., None] & (d0[..., None] <= z) & (z <= d1[..., None])
            t = np.where(ok & np.isfinite(roots) & (roots > 0), roots, np.inf)
        t = t.reshape(-1, 2)
        return t, np.zeros(t.shape, np.int64)

    def _local(self, points):
        """(axial coordinate from p0, radial vector from the axis) of points."""
        A, _ = self.axis()
        P = np.asarray(points, np.float64) - np.array(self.p0)
        z = P @ A
        return z, P - z[..., None] * A

    def oracle_normal(self, points):
        A, length = self.axis()
        z, radial = self._local(points)
        rho = np.linalg.norm(radial, axis=-1)
        side = radial / np.where(rho > 0, rho, 1.0)[..., None]
        # a cap's point is nearer its end plane than the side (at the rim either is right)
        cap = self.caps & (np.minimum(np.abs(z), np.abs(z - length)) < np.abs(rho - self.radius))
        cap_normal = np.where((np.abs(z) < np.abs(z - length))[..., None], -A, A)
        return np.where(cap[..., None], cap_normal, side)

    def surface_distance(self, points):
        _, length = self.axis()
        z, radial = self._local(points)
        out_radial = np.linalg.norm(radial, axis=-1) - self.radius
        out_axial = np.abs(z - length / 2) - length / 2
        if self.caps:  # the solid's signed distance, made unsigned
            outside = np.hypot(np.maximum(out_radial, 0), np.maximum(out_axial, 0))
            return np.abs(outside + np.minimum(np.maximum(out_radial, out_axial), 0))
        return np.hypot(out_radial, np.maximum(out_axial, 0))


    def oracle_closest(self, points):
        """The nearest of the side's point and, capped, the two caps' (the side first on a tie)."""
        points = np.asarray(points, np.float64)
        A, length = self.axis()
        z, radial = self._local(points)
        rho = np.linalg.norm(radial, axis=-1)
        other = np.array([1.0, 0.0, 0.0]) if abs(A[0]) < 0.5 else np.array([0.0, 1.0, 0.0])
        spare = np.cross(A, other)
        spare /= np.linalg.norm(spare)
        out = np.where(rho[:, None] > 0, radial / np.where(rho > 0, rho, 1.0)[:, None], spare)
        p0, p1 = np.array(self.p0), np.array(self.p1)
        candidates = [(p0 + np.clip(z, 0, length)[:, None] * A + self.radius * out, out)]
        if self.caps:
            on_cap = np.minimum(rho, self.radius)[:, None] * out
            candidates += [(p0 + on_cap, np.broadcast_to(-A, points.shape)), (p1 + on_cap, np.broadcast_to(A, points.shape))]
        position, normal = candidates[0]
        best = np.linalg.norm(points - position, axis=-1)
        for q, n in candidates[1:]:
            d = np.linalg.norm(points - q, axis=-1)
            nearer = d < best
            position, normal, best = np.where(nearer[:, None], q, position), np.where(nearer[:, None], n, normal), np.minimum(d, best)
        result = plain_closest(points, position, normal)
        return result[:4] + (best,)

    def oracle_inside(self, points, sign="parity"):
        """Capped: 0 <= (p - p0).(p1 - p0) <= |p1 - p0|^2 and |(p - p0) x (p1 - p0)|^2 <= r^2 |p1 - p0|^2,
        exactly; an open tube has no inside."""
        points = np.asarray(points, np.float64)
        if not self.caps:
            return np.zeros(len(points), bool)
        p0, d = np.array(self.p0), np.subtract(self.p1, self.p0)
        P = points - p0
        along, dd = P @ d, d @ d
        cross = np.cross(P, d)
        radial = (cross * cross).sum(axis=-1) - self.radius ** 2 * dd
        size_a = np.abs(P) @ np.abs(d) + dd
        size_r = (np.abs(P) @ np.abs(d)) ** 2 + self.radius ** 2 * dd

        def parts(i):
            a, b, r = rational(points[i]), rational(self.p0), rational([self.radius])[0]
            e = [x - y for x, y in zip(rational(self.p1), b)]
            q = [x - y for x, y in zip(a, b)]
            c = [q[1] * e[2] - q[2] * e[1], q[2] * e[0] - q[0] * e[2], q[0] * e[1] - q[1] * e[0]]
            ee = sum(x * x for x in e)
            return sum(x * y for x, y in zip(q, e)), ee, sum(x * x for x in c) - r * r * ee

        low = exact_at_most(-along, size_a, lambda i: -parts(i)[0])
        high = exact_at_most(along - dd, size_a, lambda i: parts(i)[0] - parts(i)[1])
        within = exact_at_most(radial, size_r, lambda i: parts(i)[2])
        return low & high & within

    def edge_distance(self, points):
        """Distance to the nearer rim circle (the caps' borders, or an open tube's ends)."""
        _, length = self.axis()
        z, radial = self._local(points)
        return np.hypot(np.minimum(np.abs(z), np.abs(z - length)), np.linalg.norm(radial, axis=-1) - self.radius)

    # -- the error model -----------------------------------------------------------------------
    def anchor(self, point):
        """The end farther from the point (the kernel works from p0 and p1, Mitsuba from p0 and
        its caps' centres): the larger coordinates."""
        point = np.asarray(point, np.float64)
        p0, p1 = np.array(self.p0), np.array(self.p1)
        return p0 if np.linalg.norm(p0 - point) >= np.linalg.norm(p1 - point) else p1

    def curvature_radius(self) -> float:
        return self.radius

    # Mitsuba's cylinder solves the textbook quadratic (B^2 - 4 A C in its local coordinates), in float32
    # in the JIT variants: measured up to 1.2 times the sphere's K eps (t + L) / cos on
    # scenes/tp02-cylinder.toml (llvm_ad_rgb); 3 leaves room
    mitsuba_error_scale = 3.0

    # -- Mitsuba 3 -----------------------------------------------------------------------------
    mitsuba_plugins = ("cylinder",)

    @classmethod
    def from_mitsuba(cls, props, folder):
        """Mitsuba's cylinder is open (no caps): a cylinder with caps = false. Its local coordinates
        (to_world, then p0 and the axis p1 - p0, then the radius) must keep its cross-section round."""
        p0 = props.take("p0", "point", np.zeros(3))
        p1 = props.take("p1", "point", np.array([0.0, 0.0, 1.0]))
        radius = props.take("radius", "float", 1.0)
        to_world = props.to_world()
        axis = p1 - p0
        if not np.any(axis):
            raise props.element.error("p0 and p1 are the same point")
        t1, t2, _ = space_columns(axis / np.linalg.norm(axis))
        x, y, z = (to_world.matrix[:3, :3] @ v for v in (t1 * radius, t2 * radius, axis))
        rx, ry = np.linalg.norm(x), np.linalg.norm(y)
        if (abs(np.dot(x, y)) > 1e-9 * rx * ry or abs(rx - ry) > 1e-9 * max(rx, ry)
                or max(abs(np.dot(x, z)), abs(np.dot(y, z))) > 1e-9 * rx * np.linalg.norm(z)):
            raise props.element.error("to_world makes the cylinder elliptic or slanted: pyclray's cylinders are round "
                                      "and upright")
        return partial(cls, tuple(to_world.point(p0)), tuple(to_world.point(p1)), float(0.5 * (rx + ry)), False)

    def mitsuba_shapes(self, scene):
        """Mitsuba's cylinder is open: two disks close it, normals out of the solid."""
        parts = [{"type": "cylinder", "p0": list(self.p0), "p1": list(self.p1), "radius": self.radius}]
        if self.caps:
            A, _ = self.axis()
            r = self.radius
            for centre, outward in ((self.p0, -A), (self.p1, A)):
                t1, t2, n = space_columns(outward)
                parts.append({"type": "disk", "to_world": to_world((t1 * r, t2 * r, n * r), centre)})
        return parts
