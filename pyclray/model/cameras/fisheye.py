"""The fisheye camera (pyclray.Fisheye): OpenCV's fisheye model (Kannala-Brandt, cv2.fisheye), from
intrinsics K, a pose and the coefficients k1..k4, with an optional field limit; each pixel's ray the
exact inverse of the lens (model/cameras/lens.py), beyond the field or the lens's fold a miss."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError, _shown, integer, no_unknown_keys, number, text, vector3
from . import lens
from .base import MAX_IMAGE_SIDE, CameraModel
from .perspective import (CAMERA, PIXEL_ORIGINS, _intrinsics, _matrix, _nested, _rotation, opencv_pose,
                          packed_space, scaled_intrinsics)

TABLE_KEYS = ("intrinsics", "pose", "distortion", "fov", "pixel_origin")


@dataclass(frozen=True)
class Fisheye(CameraModel):
    """OpenCV's fisheye camera: ``Fisheye.from_intrinsics(K, pose, width, height, distortion=(k1, k2,
    k3, k4), fov=None, convention="opencv", pixel_origin="center")``. A direction theta off the
    optical axis lands at K [theta_d x / r, theta_d y / r, 1] (cv2.fisheye.projectPoints, alpha 0),
    theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8); theta reaches up to 180
    degrees (rays behind the camera's plane, as a 190-degree lens has). fov: the full field angle
    in degrees, pixels beyond it misses (a circular fisheye's black border); left out, the lens's
    own field (up to where theta_d stops growing, at most 360 degrees). Holds eye, K (OpenCV's
    convention), rotation (camera-to-world), size (the image K is in pixels of; None: the scene's),
    distortion (k1..k4) and fov."""

    model = "fisheye"
    keys = TABLE_KEYS
    struct = CAMERA
    has_zdepth = False  # (the contract's zdepth is the perspective and orthographic cameras')

    eye: tuple[float, float, float]
    K: tuple
    rotation: tuple
    size: tuple[int, int] | None = None
    distortion: tuple = (0.0, 0.0, 0.0, 0.0)
    fov: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "eye", vector3("eye", self.eye))
        object.__setattr__(self, "K", _nested(_intrinsics("intrinsics", self.K)))
        object.__setattr__(self, "rotation", _nested(_rotation("pose", _matrix("pose", self.rotation, 3, 3))))
        object.__setattr__(self, "distortion", fisheye_coefficients(self.distortion))
        if self.fov is not None:
            fov = number("fov", self.fov)
            if not 0 < fov <= 360:
                raise SceneError(f"expected 0 < fov <= 360 (degrees: the fisheye's full field angle), got {fov!r}", key="fov")
            object.__setattr__(self, "fov", fov)
        if self.size is not None:
            if isinstance(self.size, (str, bytes)) or not hasattr(self.size, "__len__") or len(self.size) != 2:
                raise SceneError(f"expected (width, height), got {_shown(self.size)}", key="size")
            object.__setattr__(self, "size", tuple(integer("size", side, minimum=1, maximum=MAX_IMAGE_SIDE)
                                                   for side in self.size))

    @classmethod
    def from_intrinsics(cls, K, pose, width: int | None = None, height: int | None = None, *, distortion=(0, 0, 0, 0),
                        fov=None, convention: str = "opencv", pixel_origin: str = "center") -> "Fisheye":
        """The fisheye of K, a rigid camera-to-world pose (convention "opencv" or "opengl") and the
        coefficients k1..k4; pixel_origin as for Camera.from_intrinsics. Errors name the key."""
        K = _intrinsics("intrinsics", K)
        if pixel_origin not in PIXEL_ORIGINS:
            raise SceneError(f'expected "center" or "corner", got {_shown(pixel_origin)}', key="pixel_origin")
        if pixel_origin == "corner":
            K[0, 2] -= 0.5
            K[1, 2] -= 0.5
        pose = _matrix("pose", pose, 4, 4)
        if not np.array_equal(pose[3], [0.0, 0.0, 0.0, 1.0]):
            raise SceneError(f"expected a rigid camera-to-world pose, its last row 0 0 0 1, got {_shown(list(pose[3]))}",
                             key="pose")
        pose = opencv_pose(pose, convention)
        if (width is None) != (height is None):
            raise SceneError("expected both width and height (the image K is in pixels of), or neither",
                             key="height" if height is None else "width")
        size = None if width is None else (width, height)
        return cls(tuple(pose[:3, 3]), _nested(K), _nested(pose[:3, :3]), size, distortion, fov)

    @classmethod
    def from_table(cls, table: dict) -> "Fisheye":
        no_unknown_keys(table, TABLE_KEYS, required=("intrinsics", "pose"))
        return cls.from_intrinsics(table["intrinsics"], table["pose"], distortion=table.get("distortion", (0, 0, 0, 0)),
                                   fov=table.get("fov"), pixel_origin=text("pixel_origin", table.get("pixel_origin", "center")))

    def table(self) -> dict:
        """The [camera] table that loads as this camera (its K at its size)."""
        out = {"model": self.model, "intrinsics": self.K, "pose": self.pose().tolist(), "distortion": self.distortion}
        return out if self.fov is None else {**out, "fov": self.fov}

    @property
    def fixed_keys(self) -> tuple[str, ...]:
        """An animation keys the eye, the coefficients and the field, not K or the rotation."""
        return ("K", "rotation", "size")

    def basis(self) -> np.ndarray:
        R = np.array(self.rotation)
        return np.stack([-R[:, 0], -R[:, 1], R[:, 2]])  # OpenCV's x right, y down, z forward

    def intrinsics(self, width: int, height: int) -> np.ndarray:
        """K (OpenCV's convention) at this image size: as given at its size, scaled at another."""
        return scaled_intrinsics(self.K, self.size, width, height)

    def space_directions(self, width: int, height: int):
        """Each pixel's unit direction in the camera's space and whether the lens reaches it
        (lens.fisheye_table, float64), solved once per lens and image size."""
        K = self.intrinsics(width, height)
        max_theta = math.pi if self.fov is None else math.radians(self.fov) / 2
        return lens.fisheye_table((float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])), self.distortion,
                                  max_theta, width, height)

    def pack(self, width: int, height: int, precision: str, box_origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """The kernel's Camera struct: the frame (the rays come from space_directions' table)."""
        return packed_space(self.basis(), width, height, precision, box_origin)

    def rays(self, width: int, height: int, window=None):
        return self.rays_from_table(width, height, window)


def fisheye_coefficients(value) -> tuple:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 4:
        raise SceneError(f"expected OpenCV's fisheye coefficients [k1, k2, k3, k4], got {_shown(value)}", key="distortion")
    return tuple(number(f"distortion[{index}]", c) for index, c in enumerate(np.asarray(value, dtype=object).tolist()))
