"""The reference part of a shape type: its float64 oracle, the terms the error model takes from it,
and its Mitsuba 3 counterpart (one of the three parts of pyclray.model.shapes.base.Shape).

These are methods of the model's classes, asked by the reference stack (pyclray.reference: the
oracle, the error model, the checks against Mitsuba) and by the scene's own checks; nothing here
imports pyclray.reference, which sits above the product.
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np


class ReferenceShape:
    """The reference part of the shape interface: the contract a shape type implements for the
    float64 oracle (pyclray.reference.oracle), the error model (pyclray.reference.error_model) and
    Mitsuba 3 (pyclray.reference.mitsuba).

    A shape type defines (``required_members``):

    - ``oracle_distance(origins, directions)``: the float64 distance to the nearest crossing;
    - ``oracle_normal(points)``: the float64 unit world normal (outward, never flipped);
    - ``surface_distance(points)``: the unsigned distance of points to the surface;
    - ``oracle_closest(points)``: the nearest surface point, its normal, primitive and barycentrics;
    - ``anchor(point)``: the point its intersection measures coordinates from (the error model's
      coordinate size);
    - ``mitsuba_shapes(scene)``: its Mitsuba counterpart, one or more Mitsuba shapes that all map
      back to its id.

    Optional, with defaults here: ``oracle_inside`` (a solid's inside, exact; none by default),
    ``oracle_primitives`` (a shape of many primitives: which one a
    ray hits), ``oracle_crossings`` (every crossing of a ray: one, a flat shape's), ``hit_normals`` and
    ``hit_barycentrics`` (all_hits' per-hit normal and barycentrics: oracle_normal, and 0, 0), ``edge_distance`` (where a ray within rounding may go either way: inf, no edges),
    ``curvature_radius`` (inf: flat), ``silhouette_radius`` (the curvature radius),
    ``extent_from`` (from its box), ``flat_camera_depth`` (False), ``mitsuba_error_scale`` (1),
    ``mitsuba_primitives`` (False)
    and ``mitsuba_covers`` (everywhere: no stand-in).
    """

    required_members: ClassVar[tuple[str, ...]] = ("oracle_distance", "oracle_normal", "surface_distance", "anchor",
                                                   "mitsuba_shapes", "oracle_closest")

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

    def oracle_closest(self, points) -> tuple:
        """The nearest point of the surface to each of points (N, 3), float64: (position (N, 3),
        normal (N, 3), primitive (N,) int, barycentric (N, 2), distance (N,)). The normal is the
        surface's unit geometric normal there (outward); where that is ambiguous (a box's edge) the
        same rule as the kernel's <type>_closest."""
        raise NotImplementedError

    def oracle_inside(self, points, sign: str = "parity") -> np.ndarray:
        """Whether each point lies in the shape's solid (its surface included), decided exactly
        where float64 cannot (exact_at_most): False for a shape without an inside."""
        return np.zeros(np.shape(points)[:-1], bool)

    def oracle_crossings(self, origins, directions) -> tuple[np.ndarray, np.ndarray]:
        """(t, primitive): every crossing t > 0 of each ray (unit directions (N, 3)) as (N, K) float64
        distances, inf where a ray has fewer than K, and each one's primitive index (the oracle of
        count_hits and all_hits). A tangent ray crosses nothing; a ray through a shared edge or
        vertex of a mesh crosses it once (kernels/mesh.cl's tie rule). The default: a flat shape's one
        crossing, its nearest hit."""
        t = np.asarray(self.oracle_distance(origins, directions), np.float64).reshape(-1, 1)
        primitives = self.oracle_primitives(origins, directions)
        primitives = np.zeros(t.shape, np.int64) if primitives is None else np.asarray(primitives).reshape(-1, 1)
        return t, primitives

    def hit_normals(self, points, primitives) -> np.ndarray:
        """(N, 3) float64 unit world normals (outward, never flipped) at hit points on the surface,
        each on its primitive (all_hits' normal, engine/queries/hits.py). The default: oracle_normal."""
        return self.oracle_normal(np.asarray(points, np.float64))

    def hit_barycentrics(self, points, primitives) -> np.ndarray:
        """(N, 2) float64 (u, v) of hit points on their triangles (all_hits' barycentric); 0, 0 for a
        shape without triangles (the default)."""
        return np.zeros((len(points), 2))

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

    # True for a shape of flat faces whose fp32 and fp64 render takes a camera ray's distance as the
    # host's exact offset over an error-free n . d (kernels/lanes.h: pixel_dot): its depth errs by
    # the roundings of a quotient, K eps (t + L), not by a sideways move over |cos| (the error
    # model's flat law: error_model.tolerances)
    flat_camera_depth: ClassVar[bool] = False

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


def exact_at_most(value, size, exact) -> np.ndarray:
    """value <= 0 per row, from float64 where |value| exceeds 1e-10 of size (its rounding is far
    smaller), else from exact(i), the row's value in exact rational arithmetic (fractions.Fraction
    of the float64 inputs)."""
    value, size = np.asarray(value, np.float64), np.asarray(size, np.float64)
    out = value <= 0
    for i in np.flatnonzero(~(np.abs(value) > 1e-10 * np.broadcast_to(size, value.shape))):
        out.flat[i] = exact(i) <= 0
    return out


def rational(values):
    """The float64 values as exact fractions."""
    from fractions import Fraction

    return [Fraction(float(v)) for v in np.ravel(values)]


def plain_closest(points, position, normal) -> tuple:
    """oracle_closest's tuple for a shape of one primitive without barycentrics."""
    points = np.asarray(points, np.float64)
    count = len(points)
    return (position, np.broadcast_to(normal, points.shape).copy(), np.zeros(count, np.int64), np.zeros((count, 2)),
            np.linalg.norm(points - position, axis=-1))
