"""The shaded image of a render by casting (a camera whose rays start apart: orthographic): the
shading model (scene-format.md, "Shading") of cast's hits, on the host, its shadow rays the exact
``occluded`` query.

Why on the host, beside kernels/shading.h: the render kernel shades inside its packets, in the eye's
space, its shadow rays leaving from points of that space; a cast view has no eye, and its hits are
already here (cast's float64 origins and unit directions, its depth, normal, id, primitive and
barycentric). What remains is a per-pixel formula of a few numpy operations, written here term by
term as kernels/shading.h's PYCLRAY_WRITE_SHADED writes it (n_s, the lighting normal, E, L, cos, H,
V), in float64 rounded once to the precision; tests/test_orthographic.py holds it to the render's
own shaded image on a perspective camera's pixel rays (cast and shaded here) and both to the float64
reference (pyclray.reference.shading).

Shadow rays: from the hit point p (float64: origin + t D) moved along n_s by
SHADOW_OFFSET_K (eps t + eps64 (|p|_1 + R)), over the rounding of t (the cast's depth, a few eps t
along the ray: at most that across the surface), of p's float64 coordinates and of the float64 terms
(of the hit shape's size R) by which the shadow ray's own test decides its side, to each light
(``occluded`` with tmax the distance to a point light: hits strictly before it): the surface at p
never shadows p, an occluder touching it still does. The cast frames every shape on the ray's own
float64 origin, so which side of a surface a shadow ray starts on is exact.
"""
from __future__ import annotations

import numpy as np

from ...model.lights import PointLight, effective_lights
from ...model.shapes.capabilities import capability
from ..scene.lighting import SHADOW_OFFSET_K

EPSILON = {"fp32": 2.0**-24, "fp64": 2.0**-53}


def shading_aovs(view) -> tuple[str, ...]:
    """The cast AOVs the shading of a view's hits needs: depth, normal, id, and where a shape may
    shade with its own normals (the capability "smooth_shading"), primitive and barycentric."""
    smooth = any(capability(type(s), "smooth_shading") for s in view.shapes)
    return ("depth", "normal", "id") + (("primitive", "barycentric") if smooth else ())


def shape_sizes(shapes) -> np.ndarray:
    """Per shape id (and -1 last: 0) the half diagonal of its box (0 for an unbounded shape): the
    size of the float64 terms cast's test of it rounds from an origin near it (kernels/cast.h:
    a sphere's c = |C - O|^2 - r^2 rounds eps64 |C - O|^2, which places O on the surface within
    eps64 times the sphere's size)."""
    return np.array([0.5 * float(np.linalg.norm(np.subtract(*s.box()[::-1]))) if s.bounded else 0.0 for s in shapes]
                    + [0.0])


def shadow_offset(depth, points, sizes, precision: str) -> np.ndarray:
    """How far along n_s a shadow ray starts from the hit point (see the module's docstring): the
    rounding of the hit's depth (eps t) and of the float64 terms of the shadow ray's test from there
    (eps64 (|p|_1 + the hit shape's size: shape_sizes, per hit)), K = SHADOW_OFFSET_K times over."""
    size = np.abs(points).sum(axis=-1) + np.asarray(sizes, np.float64)
    return SHADOW_OFFSET_K * (EPSILON[precision] * np.asarray(depth, np.float64) + EPSILON["fp64"] * size)


def lighting_normals(view, hits: dict, normals: np.ndarray) -> np.ndarray:
    """Per hit the normal that lights it before it is turned toward the viewer: a smooth shape's
    shading normal at the hit (SmoothShading.shading_normals: from cast's primitive and barycentric),
    else the geometric normal (float64)."""
    ids = hits["id"]
    out = normals.copy()
    for index, shape in enumerate(view.shapes):
        if not capability(type(shape), "smooth_shading"):
            continue
        mine = ids == index
        if mine.any():
            out[mine] = shape.shading_normals(hits["primitive"][mine], hits["barycentric"][mine], normals[mine])
    return out


def shade(tracer, view, origins: np.ndarray, directions: np.ndarray, hits: dict) -> np.ndarray:
    """(N, 3) of the precision: the shaded colour of each ray's hit (the background on a miss), for
    rays from float64 ``origins`` along unit float64 ``directions`` (N, 3) and their cast ``hits``
    (shading_aovs)."""
    precision = tracer.precision
    ids = np.asarray(hits["id"]).reshape(-1)
    hit = ids >= 0
    D = directions
    depth = np.where(hit, np.asarray(hits["depth"], np.float64).reshape(-1), 0.0)
    p = origins + depth[:, None] * D
    which = np.maximum(ids, 0)
    shapes = view.shapes
    albedo = np.array([s.material.color for s in shapes] or [(0.0, 0.0, 0.0)], np.float64)[which]
    specular = np.array([s.material.specular for s in shapes] or [0.0], np.float64)[which]
    shininess = np.array([s.material.shininess for s in shapes] or [1.0], np.float64)[which]
    n = np.asarray(hits["normal"], np.float64).reshape(-1, 3)
    # n_s: the side facing the viewer (n . D < 0 is the front)
    front = np.einsum("ij,ij->i", n, D) < 0
    n_s = np.where(front[:, None], n, -n)
    # n_l: the normal that lights, facing the viewer: a shading normal (turned as n_s is) where there is one
    shading_normal = lighting_normals(view, hits, n)
    n_l = np.where((np.einsum("ij,ij->i", shading_normal, D) < 0)[:, None], shading_normal, -shading_normal)
    color = albedo * np.array(view.shading.ambient)
    sizes = shape_sizes(shapes)[np.where(hit, ids, -1)]
    shadow_origins = p + shadow_offset(depth, p, sizes, precision)[:, None] * n_s
    for light in effective_lights(view):
        if isinstance(light, PointLight):
            to = np.array(light.position) - p
            d2 = np.einsum("ij,ij->i", to, to)
            L = to / np.sqrt(d2)[:, None]
            E = np.array(light.intensity) / d2[:, None]
        else:
            L = np.broadcast_to(light.toward_light(), p.shape)
            E = np.broadcast_to(np.array(light.irradiance, np.float64), p.shape)
        cos_l = np.einsum("ij,ij->i", n_l, L)
        lit = hit & (cos_l > 0)
        if view.shading.shadows and lit.any():
            rows = np.flatnonzero(lit)
            start = shadow_origins[rows]
            if isinstance(light, PointLight):
                toward = np.array(light.position) - start
                distance = np.linalg.norm(toward, axis=1)
                # (a light exactly at a shadow ray's start: nothing lies between the two)
                rows, start, toward, distance = (x[distance > 0] for x in (rows, start, toward, distance))
                blocked = tracer.occluded(start, toward, tmax=distance)
            else:
                blocked = tracer.occluded(start, np.ascontiguousarray(L[rows]))
            lit[rows[blocked]] = False
        if not lit.any():
            continue
        glossy = np.zeros(len(ids))
        if (specular[lit] > 0).any():
            H = L - D
            H = H / np.linalg.norm(H, axis=1, keepdims=True)
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                glossy = specular * np.maximum(np.einsum("ij,ij->i", n_l, H), 0.0) ** shininess
        add = E * (albedo * np.maximum(cos_l, 0.0)[:, None] + glossy[:, None])
        color = color + np.where(lit[:, None], add, 0.0)
    out = np.where(hit[:, None], color, np.array(view.shading.background, np.float64))
    return out.astype(np.float64 if precision == "fp64" else np.float32)
