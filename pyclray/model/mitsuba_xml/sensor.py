"""Mitsuba's perspective sensor as a pyclray camera and image size.

Its to_world is a look-at (kept as such: the same rays as Mitsuba's own look_at) or any rotation,
translation and uniform scale; with a principal point offset it becomes a camera from intrinsics.
fov_axis x and y are pyclray's own; smaller, larger and diagonal are turned into x or y as Mitsuba's
perspective sensor does (src/sensors/perspective.cpp, parse_fov). A mirroring or stretching to_world
has no pyclray camera: an error.
"""
from __future__ import annotations

import math
import re

import numpy as np

from ..camera import Camera, Image
from .plugins import FILM_SETTINGS, FILM_SIZE, SENSOR_SETTINGS, Reading, checked, only_plugins, plugin_type
from .properties import IDENTITY, Properties
from .tree import Element

FILM_DIAGONAL_MM = math.hypot(36.0, 24.0)  # a focal length is given for a 35 mm film, along its diagonal


def film(element: Element) -> tuple[int, int]:
    plugin_type(element, {"hdrfilm": None, "specfilm": None})
    props = Properties(element, ignore=FILM_SETTINGS)
    width = props.take("width", "integer", FILM_SIZE[0])
    height = props.take("height", "integer", FILM_SIZE[1])
    props.finish()
    only_plugins(element, props, ("rfilter",))
    return width, height


def fov_along_x_or_y(element: Element, fov: float, axis: str, width: int, height: int) -> tuple[float, str]:
    """(fov, "x" or "y"): Mitsuba's fov_axis smaller and larger pick the image's shorter or longer
    side; diagonal turns into x through tan(fov_x / 2) = tan(fov / 2) width / diagonal."""
    if axis in ("x", "y"):
        return fov, axis
    if axis == "smaller":
        return fov, "x" if width <= height else "y"
    if axis == "larger":
        return fov, "x" if width >= height else "y"
    if axis == "diagonal":
        tangent = math.tan(math.radians(fov) / 2) * width / math.hypot(width, height)
        return math.degrees(2 * math.atan(tangent)), "x"
    raise element.error(f"property 'fov_axis': expected x, y, smaller, larger or diagonal, got {axis!r}")


def perspective(element: Element, reading: Reading) -> None:
    if reading.camera is not None:
        raise element.error("a second sensor: pyclray renders a scene through one camera")
    props = Properties(element, ignore=SENSOR_SETTINGS)
    fov = props.take("fov", "float")
    focal = props.take("focal_length", "string")
    axis = props.take("fov_axis", "string", "x")
    if fov is None and focal is None:
        raise element.error("missing property 'fov' (<float name=\"fov\" value=\"45\"/>) or 'focal_length'")
    if fov is None:
        found = re.fullmatch(r"\s*([0-9.eE+-]+)\s*(mm)?\s*", focal)
        if not found:
            raise element.error(f"property 'focal_length': expected a length in mm such as \"50mm\", got {focal!r}")
        fov, axis = math.degrees(2 * math.atan(FILM_DIAGONAL_MM / (2 * float(found.group(1))))), "diagonal"
    to_world = props.take("to_world", "transform", IDENTITY)
    offset = np.array([props.take("principal_point_offset_x", "float", 0.0),
                       props.take("principal_point_offset_y", "float", 0.0)])
    props.finish()
    only_plugins(element, props, ("film", "sampler"))
    films = [child for child in props.plugins if child.tag == "film"]
    width, height = film(films[0]) if films else FILM_SIZE
    reading.image = checked(element, Image, width, height)
    if not 0 < fov < 180:
        raise element.error(f"property 'fov': expected 0 < fov < 180 degrees, got {fov!r}")
    fov, axis = fov_along_x_or_y(element, fov, axis, width, height)
    matrix = to_world.matrix
    if to_world.look_at_args is not None and not offset.any():
        origin, target, up = (tuple(float(c) for c in v) for v in to_world.look_at_args)
        reading.camera = checked(element, Camera, origin, target, up, fov, axis)
        return
    columns = to_world.columns()  # left, up, forward
    to_world.similarity(element, "a camera's frame: anything else stretches the image")
    lengths = np.linalg.norm(columns, axis=1)
    if np.linalg.det(matrix[:3, :3]) < 0:
        raise element.error("to_world mirrors the image (a negative determinant): pyclray's cameras do not")
    left, up, forward = columns / lengths[:, None]
    eye = matrix[:3, 3]
    if not offset.any():
        reading.camera = checked(element, Camera, tuple(eye), tuple(eye + forward), tuple(up), fov, axis)
        return
    # a principal point off the centre: pinhole intrinsics (square pixels) and the pose in OpenCV's
    # convention (x right, y down, z forward); the optical axis meets the film at 0.5 - offset
    tan = math.tan(math.radians(fov) / 2)
    fx = width / (2 * tan) if axis == "x" else height / (2 * tan)
    K = [[fx, 0.0, width * (0.5 - offset[0])], [0.0, fx, height * (0.5 - offset[1])], [0.0, 0.0, 1.0]]
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = -left, -up, forward, eye
    reading.camera = checked(element, Camera.from_intrinsics, K, pose, width, height)


SENSORS = {"perspective": perspective}
