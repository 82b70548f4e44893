"""The float64 numpy reference: the same camera rays and shapes as the kernels, computed in the
world frame with plain formulas, as the oracle that exactness tests compare against.

Each shape is tested against the rays that cross its box (oracle_bvh: the scene's BVH, traversed
in numpy for all rays at once); it is meant for tests, checks and benchmarks.
"""
from __future__ import annotations

import numpy as np

from ..model.aovs import AOVS
from ..model.scene import Scene
from .oracle_bvh import by_shape, nearest_two


def camera_rays(scene: Scene):
    """(origins, directions) of the scene's pixel-centre rays, each (height, width, 3) float64, unit
    directions: its camera's own float64 rays (CameraModel.rays) at its image size."""
    return scene.camera.rays(scene.image.width, scene.image.height)


def trace(scene: Scene, origins, directions, aovs=AOVS, desc: str = "float64 oracle") -> dict:
    """Nearest hit with t > 0 of every ray (unit directions), lowest id on an exact tie; with
    "second" in aovs also the second-nearest shape's distance, id and |cos incidence|.

    Each shape is tested only against the rays that cross its box (the scene's BVH over the bounded
    shapes, traversed for all rays at once; unbounded shapes against every ray): the same shape
    tests as trace_every_shape, on fewer rays, so the same results bit for bit. A progress bar
    (``desc``) counts the rays on a terminal."""
    from ..io.progress import progress

    shape = directions.shape[:-1]
    O = np.asarray(origins, np.float64).reshape(-1, 3)
    D = np.asarray(directions, np.float64).reshape(-1, 3)
    O = np.broadcast_to(O, D.shape) if len(O) == 1 else O
    with progress(len(D), desc=desc, unit="ray") as bar:
        best, best_id, second, second_id = nearest_two(scene, O, D, bar.update)
    return _finish(scene, O, D, shape, best, best_id, second, second_id, aovs)


def trace_every_shape(scene: Scene, origins, directions, aovs=AOVS) -> dict:
    """trace, the plain way: every shape against every ray (the definition trace is tested against)."""
    shape = directions.shape[:-1]
    O = np.asarray(origins, np.float64).reshape(-1, 3)
    D = np.asarray(directions, np.float64).reshape(-1, 3)
    best = np.full(len(D), np.inf)
    second = np.full(len(D), np.inf)  # the nearest hit of any other shape, to find near-ties
    second_id = np.full(len(D), -1, np.int32)
    best_id = np.full(len(D), -1, np.int32)
    for index, item in enumerate(scene.shapes):
        t = item.oracle_distance(O, D)
        closer = t < best  # strict: an exact tie keeps the lower id, visited first
        runner_up = ~closer & (t < second)
        second_id = np.where(closer, best_id, np.where(runner_up, index, second_id))
        second = np.where(closer, best, np.where(runner_up, t, second))
        best = np.where(closer, t, best)
        best_id = np.where(closer, index, best_id)
    return _finish(scene, O, D, shape, best, best_id, second, second_id, aovs)


def _finish(scene, O, D, shape, best, best_id, second, second_id, aovs) -> dict:
    """The AOVs asked for from the nearest and second-nearest hits."""
    out = {}
    if "second" in aovs:  # the second-nearest shape: its distance, id and |cos incidence|
        out["second"] = second.reshape(shape)
        out["second_id"] = second_id.reshape(shape)
        cos = np.ones(len(D))
        points = O + np.where(np.isfinite(second), second, 0)[:, None] * D
        for index, mine in by_shape(second_id):
            cos[mine] = np.abs(np.einsum("ij,ij->i", scene.shapes[index].oracle_normal(points[mine]), D[mine]))
        out["second_cos"] = cos.reshape(shape)
    if "depth" in aovs:
        out["depth"] = best.reshape(shape)
    if "normal" in aovs:
        normal = np.zeros_like(D)
        points = O + np.where(np.isfinite(best), best, 0)[:, None] * D
        for index, mine in by_shape(best_id):
            normal[mine] = scene.shapes[index].oracle_normal(points[mine])
        out["normal"] = normal.reshape(shape + (3,))
    if "id" in aovs:
        out["id"] = best_id.reshape(shape)
    return out


def render(scene: Scene, aovs=AOVS) -> dict:
    """The reference images of the scene, float64 (int32 ids)."""
    origins, directions = camera_rays(scene)
    return trace(scene, origins, directions, aovs)


def incidence_cosine(scene: Scene, directions, ids, normals) -> np.ndarray:
    """|cos| of the angle between each ray and the surface it hit (1 on a miss)."""
    cos = np.abs(np.einsum("...k,...k", directions, normals))
    return np.where(ids >= 0, cos, 1.0)


# -- closest points, distances, inside -------------------------------------------------------------
def closest_points(scene: Scene, points) -> dict:
    """For each point (..., 3), the nearest point of any shape's surface, float64: position,
    distance, id (-1 without shapes), primitive, barycentric, normal; an exact tie of distances keeps
    the lower id (each shape's oracle_closest, every shape for every point)."""
    points = np.asarray(points, np.float64)
    shape = points.shape[:-1]
    P = points.reshape(-1, 3)
    n = len(P)
    out = {"position": np.full((n, 3), np.nan), "distance": np.full(n, np.inf), "id": np.full(n, -1, np.int32),
           "primitive": np.full(n, -1, np.int32), "barycentric": np.zeros((n, 2)), "normal": np.zeros((n, 3))}
    if n:
        for index, item in enumerate(scene.shapes):
            position, normal, primitive, barycentric, distance = item.oracle_closest(P)
            closer = distance < out["distance"]
            for key, value in (("position", position), ("normal", normal), ("barycentric", barycentric)):
                out[key][closer] = value[closer]
            out["primitive"][closer] = primitive[closer]
            out["id"][closer] = index
            out["distance"][closer] = distance[closer]
    return {k: v.reshape(shape + v.shape[1:]) for k, v in out.items()}


def distance(scene: Scene, points) -> np.ndarray:
    return closest_points(scene, points)["distance"]


def inside(scene: Scene, points, sign: str = "parity") -> np.ndarray:
    """Whether each point is inside any solid (each shape's oracle_inside: exact where a sign
    decides), or on a surface (distance 0)."""
    points = np.asarray(points, np.float64)
    P = points.reshape(-1, 3)
    out = np.zeros(len(P), bool)
    for item in scene.shapes:
        out |= np.asarray(item.oracle_inside(P, sign), bool).reshape(-1)
    out |= distance(scene, P) == 0
    return out.reshape(points.shape[:-1])


def signed_distance(scene: Scene, points, sign: str = "parity") -> np.ndarray:
    d = distance(scene, points)
    return np.where(inside(scene, points, sign) & (d > 0), -d, d)


def occupancy(scene: Scene, points, sign: str = "parity") -> np.ndarray:
    return inside(scene, points, sign).astype(np.uint8)


def winding_number(scene: Scene, points) -> np.ndarray:
    """The generalized winding number of every mesh's triangles together at each point (float64)."""
    points = np.asarray(points, np.float64)
    total = np.zeros(points.shape[:-1]).reshape(-1)
    for item in scene.shapes:
        if type(item).winding_number:  # (meshes)
            total += item.oracle_winding(points.reshape(-1, 3))
    return total.reshape(points.shape[:-1])
def all_hits(scene: Scene, origins, directions, tmin=0.0, tmax=np.inf) -> dict:
    """Every crossing t of each ray with tmin < t < tmax, nearest first (then by id and primitive),
    in all_hits' CSR form: offsets (int64, N + 1), ray, depth (float64), id, primitive. Directions of
    any length (t is along the unit direction); tmin, tmax one number or one per ray. Each shape's
    crossings (oracle_crossings: a tangent ray none, a ray through a mesh's shared edge or vertex
    one triangle there, decided in exact arithmetic); every shape against every ray."""
    D = np.asarray(directions, np.float64).reshape(-1, 3)
    D = D / np.linalg.norm(D, axis=1, keepdims=True)
    O = np.broadcast_to(np.asarray(origins, np.float64).reshape(-1, 3), D.shape)
    lo = np.broadcast_to(np.asarray(tmin, np.float64).reshape(-1), (len(D),))
    hi = np.broadcast_to(np.asarray(tmax, np.float64).reshape(-1), (len(D),))
    rays, ts, ids, primitives = [], [], [], []
    for index, item in enumerate(scene.shapes):
        t, primitive = item.oracle_crossings(O, D)
        keep = (t > lo[:, None]) & (t < hi[:, None])
        row, column = np.nonzero(keep)
        rays.append(row)
        ts.append(t[row, column])
        ids.append(np.full(len(row), index, np.int32))
        primitives.append(primitive[row, column].astype(np.int32))
    ray, t, ident, primitive = (np.concatenate(x) if x else np.zeros(0) for x in (rays, ts, ids, primitives))
    order = np.lexsort((primitive, ident, t, ray))
    ray = ray[order].astype(np.int64)
    counts = np.bincount(ray, minlength=len(D))
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return {"offsets": offsets, "ray": ray, "depth": t[order], "id": ident[order].astype(np.int32),
            "primitive": primitive[order].astype(np.int32)}


def count_hits(scene: Scene, origins, directions, tmin=0.0, tmax=np.inf) -> np.ndarray:
    """The number of all_hits' crossings of each ray (int32, the rays' leading shape)."""
    shape = np.shape(directions)[:-1]
    return np.diff(all_hits(scene, origins, directions, tmin, tmax)["offsets"]).astype(np.int32).reshape(shape)
