"""The module-level functions (pyclray.render, render_views, render_animation, cast, occluded,
clear_cache): thin wrappers over one small cache of scene handles (engine/tracer.py), so that calls
on the same shapes prepare them once.

The cache is the only engine state that outlives a call: at most TRACERS_MAX handles and about
TRACERS_BYTES of memory, the least recently used dropped first, each found by (device, shapes tuple,
precision). An entry holds its tuple, so the tuple's id() cannot be reused while it is cached. A
moved camera keeps the scene's tuple (dataclasses.replace), so it finds the same handle. An
animation's frame (a tuple that pyclray.model.frames says was made from another by changing a few
shapes) takes over the handle of that other tuple and updates it in place (Tracer.refit).
"""
from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np

from ..model.animation import scene_at
from ..model.aovs import AOVS, CAST_AOVS, RENDER_AOVS
from ..model.errors import RequestError, SceneError
from ..model.frames import derivation
from ..model.loader import as_scene
from ..model.scene import Scene, check_shape_count, checked_time
from .opencl.device import context_for
from .queries.cast import check_cast_device
from .queries.motion import Motion
from .queries.render import with_camera
from .queries.requests import Frame, check_precision, check_request
from .tracer import Tracer

TRACERS_MAX = 8
TRACERS_BYTES = 1 << 30
_tracers: OrderedDict = OrderedDict()
_lock = threading.Lock()


def clear() -> None:
    """Drop every cached scene handle (their device memory goes with them once no call uses them;
    handles from pyclray.prepare are the caller's and stay)."""
    with _lock:
        _tracers.clear()


def tracer_for(scene: Scene, ctx, precision: str) -> Tracer:
    """The cached handle of the scene's shapes on this device at this precision: made at the first
    call; an animation's frame updates the handle of the tuple it was made from (see the module's
    docstring)."""
    shapes = scene.shapes
    key = (ctx.device.int_ptr, id(shapes), precision)
    with _lock:
        tracer = _tracers.get(key)
        if tracer is not None and tracer.shapes is shapes:
            _tracers.move_to_end(key)
            return tracer
    derived = derivation(shapes)
    if derived is not None:
        base = derived[0]
        with _lock:
            candidates = [(k, t) for k, t in _tracers.items()
                          if t.prepared.base is base and k[0] == ctx.device.int_ptr and t.precision == precision]
        if candidates:  # refitted in place, or prepared anew where a refit cannot do (Tracer.update)
            old_key, candidate = candidates[0]
            candidate.update(scene)
            with _lock:
                _tracers.pop(old_key, None)
                _tracers[key] = candidate
            return candidate
    tracer = Tracer(scene, ctx.device, precision)
    if derived is not None:  # the base its changes are from, for the next frame's update
        tracer.prepared.base, tracer.prepared.dirty = derived[0], set(derived[1])
    with _lock:
        _tracers[key] = tracer
        while len(_tracers) > 1 and (len(_tracers) > TRACERS_MAX or
                                     sum(t.nbytes for t in _tracers.values()) > TRACERS_BYTES):
            _tracers.popitem(last=False)
    return tracer


# -- renders -------------------------------------------------------------------------------------
def render(scene: Scene, aovs=AOVS, precision: str = "fp32", device=None, window=None, acceleration: str = "auto",
           camera=None, time=None) -> Frame:
    """Render the scene's depth, normal and id images (see Frame) with one ray per pixel centre.

    scene: a Scene or the path of a scene file; geometry beyond the precision's range is a
    SceneError (see scene.check_renderable).
    aovs: which images (a subset of depth, normal, id, zdepth, position, shaded, primitive, label: only those
    are computed; shaded casts shadow rays where the scene's [shading] asks for them; label, each
    shape's label, is looked up from the id image);
    precision: "fp32" or "fp64"; device: a pyopencl Device, a selector string, or None (default);
    window: (x0, y0, width, height), a part of the image (column x0 and row y0 from the top left),
    rendered into images of that size, the same pixels as in the whole image; default: all of it;
    acceleration: how the kernel skips the shapes a ray cannot hit, "tiles" (screen-space tile
    lists), "bvh" (the bounding volume hierarchy) or "auto" (tiles for a few shapes, else the BVH).
    The images do not depend on it, bit for bit.
    camera: a pyclray.Camera to render the scene's shapes from instead of its own (the same as
    rendering ``dataclasses.replace(scene, camera=camera)``).
    time: render the animated scene at time t (seconds): ``scene.at(t)``, and its `flow` to the next
    frame, t + 1/fps (the shapes and camera there; a given ``camera`` stays). Without a time an
    animated scene's flow is an error; a static scene's flow is 0.

    The scene's shapes are prepared on the device once and kept (a cached scene handle, see
    pyclray.prepare for one of your own): a view from another camera uploads the camera only,
    whatever the number of shapes.
    """
    return _start(scene, aovs, precision, device, window, acceleration, camera, time)()


def _start(scene, aovs, precision, device, window=None, acceleration="auto", camera=None, time=None):
    """render's checks, in their order, and its start on the cached handle (Tracer.start_render)."""
    scene = as_scene(scene)
    ctx = context_for(device)
    asked = check_request(aovs, precision, ctx, RENDER_AOVS)
    scene, motion = _at_time(scene, time, camera, "flow" in asked)
    if camera is not None:
        scene = with_camera(scene, camera)
    return tracer_for(scene, ctx, precision).start_render(scene, aovs, window, acceleration, motion)


def _at_time(scene: Scene, time, camera, flow: bool):
    """(the scene at `time`, the next frame's Motion for flow or None)."""
    if time is None:
        if flow and scene.animation is not None:
            raise RequestError("flow: an animated scene's flow is to its next frame: give the time (render(..., time=t))")
        return scene, None
    if scene.animation is None:
        raise RequestError(f"time: the scene has no [animation] to be at time {time!r}")
    t = checked_time(time)
    motion = None
    if flow:
        following = scene_at(scene, t + 1.0 / scene.animation.fps)
        motion = Motion(following.shapes, camera if camera is not None else following.camera)
    return scene_at(scene, t, lazy=True), motion


def render_views(scene: Scene, cameras, aovs=AOVS, precision: str = "fp32", device=None, acceleration: str = "auto"):
    """Yield the Frame of each camera (a pyclray.Camera, or a Scene whose camera and image size are
    taken) in order: many views of one scene's shapes, prepared on the device once (a data set of
    depth, normal and id maps from hundreds of poses). Each frame is exactly
    ``render(scene, aovs, precision, device, camera=camera)``.

    The next view is enqueued before a frame is returned: the host's work for it (checks, camera,
    the per-view pass's launch) and the return of this one overlap the device's run of this one,
    and the device goes from one view's kernel to the next without waiting for the host. An error
    of a view is raised after the frames before it."""
    scene = as_scene(scene)
    ctx = context_for(device)
    check_request(aovs, precision, ctx, RENDER_AOVS)
    return tracer_for(scene, ctx, precision).views_of(scene, cameras, aovs, acceleration)


def render_animation(scene, aovs=AOVS, precision: str = "fp32", device=None, frames=None):
    """Yield (t, Frame) for each frame of the scene's animation: frame k at t = k / fps is
    exactly ``render(scene, aovs, precision, device, time=t)`` (``scene.at(t)``; its flow to frame k + 1). frames: the frame indices (a range
    or any iterable of ints; default all of them)."""
    animation = scene.animation
    if animation is None:
        raise SceneError("the scene has no [animation] table", file=scene.source)
    for k in range(animation.frame_count()) if frames is None else frames:
        t = animation.frame_time(k)
        # scene.at(t) with its shapes held as the animated scene's and the changes (O(K) work)
        yield t, render(scene, aovs=aovs, precision=precision, device=device, time=t)


# -- casts ---------------------------------------------------------------------------------------
def cast(scene: Scene, origins, directions, aovs=AOVS, precision: str = "fp32", device=None, tmax=None,
         tmin=0.0) -> Frame:
    """Cast arbitrary rays through the scene's shapes (the scene's camera and image are not used).

    origins: (..., 3) like directions, or one (3,) origin for every ray; directions: (..., 3), any
    non-zero length (float64 or float32, as given); tmax: None, one number or one per ray (shape
    (...)): hits farther than it are misses; tmin: one number >= 0 or one per ray: only hits beyond
    it count (each shape is tested from the ray's point at tmin on, in float64). aovs: any of depth,
    normal, id, position (the hit point, origin + depth times the unit direction, in float64 rounded
    once), label (the hit shape's label). Returns a Frame of per-ray arrays: depth (...) is the
    distance from the origin along the normalized direction (+inf on a miss), normal (..., 3), id (...).

    Each ray is traced on its own, from its float64 origin and direction: its result does not
    depend on the other rays of the batch, bit for bit, and its float32 depth and normal meet the
    render's error model for the ray as given (see kernels/rays.h). Needs cl_khr_fp64.
    Raises RequestError (a ValueError) for arrays of other shapes, rows that are not finite, zero directions, a
    tmax that is not > 0, and origins so far from the shapes that the precision overflows.
    """
    scene = as_scene(scene)
    check_shape_count(scene)
    ctx = context_for(device)
    check_request(aovs, precision, ctx, CAST_AOVS)
    check_cast_device(ctx)
    return tracer_for(scene, ctx, precision).cast(origins, directions, aovs, tmin=tmin, tmax=tmax)


def scan(scene: Scene, lidar=None, time=None, precision: str = "fp32", device=None):
    """A LiDAR scan (docs/lidar.md): every beam of every column of ``lidar`` cast from the sensor's
    origin as a float64 ray (exactly as pyclray.cast casts it: each range held to the error model),
    returns outside the sensor's range limits made misses. Returns a Scan: the range image
    (beams, columns) ``range``, ``id``, ``label``, ``normal``, ``position``, and the point cloud
    ``points`` (sensor frame), ``points_world``, ``ring``, ``column``, ``point_range``.

    lidar: a pyclray.Lidar, the name of one of the scene's [[lidars]], or None (the scene's first);
    time: the time (seconds) of an animated scene the revolution starts at (None: 0); a sensor with
    ``sweep = true`` fires column c at its own time (Lidar.step_times), the scene's shapes and the
    sensor moved to it, so the motion shows in the scan as in a real spinning sensor's."""
    scene = as_scene(scene)
    check_shape_count(scene)
    ctx = context_for(device)
    check_precision(precision, ctx)
    check_cast_device(ctx)
    from .queries.scan import run_scan

    # the handles: cached ones (an animated scene's at its frame, an earlier frame's handle updated; a
    # sweep's still shapes'), and a new one for a sweep's moving shapes
    handles = (lambda shapes: tracer_for(shapes, ctx, precision), lambda shapes: Tracer(shapes, ctx.device, precision))
    return run_scan(None, scene, lidar, time, handles)


def occluded(scene: Scene, origins, directions, tmax=None, precision: str = "fp32", device=None,
             tmin=0.0) -> np.ndarray:
    """Whether each ray hits any shape at a distance below tmax (None: any distance): a bool array
    of the rays' leading shape. The any-hit query of shadow rays: the search stops at the first
    hit found. The same rays, arguments and exactness as cast: occluded is true exactly where
    cast(..., tmax=tmax) finds a hit, up to hits within rounding of tmax."""
    scene = as_scene(scene)
    check_shape_count(scene)
    ctx = context_for(device)
    check_precision(precision)  # (fp64 on a device: the device check's matter, for casts)
    check_cast_device(ctx)
    return tracer_for(scene, ctx, precision).occluded(origins, directions, tmin=tmin, tmax=tmax)


# -- every hit -----------------------------------------------------------------------------------
def _ray_query_tracer(scene, precision, device) -> Tracer:
    scene = as_scene(scene)
    check_shape_count(scene)
    ctx = context_for(device)
    check_precision(precision, ctx)
    check_cast_device(ctx)
    return tracer_for(scene, ctx, precision)


def count_hits(scene: Scene, origins, directions, tmin=0.0, tmax=None, precision: str = "fp32",
               device=None) -> np.ndarray:
    """How many times each ray crosses the shapes' surfaces at a distance t with tmin < t < tmax:
    an int32 array of the rays' leading shape, without storing the hits. The same rays and
    arguments as cast (origins (..., 3) or one (3,), directions (..., 3), tmin and tmax one number
    or one per ray).

    Each crossing counts once: a ray through an edge or a vertex shared by triangles of a mesh
    counts one hit where it crosses the surface there, none or two where it only touches it (a tie
    rule in the ray's projected plane, as a rasterizer's top-left rule: kernels/mesh.cl), so that
    the parity of the count from a point is inside/outside of a closed mesh on every ray; an
    analytic shape counts its real crossings (a tangent ray: 0 or 2, never 1)."""
    return _ray_query_tracer(scene, precision, device).count_hits(origins, directions, tmin, tmax)


def all_hits(scene: Scene, origins, directions, tmin=0.0, tmax=None, aovs=("depth", "id", "primitive"),
             precision: str = "fp32", device=None) -> Frame:
    """Every hit along each ray at a distance t with tmin < t < tmax, nearest first: a mapping with
    offsets (int64, N + 1: the hits of ray k, the rays flattened in C order, are rows
    offsets[k]:offsets[k + 1]), ray (int64, the ray of each hit) and one array per AOV asked for,
    one row per hit: depth, id, primitive (the triangle's index in its mesh, the sphere's in its
    batch, 0 for other shapes), label, position, normal (the outward unit normal, never flipped),
    barycentric (a triangle's (u, v); 0, 0 for other shapes); position, normal and barycentric in
    float64 from the hit's point, rounded once. The hits are count_hits' (see there), each crossing
    once."""
    from .queries.hits import check_hit_aovs

    aovs = check_hit_aovs(aovs)
    return _ray_query_tracer(scene, precision, device).all_hits(origins, directions, tmin, tmax, aovs)



# -- closest points, distances, inside -------------------------------------------------------------
def _point_tracer(scene, precision: str, device) -> Tracer:
    """The cached handle for a points query (the checks of cast: a scene, a precision, a device with float64)."""
    scene = as_scene(scene)
    check_shape_count(scene)
    ctx = context_for(device)
    check_precision(precision)
    check_cast_device(ctx)
    return tracer_for(scene, ctx, precision)


def closest_points(scene: Scene, points, precision: str = "fp32", device=None) -> dict:
    """For each point (an array of shape (..., 3), float64 or float32 as given), the nearest point of
    any shape's surface. Returns a dict of arrays of the points' leading shape: ``position`` (..., 3)
    (float32, float64 with precision "fp64"; NaN where the scene has no shape), ``distance`` (float64,
    computed in float64 from the point as given; +inf with no shape), ``id`` (int32, -1 with no shape),
    ``primitive`` (int32: a mesh's triangle, a batch's sphere; 0 for a single shape), ``barycentric``
    (..., 2) (a triangle's (u, v): position = (1 - u - v) a + u b + v c; 0 for other shapes) and
    ``normal`` (..., 3) (the unit geometric normal of the nearest surface there, outward). An exact tie
    of distances goes to the lower id, then the lower primitive. Planes are unbounded: the distance
    to a plane is to its whole plane. Needs cl_khr_fp64. Bad points (another shape, NaN or inf) are
    a RequestError (a ValueError) naming the argument and the first bad row."""
    return _point_tracer(scene, precision, device).closest_points(points)


def distance(scene: Scene, points, precision: str = "fp32", device=None) -> np.ndarray:
    """The distance (float64) of each point to the nearest surface: closest_points' ``distance`` alone."""
    return _point_tracer(scene, precision, device).distance(points)


def signed_distance(scene: Scene, points, sign: str = "parity", precision: str = "fp32", device=None) -> np.ndarray:
    """The distance of each point to the nearest surface (float64), negative inside a solid: a
    sphere, a box, a capped cylinder, the half-space behind a plane, or a mesh by ``sign``: "parity"
    (a closed mesh, pyclray.Mesh.closed: the exact parity of one ray's crossings; open meshes have no
    inside) or "winding" (any mesh: its generalized winding number >= 1/2, for meshes with holes,
    self-intersections or several parts). Disks, rectangles and open cylinders have no inside. A point
    on a surface is at distance 0 and inside."""
    return _point_tracer(scene, precision, device).signed_distance(points, sign)


def occupancy(scene: Scene, points, sign: str = "parity", precision: str = "fp32", device=None) -> np.ndarray:
    """1 where a point is inside a solid or on a surface, else 0 (uint8, the points' leading shape):
    signed_distance's inside (see there for ``sign``)."""
    return _point_tracer(scene, precision, device).occupancy(points, sign)
