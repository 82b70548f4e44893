"""The view's camera controls (three.js OrbitControls, Blender, MeshLab): orbit about the target,
pan, dolly, in float64 on the camera's eye, target and up. The page sends mouse motion in fractions
of the image's height, so a drag's effect does not depend on the page's zoom or the image size.

A look-at camera keeps its up, fov and fov axis; a camera from intrinsics keeps its K and size, and
orbits about a point on its optical axis (its pose's roll is the up it starts with)."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ...model.camera import Camera

# An orbit never takes the view direction closer than this to the up axis (radians): at the pole
# the image's roll is undefined (Camera's degenerate basis), as OrbitControls' makeSafe keeps it.
POLE_MARGIN = 1e-3
# One wheel notch (deltaY = 100 in browsers) brings the eye 5 % closer to the target (OrbitControls'
# zoom scale 0.95)
DOLLY_PER_NOTCH = 0.95
# The eye never comes closer to the target than this fraction of its first distance (eye != target)
MIN_DISTANCE_FRACTION = 1e-6


def _unit(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / math.sqrt(float(v @ v))


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """v rotated by angle (right-handed) about the unit axis (Rodrigues' formula)."""
    c, s = math.cos(angle), math.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * float(axis @ v) * (1 - c)


@dataclass(frozen=True)
class Orbit:
    """Where the user has moved the camera: eye, target and the up it orbits about, over the
    camera it started from (which keeps the rest: fov, fov axis, or K and size)."""

    eye: tuple
    target: tuple
    up: tuple
    start: Camera
    min_distance: float

    @classmethod
    def of(cls, camera: Camera) -> "Orbit":
        """The controls over this camera: a look-at camera's own eye, target and up; a camera from
        intrinsics orbits about the point of its optical axis nearest the world's origin (at least
        one unit ahead), with its image's up as the up."""
        u, v, w = camera.basis()
        eye = np.array(camera.eye)
        if getattr(camera, "K", None) is None:  # a look-at (perspective, orthographic, panorama)
            target, up = np.array(camera.target), np.array(camera.up)
        else:
            target, up = eye + w * max(1.0, float(-eye @ w)), v
        distance = math.dist(eye, target)
        return cls(tuple(eye), tuple(target), tuple(_unit(up)), camera, distance * MIN_DISTANCE_FRACTION)

    def _offset(self) -> tuple[np.ndarray, float]:
        offset = np.subtract(self.eye, self.target)
        return offset, math.sqrt(float(offset @ offset))

    def orbit(self, dx: float, dy: float) -> "Orbit":
        """Left drag by (dx, dy) heights: a drag across the image's height turns the eye a full
        turn about the target (OrbitControls' rotateLeft / rotateUp), left-right about the up axis,
        up-down toward or away from it, never past the pole (POLE_MARGIN)."""
        up = np.array(self.up)
        offset, distance = self._offset()
        offset = _rotate(offset, up, -2 * math.pi * dx)  # azimuth: drag right, the scene turns right
        # polar angle from the up axis: drag down lowers it (the eye climbs), clamped off the poles
        polar = math.acos(max(-1.0, min(1.0, float(offset @ up) / distance)))
        turned = max(POLE_MARGIN, min(math.pi - POLE_MARGIN, polar - 2 * math.pi * dy)) - polar
        side = np.cross(up, offset)  # the axis that tilts the offset toward the up axis
        if float(side @ side) > 0:
            offset = _rotate(offset, _unit(side), turned)  # + tilts away from up
        return replace(self, eye=tuple(np.add(self.target, offset)))

    def pan(self, dx: float, dy: float, width: int, height: int) -> "Orbit":
        """Right (or shift + left) drag by (dx, dy) heights of a width x height image: eye and target
        move together across the view, so that the point at the target's distance follows the mouse
        (OrbitControls' pan: the image's height spans 2 distance tan(fov_y / 2) there)."""
        camera = self.camera()
        u, v, _ = camera.basis()
        _, distance = self._offset()
        span = 2 * distance * camera.tangents(width, height)[1]  # world units per image height
        # u points left and v up: dragging right moves the camera left, dragging down moves it up
        move = (u * dx + v * dy) * span
        return replace(self, eye=tuple(np.add(self.eye, move)), target=tuple(np.add(self.target, move)))

    def dolly(self, notches: float) -> "Orbit":
        """The wheel: each notch toward the user (deltaY < 0) brings the eye DOLLY_PER_NOTCH of its
        distance closer to the target, each notch away takes it as far back."""
        offset, distance = self._offset()
        scale = max(DOLLY_PER_NOTCH ** -notches, self.min_distance / distance)
        return replace(self, eye=tuple(np.add(self.target, offset * scale)))

    def camera(self) -> Camera:
        """The camera the user sees: the start camera from the new eye toward the new target."""
        if getattr(self.start, "K", None) is None:
            return replace(self.start, eye=self.eye, target=self.target)
        w = _unit(np.subtract(self.target, self.eye))
        u = _unit(np.cross(self.up, w))
        v = np.cross(w, u)
        # the start camera (its K, size, lens) turned: OpenCV's axes x right, y down, z forward
        rotation = tuple(tuple(float(x) for x in row) for row in np.stack([-u, -v, w], axis=1))
        return replace(self.start, eye=tuple(float(x) for x in self.eye), rotation=rotation)


def _number(x: float) -> str:
    """A float as TOML with the digits a scene file needs (12 significant: a view found by hand)."""
    text = f"{x:.12g}"
    return text if any(c in text for c in ".en") else text + ".0"


def _vector(values) -> str:
    return "[" + ", ".join(_number(float(x)) for x in values) + "]"


def _value(value) -> str:
    """A [camera] key's value as TOML: a string, a number, a vector or a matrix."""
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (int, float)):
        return _number(float(value))
    if len(value) and not isinstance(value[0], (int, float)):
        return "[" + ", ".join(_vector(row) for row in value) + "]"
    return _vector(value)


def camera_toml(camera: Camera) -> str:
    """The [camera] table of a scene file that loads as this camera (the "copy camera" button)."""
    if camera.model != "perspective":  # the other models say their own keys
        return "[camera]\n" + "\n".join(f"{key} = {_value(value)}" for key, value in camera.table().items()) + "\n"
    if camera.K is None:
        lines = [f"eye = {_vector(camera.eye)}", f"target = {_vector(camera.target)}",
                 f"up = {_vector(camera.up)}", f"fov = {_number(camera.fov)}"]
        if camera.fov_axis != "x":
            lines.append(f'fov_axis = "{camera.fov_axis}"')
    else:
        pose = camera.pose()
        lines = ["intrinsics = [" + ", ".join(_vector(row) for row in camera.K) + "]",
                 "pose = [" + ", ".join(_vector(row) for row in pose) + "]"]
        if camera.distortion is not None:
            lines.append(f"distortion = {_vector(camera.distortion)}")
    return "[camera]\n" + "\n".join(lines) + "\n"
