"""The camera (a perspective view from an eye toward a target) and the image's size."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .errors import SceneError, integer, norm3, number, vector3

# Below this sine of the angle between up and the view direction the image's roll is decided by
# rounding noise: a degenerate camera, reported as an error rather than rendered.
MIN_UP_SINE = 1e-6
# The smallest half-width of a pixel on the image plane (tan(fov/2) / size): below it the rays of
# neighbouring pixels are no longer distinct in float32, so such a fov is an error.
MIN_PIXEL_TAN = 1e-30
MAX_IMAGE_SIDE = 1 << 16


class ImagePlane(NamedTuple):
    """Where the pixel centres' rays go, on the image plane at distance 1 in the camera's frame
    (x left, y up, z forward): pixel (row j, column i) at
    sx = tan_x (2 cx - 2 i - 1) / width, sy = tan_y (2 cy - 2 j - 1) / height.
    tan_x = width / (2 fx) and tan_y = height / (2 fy) (the tangents of a centred camera's half
    opening angles); cx, cy: the principal point in pixels (K's: width / 2, height / 2 when centred)."""

    tan_x: float
    tan_y: float
    cx: float
    cy: float


@dataclass(frozen=True)
class Camera:
    """A perspective camera looking from ``eye`` at ``target``; ``fov`` in degrees along ``fov_axis``."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov: float = 45.0
    fov_axis: str = "x"

    def __post_init__(self):
        object.__setattr__(self, "eye", vector3("eye", self.eye))
        object.__setattr__(self, "target", vector3("target", self.target))
        object.__setattr__(self, "up", vector3("up", self.up))
        fov = number("fov", self.fov)
        if not 0 < fov < 180:
            raise SceneError(f"expected 0 < fov < 180 (degrees), got {fov!r}", key="fov")
        object.__setattr__(self, "fov", fov)
        if self.fov_axis not in ("x", "y"):
            raise SceneError(f'expected "x" or "y", got {self.fov_axis!r}', key="fov_axis")
        self.basis()  # a degenerate basis is an error now, not a NaN image later

    def basis(self) -> np.ndarray:
        """Rows u (left), v (up), w (forward): the world_from_camera columns, in float64."""
        with np.errstate(over="ignore"):
            forward = np.subtract(self.target, self.eye)
        length = norm3(forward)
        if not math.isfinite(length):
            raise SceneError("expected target - eye within the range of float64, got an overflow", key="target")
        if length == 0:
            raise SceneError("expected target != eye (the view direction is undefined)", key="target")
        w = forward / length
        up_length = norm3(self.up)
        if up_length == 0:
            raise SceneError("expected a non-zero up vector, got [0, 0, 0]", key="up")
        left = np.cross(np.array(self.up) / up_length, w)
        sine = norm3(left)
        if sine < MIN_UP_SINE:
            raise SceneError(
                f"expected up not parallel to the view direction (target - eye); the sine of "
                f"their angle is {sine:.3g}, below {MIN_UP_SINE:g}",
                key="up",
            )
        u = left / sine
        v = np.cross(w, u)
        return np.stack([u, v, w])

    def intrinsics(self, width: int, height: int) -> np.ndarray:
        """K (3x3 float64): the pinhole intrinsics of this camera's pixel-centre rays at this image
        size, in OpenCV's convention (x right, y down, z forward; pixel (row j, column i) looks
        through K^-1 [i + 0.5, j + 0.5, 1]): fx = width / (2 tan_x), cx = width / 2, and alike in y."""
        tan_x, tan_y = self.tangents(width, height)
        return np.array([[width / (2 * tan_x), 0.0, width / 2], [0.0, height / (2 * tan_y), height / 2], [0.0, 0.0, 1.0]])

    def pose(self) -> np.ndarray:
        """The camera-to-world pose (4x4 float64) in OpenCV's convention: its rotation's columns are
        the camera's x (right = -u), y (down = -v) and z (forward = w) axes in world coordinates, its
        translation the eye. A depth map back-projects as pose @ [depth * normalize(K^-1 [i+.5, j+.5, 1]), 1]."""
        u, v, w = self.basis()
        pose = np.eye(4)
        pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = -u, -v, w, self.eye
        return pose

    def image_plane(self, width: int, height: int) -> ImagePlane:
        """Where this camera's pixel-centre rays go at this image size (see ImagePlane): the one
        description of them that the kernel's camera struct, the oracle and the culling share."""
        return ImagePlane(*self.tangents(width, height), width / 2, height / 2)

    def tangents(self, width: int, height: int) -> tuple[float, float]:
        """tan of the half opening angles along x and y (square pixels)."""
        t = math.tan(math.radians(self.fov) / 2)
        if self.fov_axis == "x":
            return t, t * height / width
        return t * width / height, t


@dataclass(frozen=True)
class Image:
    width: int = 512
    height: int = 512

    def __post_init__(self):
        integer("width", self.width, minimum=1, maximum=MAX_IMAGE_SIDE)
        integer("height", self.height, minimum=1, maximum=MAX_IMAGE_SIDE)
