"""Where a data set's cameras stand: views on an orbit or a hemisphere around the scene's labelled
shapes, or the poses of a JSON file. Every camera is a pinhole camera from intrinsics (its K is the
scene camera's, ``camera.intrinsics(width, height)``: the data set follows whatever pixel convention
the camera model has) and a camera-to-world pose in OpenCV's axes (x right, y down, z forward).

A view's camera depends only on the options and its index (a hemisphere's view k draws from a
generator seeded with (seed, k)), so a resumed run, or one asking for more views, renders the same
views again."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...model.camera import Camera
from ...model.errors import RequestError

PLACEMENTS = ("hemisphere", "orbit", "poses")
DEFAULT_ELEVATION = (10.0, 80.0)  # degrees above the scene's horizon


@dataclass(frozen=True)
class Placement:
    """How the views are placed: "hemisphere" (random, seeded), "orbit" (evenly around the centre at
    the middle of the elevation range) or "poses" (a file's). radius: (min, max) distances from the
    centre (None: the scene camera's distance to it); elevation: (min, max) degrees."""

    kind: str = "hemisphere"
    radius: tuple[float, float] | None = None
    elevation: tuple[float, float] = DEFAULT_ELEVATION
    seed: int = 0
    poses: str | None = None

    def describe(self) -> dict:
        """The settings a resumed run must share (the data set's settings file)."""
        return {"kind": self.kind, "radius": None if self.radius is None else list(self.radius),
                "elevation": list(self.elevation), "seed": self.seed, "poses": self.poses}


def labelled_centre(scene) -> np.ndarray:
    """The centre of the box around the scene's labelled shapes (all bounded shapes where none has a
    label): the point every placed camera looks at."""
    shapes = [s for s in scene.shapes if s.label is not None and s.bounded] or [s for s in scene.shapes if s.bounded]
    if not shapes:
        raise RequestError("placing views: the scene has no bounded shape to look at; give --poses")
    boxes = np.stack([shape.box() for shape in shapes])
    return (boxes[:, 0].min(axis=0) + boxes[:, 1].max(axis=0)) / 2


def _scene_up(camera) -> np.ndarray:
    """The scene camera's up: a look-at camera's up vector, else minus its pose's y axis (OpenCV's y
    points down)."""
    if getattr(camera, "up", None) is not None:
        up = np.asarray(camera.up, np.float64)
    else:
        up = -camera.pose()[:3, 1]
    return up / np.linalg.norm(up)


def _horizon_axes(up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit axes a, b of the plane orthogonal to up (a, b, up right-handed)."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    a = helper - (helper @ up) * up
    a /= np.linalg.norm(a)
    return a, np.cross(up, a)


def look_pose(centre, up, radius: float, elevation: float, azimuth: float) -> np.ndarray:
    """The camera-to-world pose (OpenCV axes) at `radius` from `centre`, `elevation` degrees above the
    horizon orthogonal to `up`, at `azimuth` degrees around up, looking at the centre. The image's
    up is the direction of rising elevation, so the frame is defined at every elevation (also
    straight above the centre)."""
    a, b = _horizon_axes(up)
    e, t = math.radians(elevation), math.radians(azimuth)
    outward = math.cos(e) * (math.cos(t) * a + math.sin(t) * b) + math.sin(e) * up
    rising = -math.sin(e) * (math.cos(t) * a + math.sin(t) * b) + math.cos(e) * up
    z = -outward
    y = -rising
    x = np.cross(y, z)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2] = x, y, z
    pose[:3, 3] = np.asarray(centre, np.float64) + radius * outward
    return pose


def read_poses(path) -> list[tuple[np.ndarray | None, np.ndarray]]:
    """The views of a poses file: a JSON list of 4x4 camera-to-world matrices (OpenCV axes), or of
    objects {"K": 3x3, "pose": 4x4}. (K or None, pose) per view; a bad entry is a RequestError naming
    its index."""
    where = f"--poses {path}"
    try:
        data = json.loads(Path(path).read_text())
    except OSError as error:
        raise RequestError(f"{where}: cannot read it ({(error.strerror or str(error)).lower()})") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise RequestError(f"{where}: not JSON ({error})") from None
    if not isinstance(data, list) or not data:
        raise RequestError(f"{where}: expected a non-empty JSON list of 4x4 poses or of {{\"K\": ..., \"pose\": ...}}")
    views = []
    for index, entry in enumerate(data):
        K = None
        if isinstance(entry, dict):
            unknown = sorted(set(entry) - {"K", "pose"})
            if unknown or "pose" not in entry:
                raise RequestError(f"{where}: entry {index}: expected keys K (optional) and pose, got "
                                   f"{', '.join(sorted(entry)) or 'none'}")
            K = _array(where, index, "K", entry.get("K"), (3, 3)) if "K" in entry else None
            pose = _array(where, index, "pose", entry["pose"], (4, 4))
        else:
            pose = _array(where, index, "pose", entry, (4, 4))
        views.append((K, pose))
    return views


def _array(where, index, key, value, shape) -> np.ndarray:
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        array = None
    if array is None or array.shape != shape or not np.isfinite(array).all():
        raise RequestError(f"{where}: entry {index}: {key}: expected a {shape[0]}x{shape[1]} matrix of finite "
                           f"numbers")
    return array


def view_poses(scene, placement: Placement, count: int) -> list[tuple[np.ndarray | None, np.ndarray]]:
    """(K or None, pose) of each of `count` views (None: the scene camera's K)."""
    if placement.kind == "poses":
        views = read_poses(placement.poses)
        if count > len(views):
            raise RequestError(f"--views {count}: the poses file {placement.poses} has {len(views)} poses")
        return views[:count]
    centre = labelled_centre(scene)
    up = _scene_up(scene.camera)
    if placement.radius is None:
        distance = float(np.linalg.norm(np.asarray(scene.camera.eye) - centre))
        radius = (distance, distance) if distance > 0 else (1.0, 1.0)
    else:
        radius = placement.radius
    low, high = placement.elevation
    views = []
    for k in range(count):
        if placement.kind == "orbit":
            r, elevation, azimuth = (radius[0] + radius[1]) / 2, (low + high) / 2, 360.0 * k / count
        else:
            # uniform on the sphere's zone between the two elevations: sin(elevation) uniform
            draw = np.random.default_rng([placement.seed, k]).random(3)
            sine = math.sin(math.radians(low)) + draw[0] * (math.sin(math.radians(high)) - math.sin(math.radians(low)))
            elevation = math.degrees(math.asin(min(1.0, max(-1.0, sine))))
            azimuth = 360.0 * draw[1]
            r = radius[0] + draw[2] * (radius[1] - radius[0])
        views.append((None, look_pose(centre, up, r, elevation, azimuth)))
    return views


def view_cameras(scene, placement: Placement, count: int) -> list[Camera]:
    """The pinhole camera of each view at the scene's image size: K the scene camera's
    (``intrinsics(width, height)``) or the poses file's, the pose placed."""
    width, height = scene.image.width, scene.image.height
    own = scene.camera.intrinsics(width, height)  # (a lens's distortion is not carried: views are pinholes)
    cameras = []
    for index, (K, pose) in enumerate(view_poses(scene, placement, count)):
        if K is None:
            if own is None:
                raise RequestError(f"placing views: the scene's {scene.camera.model} camera has no pinhole K; "
                                   "give K per view in --poses")
            K = own
        try:
            cameras.append(Camera.from_intrinsics(K, pose, width, height))
        except ValueError as error:
            raise RequestError(f"view {index}: {error}") from None
    return cameras
