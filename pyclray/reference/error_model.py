"""The error model: the one place that says how far a result may be from the float64 oracle or
from Mitsuba 3, which rays are not judged, and the measures of a render's error.

A rounded intersection is the exact intersection of a slightly moved ray: a position error of a
few eps (the unit roundoff) times the size of the coordinates involved, ``t + L`` (t: the distance
along the ray; L: the size of the coordinates the engine intersects in). Along the ray that error
becomes a depth error over the cosine of incidence (a sideways move slides a grazing hit far), and
seen from a centre of curvature of radius r it turns the normal by that error over r:

    depth  <= D = (k eps (t + L) [+ k eps64 (t + W)] [+ camera]) / cos
    normal <= k eps [+ k eps64] + D / r

- eps64 (t + W): the float64 oracle's own error, W the size of its world coordinates (only where
  the comparison is against the oracle and the origins are arbitrary);
- camera: Mitsuba's float32 look_at camera turns its rays by up to alpha = 3 eps (1 + S),
  S = max(|eye|, |target|) / |target - eye|, and its origins lie within 2 eps max(|eye|, 1) of the
  eye: alpha t + 2 eps max(|eye|, 1) (images against Mitsuba only);
- L: pyclray subtracts the eye in float64 on the host (render), so its L is the size of the space's
  coordinates: |origin - eye| + |anchor - eye|; a cast traces each ray on its own, from a point of
  it next to each bounded shape, relative to the shape's box centre (``cast_spaces``); Mitsuba works in
  float32 world coordinates: L = max(|eye|, |anchor|, |eye - anchor|). The anchor is the point a
  shape's intersection measures from (``Shape.anchor``), r its ``curvature_radius``.
- the flat law: where a render's camera ray hits a shape of flat faces whose distance the kernel
  takes as the host's exact offset over an error-free n . d (``Shape.flat_camera_depth``: plane,
  disk, rectangle, box; the kernel's pixel_dot, below |n . d| = 1/8), the ray is not moved
  sideways: the engine's own term is k eps (t + L) / max(cos, FLAT_COS) (the oracle's term keeps
  its 1 / cos). A grazing ground then holds a few ulps of t, as cast of an axis-aligned plane does;
- k: K_ORACLE = 4 against the oracle (measured <= 2.4 for depths over random scenes of every
  shape, tests/test_cast.py and tests/test_shapes.py), K_MITSUBA = 6 against Mitsuba (measured
  <= 2.8 over 75 random scenes moved up to 1000 units off the origin).

Rays outside the model, counted apart and not judged (one rule each):
- silhouettes: |cos| < SILHOUETTE_COS, where the 1/cos law turns into a square-root law;
- near ties: the oracle's second-nearest surface within D of the nearest: either may win;
- edges: a hit point (the oracle's or the engine's) within D of an edge of its shape (a rim, a
  border, a box's edge): a ray within rounding of an edge may go either way.

The stability targets (``meets_targets``) are stated in float32 ulps of t: fp32 depth within 8
ulps x 1/|cos|, normals within 2e-5 / |cos|, ids right; fp64 depth within 1e-12 relative / |cos|,
normals within 1e-12 / |cos| times the normal's conditioning max(1, (t + |eye|) / r) (the float64
reference rounds its ray and its world coordinates to 2^-53, which moves the normal of a unit
sphere 1e7 away by ~1e-9: an error of the reference, not of the kernel).
"""
from __future__ import annotations

import numpy as np

from . import oracle
from ..model.scene import Scene

EPSILON = {"fp32": 2.0**-24, "fp64": 2.0**-53}  # unit roundoff: half an ulp of 1
ORACLE_EPSILON = EPSILON["fp64"]
SILHOUETTE_COS = 0.02
K_ORACLE = 4.0
# the flat law's floor of cos: above it a render's flat shapes follow the sideways law, below it
# their depth error stops growing as 1 / cos (kernels/lanes.h: PIXEL_EXACT_COS, a half of it)
FLAT_COS = 0.25
K_MITSUBA = 6.0
CAMERA_K = 3.0  # Mitsuba's camera rays: angle <= CAMERA_K eps (1 + S)
ORIGIN_K = 2.0  # Mitsuba's camera rays: origin off our ray <= ORIGIN_K eps max(|eye|, 1)

FP32_DEPTH_ULPS = 8.0
FP32_NORMAL = 2e-5
FP64_DEPTH_RELATIVE = 1e-12
FP64_NORMAL = 1e-12


# -- measures ------------------------------------------------------------------------------------
def ulp32(x) -> np.ndarray:
    """The float32 ulp of |x| (as float64)."""
    x = np.abs(np.asarray(x, np.float64))
    return np.spacing(x.astype(np.float32)).astype(np.float64)


def angle_between(a, b) -> np.ndarray:
    """Angle in radians between vectors (last axis), accurate for tiny angles (atan2 of the cross
    and dot products; arccos of the dot product loses half the digits near 0)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.einsum("...k,...k", a, b))


# -- what the shapes contribute --------------------------------------------------------------------
def anchors(scene: Scene, point) -> np.ndarray:
    """(shapes, 3): each shape's anchor for rays from ``point`` (one row of zeros if no shapes)."""
    return np.array([shape.anchor(point) for shape in scene.shapes] or [np.zeros(3)], np.float64).reshape(-1, 3)


def curvature_radii(scene: Scene) -> np.ndarray:
    """The smallest radius of curvature per shape id (inf for flat shapes)."""
    return np.array([shape.curvature_radius() for shape in scene.shapes] or [np.inf], np.float64)


def silhouette_radii(scene: Scene) -> np.ndarray:
    """The radius of curvature at silhouettes per shape id (Shape.silhouette_radius: inf for a mesh,
    whose silhouettes are edges), for the silhouette rule."""
    return np.array([shape.silhouette_radius() for shape in scene.shapes] or [np.inf], np.float64)


def world_sizes(scene: Scene, point) -> np.ndarray:
    """Per shape: the size of float32 world coordinates in which an engine that does not move the
    origin (Mitsuba) intersects it from ``point``: max(|point|, |anchor|, |point - anchor|)."""
    point = np.asarray(point, np.float64)
    anchor = anchors(scene, point)
    return np.maximum.reduce([np.full(len(anchor), np.linalg.norm(point)), np.linalg.norm(anchor, axis=1),
                              np.linalg.norm(anchor - point, axis=1)])


# -- the bounds ------------------------------------------------------------------------------------
def tolerances(t, cos, radius, *, eps, scale, k, oracle_scale=None, camera_reach=0.0, travelled=None, flat=None):
    """(depth tolerance, normal angle tolerance in radians) per ray: the formula of the module's
    docstring. t, cos, radius, scale (L), oracle_scale (W) and camera_reach are per ray; travelled:
    how far the engine moved the ray's origin along it (in float64) before intersecting (cast), so
    that its own rounding, and the normal's angle, grow with t - travelled only; flat: the rays
    the flat law holds for (per ray), whose own depth term is divided by max(cos, FLAT_COS), not cos."""
    t = np.where(np.isfinite(t), t, 0.0)
    local = t if travelled is None else np.maximum(t - travelled, 0.0)
    reach = k * eps * (t + scale)
    reach_local = k * eps * (local + scale)
    angle = k * eps
    if oracle_scale is not None:
        reach = reach + k * ORACLE_EPSILON * (t + oracle_scale)
        reach_local = reach_local + k * ORACLE_EPSILON * (t + oracle_scale)
        angle = angle + k * ORACLE_EPSILON
    reach = reach + camera_reach
    reach_local = reach_local + camera_reach
    with np.errstate(invalid="ignore", divide="ignore"):
        depth = reach / cos
        normal = angle + reach_local / cos / radius
        if flat is not None:
            own = k * eps * (t + scale)
            depth = np.where(flat, own / np.maximum(cos, FLAT_COS) + (reach - own) / cos, depth)
    return depth, normal


def cast_spaces(scene: Scene, origins, directions, ids):
    """(L, travelled, anchor) per ray of a cast: cast tests a bounded shape of box centre A and
    bounding radius R from the point O + s0 D of the ray, s0 = max(0, (A - O).D - R) (float64), in
    coordinates relative to A, so what it rounds is of size L = |O + s0 D - A| + R; an unbounded
    shape (a plane) from the ray's world origin in float64 (its signed distance rounded once: L = 0)."""
    origins = np.asarray(origins, np.float64)
    directions = np.asarray(directions, np.float64)
    count = max(len(scene.shapes), 1)
    centre, radius, bounded = np.zeros((count, 3)), np.zeros(count), np.zeros(count, bool)
    mean = origins.reshape(-1, 3).mean(axis=0) if origins.size else np.zeros(3)
    for i, shape in enumerate(scene.shapes):
        if shape.bounded:
            lo, hi = shape.box()
            centre[i], radius[i], bounded[i] = 0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo), True
        else:
            centre[i] = shape.anchor(mean)
    index = np.maximum(ids, 0)
    A, R, b = centre[index], radius[index], bounded[index]
    F = A - origins
    margin = 2.0**-50 * np.abs(F).sum(axis=-1)  # the kernel's bound on the rounding of (A - O).D
    s0 = np.where(b, np.maximum(0.0, np.einsum("...k,...k", F, directions) - R - margin), 0.0)
    size = np.where(b, np.linalg.norm(F - s0[..., None] * directions, axis=-1) + R, 0.0)
    return size, s0, A


def flat_camera_depths(scene: Scene) -> np.ndarray:
    """Per shape id: whether the flat law holds for a render's camera rays (Shape.flat_camera_depth),
    which the kernel computes from the pinhole's image plane itself (a camera whose rays come as a
    table, a lens or a panorama, or start off the eye, has the sideways law everywhere)."""
    camera = scene.camera
    pinhole = camera.rays_from_eye and camera.space_directions(scene.image.width, scene.image.height) is None
    return np.array([pinhole and shape.flat_camera_depth for shape in scene.shapes] or [False], bool)


def pyclray_tolerances(scene: Scene, truth: dict, cos, origins, precision: str, reference_point=None, directions=None,
                       flat: bool = True, flat_shapes=None):
    """Bounds of pyclray (render or cast, ``precision``) against the float64 oracle's ``truth``
    for rays from ``origins``. A render's kernel works in a space centred on ``reference_point``
    (the eye); without one, the rays are a cast's, each traced on its own (``cast_spaces``, which
    needs their unit ``directions``). A render's depth bound on the flat shapes follows the flat
    law (``flat``; False: the sideways law everywhere, the position error that decides edges).
    flat_shapes: per shape id, whether the flat law holds for a render's camera rays, where a
    caller has arranged its conditions for another shape (a mesh instance whose triangles all lie
    in one coordinate plane of its object space: tests/test_instance_exact.py); by default
    ``flat_camera_depths``."""
    origins = np.asarray(origins, np.float64)
    index = np.maximum(truth["id"], 0)
    if reference_point is not None:
        ref = np.asarray(reference_point, np.float64)
        anchor = anchors(scene, ref)[index]
        size = np.linalg.norm(origins - ref, axis=-1) + np.linalg.norm(anchor - ref, axis=-1)
        travelled = None
    else:
        size, travelled, anchor = cast_spaces(scene, origins, directions, truth["id"])
    world = np.linalg.norm(origins, axis=-1) + np.linalg.norm(anchor, axis=-1)
    flat_ids = flat_camera_depths(scene) if flat_shapes is None else np.asarray(flat_shapes, bool)
    along = flat_ids[index] if flat and reference_point is not None else None
    return tolerances(truth["depth"], cos, curvature_radii(scene)[index], eps=EPSILON[precision], scale=size,
                      k=K_ORACLE, oracle_scale=world, travelled=travelled, flat=along)


def camera_size(scene: Scene) -> float:
    """S, the size of the roundings of Mitsuba's float32 camera rays: a look-at camera's
    max(|eye|, |target|) / |target - eye| (look_at's subtraction); a camera from intrinsics (its
    to_world a matrix) max(tan_x, tan_y) (1 + 2 |offset|), offset the larger principal point
    offset (mitsuba.sensor_of), which Mitsuba adds to the film position in float32."""
    camera = scene.camera
    if not camera.rays_from_eye:
        # (orthographic) Mitsuba's origins are the eye plus the film's offsets, rounded to float32, its
        # direction its to_world's z: S bounds those origins' size (as a look-at's |eye| / |target - eye|
        # does) in units of the eye's distance to its target, at least 1
        origins, _ = camera.rays(scene.image.width, scene.image.height)
        eye, target = np.array(camera.eye), np.array(getattr(camera, "target", None) or camera.eye)
        reach = float(np.linalg.norm(eye) + np.linalg.norm(origins - eye, axis=-1).max())
        return max(1.0, reach / max(np.linalg.norm(target - eye), 1.0))
    if camera.K is None:
        eye, target = np.array(camera.eye), np.array(camera.target)
        return max(np.linalg.norm(eye), np.linalg.norm(target)) / np.linalg.norm(target - eye)
    width, height = scene.image.width, scene.image.height
    plane = camera.image_plane(width, height)
    offset = max(abs(0.5 - plane.cx / width), abs(0.5 - plane.cy / height))
    return max(plane.tan_x, plane.tan_y) * (1 + 2 * offset)


def camera_angle_tolerance(scene: Scene) -> float:
    """alpha: how far (radians) Mitsuba's float32 camera rays may be from pyclray's."""
    return CAMERA_K * EPSILON["fp32"] * (1 + camera_size(scene))


def mitsuba_tolerances(scene: Scene, t, ids, cos, *, cameras: bool, origin_scale=None):
    """Bounds of pyclray fp32 against Mitsuba (float32 world coordinates): cameras adds the
    difference of the two cameras' rays (images; not for the very same rays); origin_scale: the
    size of the rays' origins if they are not the eye (ray level)."""
    index = np.maximum(ids, 0)
    scale = world_sizes(scene, scene.camera.eye)[index]
    if origin_scale is not None:
        scale = np.maximum(scale, origin_scale)
    # a Mitsuba counterpart less exact than the model's K (Shape.mitsuba_error_scale)
    k = K_MITSUBA * np.array([s.mitsuba_error_scale for s in scene.shapes] or [1.0])[index]
    camera_reach = 0.0
    if cameras:
        eye = np.linalg.norm(scene.camera.eye)
        camera_reach = camera_angle_tolerance(scene) * np.where(np.isfinite(t), t, 0.0) + ORIGIN_K * EPSILON["fp32"] * max(eye, 1.0)
    return tolerances(t, cos, curvature_radii(scene)[index], eps=EPSILON["fp32"], scale=scale, k=k,
                      camera_reach=camera_reach)


# -- the rays not judged ---------------------------------------------------------------------------
def silhouettes(ids, cos, depth_tolerance=None, radius=None) -> np.ndarray:
    """Grazing hits: |cos| < SILHOUETTE_COS, and on a curved shape (radius of curvature r) also
    where a sideways move of the ray by its position error e = D |cos| may take it off the
    silhouette: the ray passes the rim r cos^2 / 2 inside it, so cos^2 < 2 e / r (the square-root
    law that replaces 1/cos at tangency; for a unit sphere 1e5 away in fp32 that is cos < 0.3)."""
    ids = np.asarray(ids)
    out = (ids >= 0) & (cos < SILHOUETTE_COS)
    if depth_tolerance is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            out |= (ids >= 0) & (cos * cos < 2 * depth_tolerance * cos / radius)
    return out


def near_ties(truth: dict, tolerance) -> np.ndarray:
    """The one near-tie rule: the oracle's second-nearest surface lies within the sum of both
    surfaces' depth tolerances of the nearest (each may be off by its own, at its own incidence).
    truth: oracle.trace's result with "second"; tolerance(t, ids, cos): the depth tolerance."""
    nearest, second = truth["depth"], truth["second"]
    both = tolerance(nearest, truth["id"], truth["cos"]) + tolerance(second, truth["second_id"], truth["second_cos"])
    with np.errstate(invalid="ignore"):  # inf - inf where nothing is hit
        return np.isfinite(nearest) & (second - nearest <= both)


def at_edges(scene: Scene, origins, directions, hits, reach) -> np.ndarray:
    """Rays that one of ``hits`` ((ids, depth) pairs: the oracle's, an engine's) sees at an edge
    or a silhouette of the shape it hits, where a ray moved by its position error ``reach`` (per
    ray, scene units: the depth tolerance times |cos|) may go either way: the hit point within
    reach / |cos| of an edge of its shape (a rim, a border, a box's edge), or a grazing hit by
    the silhouette rule at its own incidence. Both sides are looked at, so a ray that one side
    sees and the other misses is found from either; the first of ``hits`` is the reference, the
    others count where they hit another shape than it."""
    origins = np.broadcast_to(np.asarray(origins, np.float64), np.shape(directions))
    out = np.zeros(np.shape(directions)[:-1], bool)
    reach = np.broadcast_to(reach, out.shape)
    first = np.asarray(hits[0][0])
    for k, (ids, depth) in enumerate(hits):
        ids = np.asarray(ids)
        depth = np.asarray(depth, np.float64)
        # another side's hit point tells something only where it hits another shape (a far
        # float32 hit point is too coarse to place on the surface: its own normal would be noise)
        other = (ids != first) if k else np.ones(ids.shape, bool)
        looked_at = np.where(np.isfinite(depth) & other, ids, -1).ravel()
        flat_out, flat_o, flat_d = out.reshape(-1), origins.reshape(-1, 3), directions.reshape(-1, 3)
        flat_depth, flat_reach = depth.reshape(-1), reach.reshape(-1)
        for index, mine in oracle.by_shape(looked_at):  # one group per shape hit, not a pass per shape
            shape = scene.shapes[index]
            points = flat_o[mine] + flat_depth[mine][:, None] * flat_d[mine]
            cos = np.abs(np.einsum("ij,ij->i", shape.oracle_normal(points), flat_d[mine]))
            grazing = silhouettes(np.zeros(len(cos)), cos, flat_reach[mine] / cos, shape.silhouette_radius())
            flat_out[mine] |= grazing | (shape.edge_distance(points) <= flat_reach[mine] / np.maximum(cos, SILHOUETTE_COS))
    return out


# -- a render against the oracle -------------------------------------------------------------------
def reference(scene: Scene, truth: dict | None = None) -> dict:
    """The float64 images plus what the error model needs: |cos incidence|, the second-nearest
    distance, the normal's conditioning and the silhouettes. truth: the oracle's trace of these
    pixels with "second", if already at hand (the same geometry)."""
    origins, directions = oracle.camera_rays(scene)
    ref = dict(truth) if truth is not None else oracle.trace(scene, origins, directions,
                                                             aovs=("depth", "normal", "id", "second"))
    cos = oracle.incidence_cosine(scene, directions, ref["id"], ref["normal"])
    ref["cos"] = cos
    # how far the float64 reference's own rounding (2^-53 of the ray's length and of the world
    # coordinates) moves a normal: (t + |origin|) / r, r the shape's radius of curvature
    reach = np.where(np.isfinite(ref["depth"]), ref["depth"], 0.0) + np.linalg.norm(origins, axis=-1)
    ref["normal_condition"] = np.where(ref["id"] >= 0, reach / curvature_radii(scene)[np.maximum(ref["id"], 0)], 0.0)
    ref["silhouette"] = silhouettes(ref["id"], cos)
    ref["origins"], ref["directions"] = origins, directions
    ref["scene"] = scene
    return ref


def render_reach(scene: Scene, t, ids, directions, precision: str) -> np.ndarray:
    """The sideways position error of pyclray's render rays at their hits (scene units), which
    decides silhouettes and edges. The render works in the camera's frame, where every coordinate
    keeps its own relative precision (docs/exactness.md, "Numerical design"): a ray's sideways error is eps
    times the sideways size of the coordinates involved (the hit's and the anchor's distances from
    the optical axis), not eps t; plus the oracle's own eps64 (t + W)."""
    eye = np.asarray(scene.camera.eye, np.float64)
    w = scene.camera.basis()[2]
    t = np.where(np.isfinite(t), t, 0.0)
    hit = t[..., None] * directions
    anchor = anchors(scene, eye)[np.maximum(ids, 0)] - eye

    def sideways(v):
        return np.linalg.norm(v - np.einsum("...k,k", v, w)[..., None] * w, axis=-1)

    world = np.linalg.norm(eye) + np.linalg.norm(anchor + eye, axis=-1)
    return K_ORACLE * (EPSILON[precision] * (sideways(hit) + sideways(anchor)) + ORACLE_EPSILON * (t + world))


def judged_pixels(images: dict, ref: dict, engine: str = "fp32") -> dict:
    """The masks of pixels set apart for this engine ("fp32", "fp64": pyclray's render; anything
    else: Mitsuba): silhouettes (by its position error), near ties (by its depth tolerance) and
    edges (within its position error, seen from the oracle's hit or the engine's)."""
    scene = ref["scene"]

    def depth_tolerance(t, ids, cos):
        if engine in EPSILON:
            return pyclray_tolerances(scene, {"depth": t, "id": ids}, cos, ref["origins"], engine, scene.camera.eye)[0]
        return mitsuba_tolerances(scene, t, ids, cos, cameras=True)[0]

    near_tie = near_ties(ref, depth_tolerance)
    t = np.where(np.isfinite(ref["depth"]), ref["depth"], 0.0)
    hits = [(ref["id"], ref["depth"])]
    if "id" in images and "depth" in images:
        ours = np.asarray(images["depth"], np.float64)
        hits.append((images["id"], ours))
        t = np.maximum(t, np.where(np.isfinite(ours), ours, 0.0))
    if engine in EPSILON:
        reach = render_reach(scene, t, ref["id"], ref["directions"], engine)
    else:
        reach = depth_tolerance(t, ref["id"], ref["cos"]) * ref["cos"]
    radius = silhouette_radii(scene)[np.maximum(ref["id"], 0)]
    with np.errstate(invalid="ignore", divide="ignore"):
        silhouette = silhouettes(ref["id"], ref["cos"], reach / ref["cos"], radius)
    edge = at_edges(scene, ref["origins"], ref["directions"], hits, reach)
    return {"silhouette": silhouette, "near_tie": near_tie, "edge": edge}


def compare(images: dict, ref: dict, exclude=None, engine: str = "fp32") -> dict:
    """Errors of a render against the reference, on the pixels that are neither silhouettes nor
    near-ties nor at edges (by ``engine``'s tolerance, see judged_pixels) nor in ``exclude``:
    depth in float32 ulps of t times |cos|, relative depth error, normal error (Euclidean) times
    |cos|, id mismatches, and counts of what was left out."""
    masks = judged_pixels(images, ref, engine)
    excluded = masks["silhouette"] | masks["near_tie"] | masks["edge"]
    if exclude is not None:
        excluded = excluded | exclude
    judged = ~excluded
    out = {
        "pixels": int(judged.sum()),
        "silhouette": int(masks["silhouette"].sum()),
        "near_tie": int((masks["near_tie"] & ~masks["silhouette"]).sum()),
        "edge": int((masks["edge"] & ~masks["silhouette"] & ~masks["near_tie"]).sum()),
    }
    if "id" in images:
        out["id_mismatch"] = int(((images["id"] != ref["id"]) & judged).sum())
        same = judged & (images["id"] == ref["id"]) & (ref["id"] >= 0)
    else:  # no id image: a hit where the reference misses, or the reverse, is the mismatch
        hits = np.isfinite(np.asarray(images["depth"], np.float64))
        out["id_mismatch"] = int(((hits != (ref["id"] >= 0)) & judged).sum())
        same = judged & (ref["id"] >= 0) & hits
    cos = ref["cos"][same]
    if "depth" in images:
        test = np.asarray(images["depth"], np.float64)
        miss_ok = judged & (ref["id"] < 0)
        out["miss_mismatch"] = int((np.isfinite(test) & miss_ok).sum())
        error = np.abs(test[same] - ref["depth"][same])
        ulps = error / ulp32(ref["depth"][same]) * cos
        relative = error / ref["depth"][same]
        raw = error / ulp32(ref["depth"][same])
        out["depth_ulps_raw_max"] = float(raw.max()) if raw.size else 0.0
        out["depth_ulps_max"] = float(ulps.max()) if ulps.size else 0.0
        out["depth_ulps_p99"] = float(np.percentile(ulps, 99)) if ulps.size else 0.0
        out["depth_rel_max"] = float(relative.max()) if relative.size else 0.0
        out["depth_rel_cos_max"] = float((relative * cos).max()) if relative.size else 0.0
    if "normal" in images:
        test = np.asarray(images["normal"], np.float64)
        error = np.linalg.norm(test[same] - ref["normal"][same], axis=-1)
        out["normal_max"] = float(error.max()) if error.size else 0.0
        out["normal_cos_max"] = float((error * cos).max()) if error.size else 0.0
        out["normal_cos_p99"] = float(np.percentile(error * cos, 99)) if error.size else 0.0
        # scaled by the normal's conditioning max(1, (t + |origin|) / r): what the float64
        # reference's own rounding moves a far or far-off curved shape's normal by
        scaled = error * cos / np.maximum(1.0, ref["normal_condition"][same])
        out["normal_conditioned_max"] = float(scaled.max()) if error.size else 0.0
    return out


def meets_targets(result: dict, precision: str) -> bool:
    """Whether a compare() result of pyclray at this precision meets the stability targets."""
    if precision == "fp64":
        return (result["depth_rel_cos_max"] <= FP64_DEPTH_RELATIVE and result["normal_conditioned_max"] <= FP64_NORMAL
                and result["id_mismatch"] == 0 and result["miss_mismatch"] == 0)
    return (result["depth_ulps_max"] <= FP32_DEPTH_ULPS and result["normal_cos_max"] <= FP32_NORMAL
            and result["id_mismatch"] == 0 and result["miss_mismatch"] == 0)


# -- closest points --------------------------------------------------------------------------------
def closest_tolerances(points, truth: dict, precision: str) -> dict:
    """How far closest_points may be from the float64 oracle's (truth: oracle.closest_points). Both
    compute in float64 from the point as given and the shapes' float64 geometry, so the distance
    errs by a few eps64 of the coordinates involved on each side: K_ORACLE eps64 (|p| + |q| + d) twice
    (q the nearest point, d the distance). The position is that, plus its rounding to the precision
    (eps |q|). A normal is unit and exact up to the position's error over the surface's curvature
    radius; where the nearest point is ambiguous (two surfaces within the distance's tolerance, a
    box's edge, a point on a sphere's centre) the tests judge the distance alone."""
    points = np.asarray(points, np.float64)
    position = np.nan_to_num(truth["position"])
    size = np.linalg.norm(points, axis=-1) + np.linalg.norm(position, axis=-1) + truth["distance"]
    distance = 2 * K_ORACLE * ORACLE_EPSILON * size
    return {"distance": distance,
            "position": distance + K_ORACLE * EPSILON[precision] * np.linalg.norm(position, axis=-1)}
