"""A LiDAR scan (pyclray.scan, Tracer.scan): every beam of every column cast as a float64 ray from
the sensor's origin through the cast query (engine/queries/cast.py), so that each range is held to
the error model as any cast's depth; returns outside the sensor's range limits made misses; the
range image and the point cloud assembled on the host.

A sweeping scan (``sweep = true`` in an animated scene) fires each column at its own time: every
column is cast once at the shapes no animation moves (their handle kept: prepared once) and, for each
time slice in which a column's beams may meet a moving shape's box, those columns at the moving
shapes alone (a small handle updated from slice to slice), each beam keeping the nearer hit. A moving
sensor only moves the rays (each column's origin and directions from the sensor's pose at its time):
a scan with a moving sensor among still shapes is one cast.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...model.animation import scene_at, tracks_in
from ...model.errors import RequestError
from ...model.lidar import Lidar
from ...model.lidar.sensor import rotated
from ...model.scene import checked_time
from ...model.shapes.base import labels_of


class Scan(dict):
    """A LiDAR scan: name -> numpy array (docs/lidar.md).

    The range image, (beams, columns): ``range`` (distance from the sensor along the beam, +inf on a
    miss; float32, float64 with precision "fp64"), ``id`` and ``label`` (int32, -1 on a miss),
    ``normal`` ((beams, columns, 3) unit world normal, 0 on a miss) and ``position`` ((beams, columns,
    3) float64 world hit point, 0 on a miss). The point cloud, one row per hit in row-major order
    (ring, then column): ``points`` ((M, 3) float64, in the sensor's frame at the column's firing
    time: x forward, y left, z up), ``points_world`` ((M, 3) float64, the world's), ``ring`` and
    ``column`` (int32: the hit's row and column), ``point_range`` (M,). Per row and column:
    ``elevation`` (beams,) and ``azimuth`` (columns,) in degrees, ``time`` (columns,) float64, each
    column's firing time in seconds.

    Attributes: ``lidar`` (the sensor, at the scan's time t), ``pose`` (its 4x4 sensor-to-world at
    t), ``t``, ``precision``, ``device``."""

    def __init__(self, arrays, *, lidar: Lidar, pose, t: float, precision: str, device: str):
        super().__init__(arrays)
        self.lidar, self.pose, self.t = lidar, pose, t
        self.precision, self.device = precision, device

    def __repr__(self) -> str:
        shapes = ", ".join(f"{k}: {v.dtype}{list(v.shape)}" for k, v in self.items())
        return f"Scan({shapes}; {self.precision} on {self.device})"


def scene_lidar(scene, lidar) -> tuple[Lidar, int | None]:
    """(the sensor, its index in scene.lidars or None): ``lidar`` a Lidar (one of the scene's, by
    value, is that one: its animation applies), the name of one of the scene's, or None (the scene's
    first); anything else is a RequestError."""
    if lidar is None:
        if not scene.lidars:
            raise RequestError("lidar: the scene has no [lidar] or [[lidars]]; give a pyclray.Lidar")
        return scene.lidars[0], 0
    if isinstance(lidar, str):
        for index, mine in enumerate(scene.lidars):
            if mine.name == lidar:
                return mine, index
        names = ", ".join(repr(mine.name) for mine in scene.lidars) or "none"
        raise RequestError(f"lidar: no sensor named {lidar!r} in the scene (its lidars: {names})")
    if not isinstance(lidar, Lidar):
        raise RequestError(f"lidar: expected a pyclray.Lidar, the name of one of the scene's or None, got "
                           f"{type(lidar).__name__}")
    for index, mine in enumerate(scene.lidars):
        if mine is lidar or mine == lidar:
            return mine, index
    return lidar, None


def scan_time(scene, t) -> float:
    """The time a scan starts at: t (seconds, >= 0) of an animated scene, or 0 for None; a time for a
    static scene is a RequestError (a mistake, not ignored)."""
    if t is None:
        return 0.0
    if scene.animation is None:
        raise RequestError("time: the scene has no [animation]; a time scans an animated scene")
    try:
        return checked_time(t)
    except RequestError as error:
        raise RequestError(f"time: {str(error).removeprefix('t: ')}") from None


def _lidar_at(lidar: Lidar, tracks, t: float, interpolation: str) -> Lidar:
    """The sensor with its animated keys at time t (its tracks' values; a SceneError names the key)."""
    if not tracks:
        return lidar
    return dataclasses.replace(lidar, **{track.key: track.value_at(t, interpolation) for track in tracks})


def _split_sweep(scene, handles, runs, step_times, column_step, origins_per_column, world_directions, poses,
                 lidar_tracks, range_max, interpolation):
    """(depth, normal, ids) of a sweep cast as run_scan's handles say: the still shapes once, the
    moving ones per time slice, the nearer hit of each beam."""
    from ...model.scene import Scene

    kept, new = handles
    moving_ids, still_shapes = scene.still_shapes
    skip = set(moving_ids)
    still_ids = np.array([i for i in range(len(scene.shapes)) if i not in skip], np.int64)
    moving_ids = np.array(moving_ids, np.int64)
    tmax = _cast_limit(range_max)
    columns = world_directions.shape[1]
    origins_all = poses[0, :3, 3] if not lidar_tracks else np.broadcast_to(origins_per_column, world_directions.shape)
    # every column at the still shapes, once (their handle kept: the still scene is prepared once)
    still_handle = kept(Scene(scene.camera, scene.image, still_shapes))
    still = still_handle.cast(origins_all, world_directions, aovs=("depth", "normal", "id"), tmax=tmax)
    depth, normal = still["depth"], still["normal"]
    ids = np.where(still["id"] >= 0, np.append(still_ids, -1)[still["id"]], -1).astype(np.int32)
    # the columns whose beams may meet a moving shape at their own time (no other time matters now)
    boxes = _moving_boxes(scene, tracks_in(scene, "shapes"), [float(step_times[start]) for start, _ in runs],
                          interpolation)
    if boxes is None:
        moving = np.ones(columns, bool)
    else:
        run_of_step = np.repeat(np.arange(len(runs)), [stop - start for start, stop in runs])
        moving = _beams_meet_box(origins_per_column, world_directions, boxes[run_of_step[column_step]])
    handle = None
    try:
        for start, stop in runs:
            columns_of_run = np.flatnonzero((column_step >= start) & (column_step < stop) & moving)
            if not len(columns_of_run):
                continue
            frame = scene_at(scene, float(step_times[start]), lazy=True)
            view = Scene(scene.camera, scene.image, tuple(frame.shapes[i] for i in moving_ids))
            if handle is None:
                handle = new(view)
            else:
                handle.update(view)  # the moving shapes moved in place
            directions = world_directions[:, columns_of_run]
            origins = poses[0, :3, 3] if not lidar_tracks else \
                np.broadcast_to(origins_per_column[columns_of_run], directions.shape)
            hits = handle.cast(origins, directions, aovs=("depth", "normal", "id"), tmax=tmax)
            hit_ids = np.where(hits["id"] >= 0, np.append(moving_ids, -1)[hits["id"]], -1)
            # the nearer of the two hits; on a tie the lower id (one cast of every shape keeps that one)
            before, before_ids = depth[:, columns_of_run], ids[:, columns_of_run]
            nearer = (hit_ids >= 0) & ((hits["depth"] < before) | ((hits["depth"] == before) & (hit_ids < before_ids)))
            depth[:, columns_of_run] = np.where(nearer, hits["depth"], before)
            ids[:, columns_of_run] = np.where(nearer, hit_ids, before_ids)
            normal[:, columns_of_run] = np.where(nearer[..., None], hits["normal"], normal[:, columns_of_run])
    finally:
        if handle is not None:
            handle.close()
    return depth, normal, ids, still_handle


def _moving_boxes(scene, shape_places, times, interpolation):
    """(len(times), 2, 3) float64 [lo, hi] holding every animated shape at each of these times (the
    starts of the runs: between them the shapes hold still), or None where one has no bounds (a
    plane)."""
    tracks_of: dict[int, list] = {}
    for index, track in shape_places:
        tracks_of.setdefault(index, []).append(track)
    lo, hi = np.full((len(times), 3), np.inf), np.full((len(times), 3), -np.inf)
    for index, tracks in tracks_of.items():
        shape = scene.shapes[index]
        if not shape.bounded:
            return None
        moved = [dataclasses.replace(shape, **{track.key: track.value_at(when, interpolation) for track in tracks})
                 for when in times]
        bounds = type(shape).world_bounds(moved).reshape(len(times), -1, 2, 3)  # every time's primitives at once
        lo, hi = np.minimum(lo, bounds[:, :, 0].min(axis=1)), np.maximum(hi, bounds[:, :, 1].max(axis=1))
    return np.stack([lo, hi], axis=1)


def _beams_meet_box(origins, directions, boxes) -> np.ndarray:
    """(columns,) bool: whether any beam of a column (origins (columns, 3), directions (beams,
    columns, 3)) meets its box (boxes (columns, 2, 3)), grown by a margin far beyond the rounding of
    the casts' hits (a slab test in float64; a column it keeps is only cast more often, never
    wrongly)."""
    size = float(np.max(np.abs(boxes))) + float(np.max(np.abs(origins)))
    margin = 1e-5 * size + 1e-9  # float32 rounds at 6e-8 of these sizes: a hundred times that
    lo, hi = boxes[:, 0] - margin, boxes[:, 1] + margin
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = 1.0 / directions
        near = (lo - origins)[None] * inverse
        far = (hi - origins)[None] * inverse
    # a zero component: the beam is within the slab for every t, or for none
    inside = ((origins >= lo) & (origins <= hi))[None]
    entry = np.where(directions == 0, np.where(inside, -np.inf, np.inf), np.fmin(near, far))
    leave = np.where(directions == 0, np.where(inside, np.inf, -np.inf), np.fmax(near, far))
    meets = (entry.max(axis=-1) <= leave.min(axis=-1)) & (leave.min(axis=-1) >= 0.0)
    return meets.any(axis=0)


def run_scan(tracer, scene, lidar, t, handles) -> Scan:
    """The scan of ``lidar`` (see scene_lidar) in ``scene`` (its shapes are the handle's, or an
    animated scene whose static shapes or frames are) at time t (an animated scene's; None: 0), on a
    handle whose device can cast (engine/tracer.py). A scan in one time slice leaves the handle
    prepared for the scene at t (a frame of an animated scene); a sweep among moving shapes leaves it
    as it was.

    tracer: the handle, or None where handles give it (kept(the scene at t)). handles: (kept, new):
    kept(scene) a handle of these shapes kept between calls (the module-level functions' cache, or
    Tracer.scan's handle of its still shapes), new(scene) a new handle, closed after the scan: a sweep
    whose shapes move casts every column once at the shapes no animation moves (a kept handle: a
    large still scene is prepared once) and the columns that may meet a moving shape at the moving
    shapes alone, updated from time slice to time slice (a handle of a few shapes: each update and
    cast costs what those shapes cost), each beam's nearer hit kept (the lower id on a tie, as one
    cast of every shape keeps)."""
    lidar, index = scene_lidar(scene, lidar)
    t = scan_time(scene, t)
    animation = scene.animation
    interpolation = animation.interpolation if animation is not None else "linear"
    lidar_tracks = [track for i, track in tracks_in(scene, "lidars") if i == index] if index is not None else []
    shape_places = tracks_in(scene, "shapes")  # ((shape index, track), ...)
    shape_tracks = [track for _, track in shape_places]
    columns = lidar.columns
    sensor_directions = lidar.directions()  # (beams, columns, 3), the sensor's frame
    if animation is not None and lidar.sweep:
        step_times = lidar.step_times(t)
        column_step = lidar.column_steps()
    else:
        step_times = np.array([t])
        column_step = np.zeros(columns, np.int64)
    # the sensor at each step's time: each column's origin and world directions
    poses = lidar.poses_at(lidar_tracks, step_times, interpolation)
    first = _lidar_at(lidar, lidar_tracks, t, interpolation)  # the sensor at the scan's start
    # the runs of steps whose shapes are the same (their animated values equal): one update and one cast each
    if shape_tracks and len(step_times) > 1:
        states = [tuple(track.value_at(float(when), interpolation) for track in shape_tracks) for when in step_times]
        starts = [k for k in range(len(states)) if k == 0 or states[k] != states[k - 1]]
    else:
        starts = [0]
    runs = list(zip(starts, starts[1:] + [len(step_times)]))
    origins_per_column = poses[column_step, :3, 3]  # (columns, 3)
    # (beams, columns, 3); a sensor that does not move: its one rotation for every column (the same bits)
    world_directions = rotated(poses[column_step, :3, :3] if lidar_tracks else poses[:1, :3, :3], sensor_directions)
    if len(runs) > 1:  # shapes move during the revolution: the still ones once, the moving ones per slice
        depth, normal, ids, still = _split_sweep(scene, handles, runs, step_times, column_step, origins_per_column,
                                                 world_directions, poses, lidar_tracks, lidar.range[1], interpolation)
        return _assembled(scene, lidar, first, t, still, depth, normal, ids, step_times, column_step, poses,
                          origins_per_column, world_directions, sensor_directions)
    # one cast of every column at the scene at t (its frame, for an animated scene)
    frame = scene if animation is None else scene_at(scene, t, lazy=True)
    if tracer is None:  # the kept handle of the whole scene (an earlier frame's, updated)
        tracer = handles[0](frame)
    elif animation is not None:
        tracer.update(frame)
    range_max = lidar.range[1]
    origins = poses[0, :3, 3] if not lidar_tracks else np.broadcast_to(origins_per_column, world_directions.shape)
    hits = tracer.cast(origins, world_directions, aovs=("depth", "normal", "id"), tmax=_cast_limit(range_max))
    return _assembled(scene, lidar, first, t, tracer, hits["depth"], hits["normal"], hits["id"], step_times,
                      column_step, poses, origins_per_column, world_directions, sensor_directions)


def _cast_limit(range_max: float):
    """cast's tmax for returns up to range_max, inclusive as the scan's [min, max] (cast counts hits
    below its tmax: the next float64 above range_max); None for no limit."""
    return None if math.isinf(range_max) else float(np.nextafter(range_max, np.inf))


def _assembled(scene, lidar, first, t, handle, depth, normal, ids, step_times, column_step, poses, origins_per_column,
               world_directions, sensor_directions) -> Scan:
    """The Scan of the casts' range image: the range limits applied, the labels, the positions and
    the point cloud."""
    range_min, range_max = lidar.range
    # returns outside [min, max] are misses (a return nearer than min hides what is behind it, as a
    # real sensor's blind zone does)
    outside = (ids >= 0) & ~((depth >= range_min) & (depth <= range_max))
    depth[outside], ids[outside], normal[outside] = np.inf, -1, 0
    hit = ids >= 0
    labels = np.append(labels_of(scene.shapes), np.int32(-1))[ids]
    range64 = np.where(hit, depth.astype(np.float64), 0.0)
    position = np.where(hit[..., None], origins_per_column[None] + range64[..., None] * world_directions, 0.0)
    ring, column = np.nonzero(hit)
    arrays = {
        "range": depth, "id": ids, "label": labels, "normal": normal, "position": position,
        "points": range64[ring, column, None] * sensor_directions[ring, column],
        "points_world": position[ring, column], "ring": ring.astype(np.int32), "column": column.astype(np.int32),
        "point_range": depth[ring, column],
        "elevation": lidar.elevation_angles.copy(), "azimuth": lidar.azimuth_angles,
        "time": step_times[column_step].astype(np.float64),
    }
    return Scan(arrays, lidar=first, pose=poses[0].copy(), t=t, precision=handle.precision,
                device=handle.ctx.device.name.strip())
