"""The data sets' images derived on the host after the kernel, from the hit point (`position`), the
shape (`id`) and its primitive: `object_coordinates`, the hit point in its shape's own space
(Shape.object_poses), and `flow`, the forward optical flow in pixels.

Flow is exact per pixel, not estimated from images: the hit point X in its shape's frame at t is
carried by the shape's rigid motion to the next frame (t + 1/fps: world_from_object there, the same
X) and projected by the camera there; the flow is that projection minus the projection of the hit
point now (which is the pixel's centre up to the hit point's rounding), computed in float64 from the
float32 (fp32) hit point, so that it does not depend on where K puts pixel centres. A point that
goes behind the next camera has flow NaN; a miss has (0, 0)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model.errors import RequestError

MOTION_AOVS = ("object_coordinates", "flow")


@dataclass(frozen=True)
class Motion:
    """What flow needs beyond the view: the scene's shapes at the next frame's time (the same shapes
    moved: shapes[i] is shape i then) and the camera there."""

    shapes: tuple
    camera: object


def _object_points(shapes, ids, primitives, points) -> np.ndarray:
    """(N, 3) float64: world points hit on shapes[ids] (primitive primitives) in those shapes' own
    frames; world coordinates for a shape without a frame."""
    out = np.array(points, np.float64)
    for shape_id in np.unique(ids):
        frames = shapes[shape_id].object_poses()
        if frames is None:
            continue
        chosen = ids == shape_id
        inverse = np.linalg.inv(frames)
        if len(inverse) == 1:
            out[chosen] = points[chosen] @ inverse[0, :3, :3].T + inverse[0, :3, 3]
        else:
            each = inverse[primitives[chosen]]
            out[chosen] = np.einsum("nij,nj->ni", each[:, :3, :3], points[chosen]) + each[:, :3, 3]
    return out


def _world_points(shapes, ids, primitives, local) -> np.ndarray:
    """The inverse of _object_points with these shapes (at another time)."""
    out = np.array(local, np.float64)
    for shape_id in np.unique(ids):
        frames = shapes[shape_id].object_poses()
        if frames is None:
            continue
        chosen = ids == shape_id
        if len(frames) == 1:
            out[chosen] = local[chosen] @ frames[0, :3, :3].T + frames[0, :3, 3]
        else:
            each = frames[primitives[chosen]]
            out[chosen] = np.einsum("nij,nj->ni", each[:, :3, :3], local[chosen]) + each[:, :3, 3]
    return out


def _project(camera, width: int, height: int, points) -> tuple[np.ndarray, np.ndarray]:
    """(pixel coordinates (N, 2), depth along the optical axis (N,)) of world points: the camera
    model's own projection (CameraModel.project: a pinhole's K and pose, an orthographic camera's
    plane)."""
    found = camera.project(points, width, height)
    if found is None:
        raise RequestError(f"flow: needs a pinhole camera (pyclray.Camera without distortion) or an orthographic one, "
                           f"not this {camera.model} camera"
                           f"{' with a distortion' if getattr(camera, 'distortion', None) is not None else ''}")
    return found


def with_motion(view, images: dict, motion: Motion | None, asked) -> dict:
    """images with object_coordinates and flow where asked (see the module's docstring). motion:
    the next frame, or None for a scene that does not move (flow 0)."""
    wanted = [name for name in MOTION_AOVS if name in asked]
    if not wanted:
        return images
    ids = images["id"]
    real = images["position"].dtype
    hit = ids >= 0
    hit_ids, primitives = ids[hit], images["primitive"][hit]
    points = images["position"][hit].astype(np.float64)
    shapes = view.shapes
    out = dict(images)
    local = _object_points(shapes, hit_ids, primitives, points)
    if "object_coordinates" in wanted:
        coordinates = np.zeros(ids.shape + (3,), real)
        coordinates[hit] = local
        out["object_coordinates"] = coordinates
    if "flow" in wanted:
        flow = np.zeros(ids.shape + (2,), real)
        if motion is not None:
            width, height = view.image.width, view.image.height
            now, _ = _project(view.camera, width, height, points)
            moved = _world_points(motion.shapes, hit_ids, primitives, local)
            then, z = _project(motion.camera, width, height, moved)
            flow[hit] = np.where((z > 0)[:, None], then - now, np.nan)
        out["flow"] = flow
    return out
