"""The float64 reference of the shading model (scene-format.md, "Shading"; kernels/shading.h) and
the bound on the shaded image's error that follows from the error model."""
from __future__ import annotations

import numpy as np

from ..model.lights import PointLight, effective_lights
from ..model.shapes.capabilities import capability


# -- the float64 reference -----------------------------------------------------------------------
def facing_normals(normals, directions) -> np.ndarray:
    """n_s: the normal on the side the ray comes from."""
    front = np.einsum("...k,...k", normals, directions) < 0
    return np.where(front[..., None], normals, -normals)


def lighting_normals(scene, hits) -> np.ndarray:
    """The normals that light each hit: the geometric ``hits["normal"]``, or a shape's own shading
    normal at the hit point (the capability "smooth_shading": SmoothShading.oracle_shading_normal, a
    smooth mesh's interpolated vertex normals), float64."""
    normals = np.array(hits["normal"], np.float64)
    ids, points = hits["id"], hits["points"]
    for index, shape in enumerate(scene.shapes):
        mine = ids == index
        if mine.any() and capability(type(shape), "smooth_shading"):
            normals[mine] = shape.oracle_shading_normal(points[mine], normals[mine])
    return normals


def light_terms(light, points):
    """(L unit toward the light, E per point (..., 3), distance to the light (inf: directional))."""
    if isinstance(light, PointLight):
        to = np.array(light.position) - points
        distance = np.linalg.norm(to, axis=-1)
        L = to / distance[..., None]
        E = np.array(light.intensity) / (distance**2)[..., None]
        return L, E, distance
    L = np.broadcast_to(light.toward_light(), points.shape)
    E = np.broadcast_to(np.array(light.irradiance), points.shape)
    return L, E, np.full(points.shape[:-1], np.inf)


def reference_shading(scene, directions, hits, visibility=None) -> np.ndarray:
    """The shading model in float64 for rays of unit ``directions`` (..., 3) and their float64 hits
    (``oracle.trace``'s depth, normal and id, with ``points``), V from ``visibility`` (a list of (...)
    arrays, one per light, 1 lit and 0 shadowed; default all lit). Misses get the background."""
    ids = hits["id"]
    hit = ids >= 0
    points = hits["points"]
    color = np.array([s.material.color for s in scene.shapes] or [(0, 0, 0)])[np.maximum(ids, 0)]
    specular = np.array([s.material.specular for s in scene.shapes] or [0.0])[np.maximum(ids, 0)]
    shininess = np.array([s.material.shininess for s in scene.shapes] or [1.0])[np.maximum(ids, 0)]
    n_s = facing_normals(lighting_normals(scene, hits), directions)  # the shading normal, toward the viewer
    out = color * np.array(scene.shading.ambient)
    for index, light in enumerate(effective_lights(scene)):
        L, E, _ = light_terms(light, points)
        cos = np.einsum("...k,...k", n_s, L)
        H = L - directions
        H = H / np.linalg.norm(H, axis=-1, keepdims=True)
        with np.errstate(invalid="ignore"):
            glossy = specular * np.maximum(np.einsum("...k,...k", n_s, H), 0.0) ** shininess
        lit = cos > 0
        if visibility is not None:
            lit &= visibility[index] > 0
        term = E * (color * np.maximum(cos, 0)[..., None] + glossy[..., None])
        out = out + np.where(lit[..., None], term, 0.0)
    return np.where(hit[..., None], out, np.array(scene.shading.background))


def reference_visibility(scene, points, normals, directions, ids, *, skip=1e-9, blur=0.0, lifts=()):
    """Per light, V (1 lit, 0 shadowed) of each hit point in float64: the nearest hit of the ray from
    p toward the light, beyond skip times the scene's size (the surface at p itself never shadows p,
    and a float64 test of it from p errs by far less), before the light.

    blur > 0 (scene units, one number or one per point) also tests rays from points moved by blur
    along six directions, and returns per light a second array: True where the moved rays disagree
    (a shadow boundary). Whether a light is in front (cos > 0) is the lighting normal's
    (lighting_normals: a smooth mesh's interpolated one); the rays start at p, on the surface. lifts (each one number or one per point, scene units): more moved points,
    p + lift n_s, the origins an engine's shadow rays start from (the kernel's offset along the
    normal, Mitsuba's spawn_ray): where one of them sees another visibility than p, the engine's
    own offset decides, which the error model counts as rounding (a shadow boundary too)."""
    from .oracle_bvh import any_hit, near_pairs

    size = max(1.0, float(np.abs(points[ids >= 0]).max(initial=1.0)))
    n_s = facing_normals(normals, directions)
    n_lit = facing_normals(lighting_normals(scene, {"normal": normals, "id": ids, "points": points}), directions)
    blurred = np.any(blur > 0)
    # the moves: within the surface's tangent plane along each axis (and slightly off it, to the lit
    # side) by blur, and along n_s by each lift
    moves = []
    if blurred:
        reach = np.broadcast_to(blur, ids.shape)[..., None]
        for axis, sign in ((a, s) for a in range(3) for s in (-1.0, 1.0)):
            step = np.zeros(3)
            step[axis] = sign
            moves.append(reach * (step - np.einsum("...k,k->...", n_s, step)[..., None] * n_s + 0.5 * n_s))
        moves += [np.broadcast_to(lift, ids.shape)[..., None] * n_s for lift in lifts]
    # how far each pixel's moved points go, rounded up to a power of 2 (one padded tree per level)
    reach = np.max([np.linalg.norm(m, axis=-1) for m in moves], axis=0) if moves else np.zeros(ids.shape)
    level = np.ceil(np.log2(np.maximum(reach, 2.0**-1000)))
    out, unsure = [], []
    for light in effective_lights(scene):
        # only hit points the light is in front of (cos > 0) are traced: elsewhere it adds nothing
        lit = (ids >= 0) & (np.einsum("...k,...k", n_lit, light_terms(light, points)[0]) > 0)
        P = points[lit]
        L0 = light_terms(light, P)[0]
        # a moved point's ray stays within its move of p's (parallel for a directional light, ending
        # at the same point light): the shapes within that of p's ray are all it may meet
        starts, levels = P + skip * size * L0, level[lit]
        found = []
        for value in np.unique(levels):
            mine = np.flatnonzero(levels == value)
            near_rays, near_shapes = near_pairs(scene, starts[mine], L0[mine], float(2.0**value))
            found.append((mine[near_rays], near_shapes))
        rays = np.concatenate([r for r, _ in found] or [np.zeros(0, np.int64)])
        shapes = np.concatenate([q for _, q in found] or [np.zeros(0, np.int64)])
        # p and all its moved points at once (one shape test per shape, not one per move)
        origins = np.concatenate([P] + [P + move[lit] for move in moves])
        copies = 1 + len(moves)
        pairs = (np.concatenate([rays + k * len(P) for k in range(copies)]), np.tile(shapes, copies))
        L, _, distance = light_terms(light, origins)
        seen = ~any_hit(scene, pairs, origins + skip * size * L, L, distance - skip * size)
        seen = seen.reshape(copies, len(P))
        V = np.zeros(ids.shape)
        V[lit] = seen[0]
        out.append(V)
        if blurred:
            mixed = np.zeros(ids.shape, bool)
            mixed[lit] = (seen[1:] != seen[0]).any(axis=0)
            unsure.append(mixed)
    return (out, unsure) if blurred else out


# -- the shading's error bound -----------------------------------------------------------------------
LOG_EXP_ULPS = 3  # OpenCL C's log2 and exp2: at most 3 ulps each (x^k = exp2(k log2 x) in the kernel)


def tolerance(scene, directions, hits, depth_tolerance, normal_tolerance, eps):
    """(bound on |shaded - reference| per pixel and channel's largest, pixels where the model is
    discontinuous within that error): what the error model's bounds on the hit (``depth_tolerance``
    along the ray, scene units) and on the normal (``normal_tolerance``, radians) and the kernel's own
    roundings (``eps``: its unit roundoff) make of the shading model, which is a smooth function of
    the point and the normal (kernels/shading.h), term by term:

    - the point p moves by dp = depth_tolerance: a point light's direction L turns by dp / d and
      its falloff 1 / d^2 changes by 2 dp / d relative (d: the distance to the light);
    - cos = n_s.L moves by the normal's angle + L's turn + the roundings (8 eps: the normal turned
      into the frame, L normalized, the dot);
    - H = normalize(L - D) turns by (L's turn + 4 eps) / |L - D|, so n_s.H by that plus the normal's
      angle, and x^k by k max(x, x + dx)^(k - 1) dx (k >= 1; |dx|^k for k < 1: x^k is Hoelder), plus
      the kernel's exp2(k log2 x): ln 2 |k log2 x| 7 ulps + 6 ulps relative;
    - each term is a product and a sum of a few roundings: 8 eps of its size.

    Where cos or the visibility V changes within the error (the terminator of a light with a
    specular term, where the model's "if n_s.L > 0" jumps; a shadow's edge) no bound holds: the
    second result marks the terminators (shadow edges are the caller's, see reference_visibility)."""
    ids = hits["id"]
    hit = ids >= 0
    index = np.maximum(ids, 0)
    points = hits["points"]
    albedo = np.array([s.material.color for s in scene.shapes] or [(0, 0, 0)])[index].max(axis=-1)
    specular = np.array([s.material.specular for s in scene.shapes] or [0.0])[index]
    shininess = np.array([s.material.shininess for s in scene.shapes] or [1.0])[index]
    n_s = facing_normals(lighting_normals(scene, hits), directions)
    dp = np.where(hit, depth_tolerance, 0.0)
    angle = np.where(hit, normal_tolerance, 0.0)
    bound = 8 * eps * albedo * max(scene.shading.ambient) + np.zeros(ids.shape)
    jump = np.zeros(ids.shape, bool)
    for light in effective_lights(scene):
        L, E, distance = light_terms(light, points)
        E = E.max(axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            turn = np.where(np.isfinite(distance), dp / distance, 0.0) + 4 * eps
            falloff = np.where(np.isfinite(distance), 2 * dp / distance, 0.0) + 4 * eps
            cos = np.einsum("...k,...k", n_s, L)
            d_cos = angle + turn + 8 * eps
            half = L - directions
            half_length = np.linalg.norm(half, axis=-1)
            H = half / half_length[..., None]
            n_h = np.maximum(np.einsum("...k,...k", n_s, H), 0.0)
            d_nh = angle + (turn + 4 * eps) / half_length + 4 * eps
            k = shininess
            top = np.minimum(n_h + d_nh, 1.0)
            d_pow = np.where(k >= 1, k * top ** np.maximum(k - 1, 0), d_nh ** np.minimum(k, 1))
            # exp2(k log2 x): log2's error times k, the product's rounding, exp2's error (relative)
            log_power = np.abs(k * np.log2(np.where(n_h > 0, n_h, 1.0)))
            relative = np.log(2) * log_power * (2 * LOG_EXP_ULPS + 1) * 2 * eps + 2 * LOG_EXP_ULPS * 2 * eps
            d_pow = d_pow * np.where(k >= 1, d_nh, 1.0) + relative * n_h**k
            value = albedo * np.maximum(cos, 0) + specular * n_h**k
            term = E * (albedo * d_cos + specular * d_pow + value * falloff + 8 * eps * value)
        # beyond the terminator (cos < -d_cos) the light adds nothing, whatever the error
        bound = bound + np.where(hit & (cos > -d_cos), term, 0.0)
        jump |= hit & (specular > 0) & (np.abs(cos) <= d_cos)
    return bound, jump
