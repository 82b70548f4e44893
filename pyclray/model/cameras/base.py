"""What a camera model is: the interface each model in CAMERAS implements (pbrt-v4's Camera and
GenerateRay, Mitsuba's sensor plugins), and its Mitsuba 3 sensor as plain data."""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numpy as np

from ..errors import RequestError, SceneError
from ..layout import Struct

MAX_IMAGE_SIDE = 1 << 16


class LookAt(NamedTuple):
    """A sensor's to_world given as a look-at: <lookat origin=... target=... up=...> in XML (the
    check gives Mitsuba the matrix its XML parser makes of it, so that the check's scene and an
    exported file are the same bit for bit)."""

    origin: list
    target: list
    up: list


@dataclass(frozen=True)
class MitsubaSensor:
    """A camera as a Mitsuba 3 sensor, as data (no Mitsuba needed): what ``pyclray check`` gives
    Mitsuba, what ``pyclray export`` writes and what the Mitsuba XML reader reads back.

    plugin: the sensor plugin (``<sensor type=...>``); properties: the plugin's own (a perspective
    sensor's fov, fov_axis, principal_point_offset_x and _y); width, height: the film's size.
    to_world: the camera-to-world matrix (4x4 float64, columns Mitsuba's camera axes x left, y up,
    z forward, then the eye), or None where look_at gives it: the <lookat> it was written as (the
    same rays as Mitsuba's own look_at). A sensor read from a file has its matrix, and its look_at
    where to_world was one <lookat>. The near and far clip are the check's own (they depend on the
    scene's shapes, not on the camera)."""

    plugin: str
    properties: dict
    width: int
    height: int
    to_world: np.ndarray | None = None
    look_at: LookAt | None = None


class RayTable:
    """A camera's rays where they are not a pinhole's image plane (CameraModel.space_directions):
    ``directions`` (height, width, 3) unit float64 in the camera's space (u left, v up, w forward),
    ``valid`` (height, width): the pixels in the model's field; both read-only. It unpacks as
    (directions, valid). ``derived`` keeps what the engine makes of it once (its tiles' bounds), for
    as long as the table is kept."""

    __slots__ = ("directions", "valid", "derived")

    def __init__(self, directions: np.ndarray, valid: np.ndarray):
        directions.setflags(write=False)
        valid.setflags(write=False)
        self.directions, self.valid, self.derived = directions, valid, {}

    def __iter__(self):
        return iter((self.directions, self.valid))

    def __getitem__(self, index):
        return (self.directions, self.valid)[index]


class CameraModel(ABC):
    """A camera model: a class per model, registered in pyclray.model.cameras.CAMERAS under its
    ``model`` name, with one OpenCL function that makes a pixel's ray from its packed struct.

    A model declares its ``[camera]`` keys and reads them (``from_table``: errors name the key,
    the loader adds the file and the table), packs the struct its kernel function reads
    (``struct``, ``pack``), makes the same pixel-centre rays in float64 for the oracle and the
    checks (``rays``), gives K and the pose where they mean something (``intrinsics``, ``pose``),
    names the keys an animation cannot change (``fixed_keys``) and, where Mitsuba 3 has a sensor
    of the same rays (``mitsuba_plugin``), maps itself to that sensor (``mitsuba_sensor``) and
    back (a classmethod ``from_mitsuba(sensor)``, given the properties ``mitsuba_properties`` names
    as the XML reader reads them)."""

    model: ClassVar[str]  # the [camera] table's model key, and the registry's
    keys: ClassVar[tuple[str, ...]]  # the [camera] table's keys (besides model)
    struct: ClassVar[Struct]  # the struct the kernel's camera function reads (model/layout.py)
    mitsuba_plugin: ClassVar[str | None] = None  # Mitsuba 3's sensor plugin of the same rays, if any
    # the properties of that sensor the XML reader takes: (name, Mitsuba type, default)
    mitsuba_properties: ClassVar[tuple[tuple[str, str, object], ...]] = ()

    @classmethod
    @abstractmethod
    def from_table(cls, table: dict) -> "CameraModel":
        """The camera of a [camera] table's keys (without model); a SceneError naming the key."""

    @property
    @abstractmethod
    def fixed_keys(self) -> tuple[str, ...]:
        """The fields an animation cannot key (pyclray.model.animation)."""

    @abstractmethod
    def pack(self, width: int, height: int, precision: str, box_origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """The kernel's struct (one element of layout(struct, precision).dtype) for an image of
        width x height; box_origin: the eye in the render BVH's space (the eye minus the scene's
        anchor, float64)."""

    @abstractmethod
    def rays(self, width: int, height: int, window=None) -> tuple[np.ndarray, np.ndarray]:
        """(origins, unit directions), each (rows, columns, 3) float64, of the pixel centres of a
        width x height image, or of the window (x0, y0, columns, rows) of it (render's window):
        the rays the kernel casts, computed in float64 for the oracle and the checks."""

    # every pixel's ray starts at the eye (render's packets share their origin); a model whose rays
    # start elsewhere (orthographic) is rendered by casting its rays (engine/queries/render.py)
    rays_from_eye: ClassVar[bool] = True
    # the depth along the optical axis (zdepth) means something for this model
    has_zdepth: ClassVar[bool] = True

    def intrinsics(self, width: int, height: int) -> np.ndarray | None:
        """K (3x3 float64) of the pixel-centre rays at this image size, OpenCV's convention (pixel
        centres at integer coordinates); None for a model without one (orthographic, panoramas)."""
        return None

    def project(self, points, width: int, height: int):
        """(pixel coordinates (N, 2) in OpenCV's convention (pixel centres at integers), depth along
        the optical axis (N,)) of world points (N, 3) float64, the inverse of this model's pixel rays
        at this image size (for flow: engine/queries/motion.py); None for a model without one here
        (a lens, a panorama)."""
        return None

    @abstractmethod
    def basis(self) -> np.ndarray:
        """Rows u (left), v (up), w (forward): the camera's axes in world coordinates, float64."""

    def space_directions(self, width: int, height: int):
        """(directions, valid) of a model whose rays are not a pinhole's image plane (a lens, a
        panorama): unit directions (height, width, 3) in the camera's space (u, v, w components),
        float64, and whether each pixel is in the model's field (a miss where not); None for a
        pinhole (the kernel computes those rays itself: kernels/camera.h)."""
        return None

    def rays_from_table(self, width: int, height: int, window=None) -> tuple[np.ndarray, np.ndarray]:
        """rays() of a model whose rays come from its table (space_directions): each pixel's
        direction turned into the world by the basis and normalized, from the eye."""
        d, _ = self.space_directions(width, height)
        if window is not None:
            col0, row0, columns, rows = window
            d = d[row0:row0 + rows, col0:col0 + columns]
        d = d @ self.basis()
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        return np.broadcast_to(np.array(self.eye), d.shape), d

    def pose(self, convention: str = "opencv") -> np.ndarray:
        """The camera-to-world pose (4x4 float64): its rotation's columns the camera's axes in world
        coordinates, its translation the eye. convention "opencv" (the default; also Open3D's, BOP's
        and COLMAP's axes): x right, y down, z forward; "opengl" (Blender, pyrender, NeRF): x right,
        y up, z backward."""
        u, v, w = self.basis()
        pose = np.eye(4)
        if convention == "opencv":
            pose[:3, 0], pose[:3, 1], pose[:3, 2] = -u, -v, w
        elif convention == "opengl":
            pose[:3, 0], pose[:3, 1], pose[:3, 2] = -u, v, -w
        else:
            raise RequestError(f'convention: expected "opencv" or "opengl", got {convention!r}')
        pose[:3, 3] = self.eye
        return pose

    def extrinsic(self) -> np.ndarray:
        """The world-to-camera matrix (4x4 float64), OpenCV's axes: the inverse of pose(), as
        Open3D (its ``extrinsic``), BOP (``cam_R_w2c``, ``cam_t_w2c``) and OpenCV (rvec, tvec) take it."""
        pose = self.pose()
        extrinsic = np.eye(4)
        extrinsic[:3, :3] = pose[:3, :3].T
        extrinsic[:3, 3] = -pose[:3, :3].T @ pose[:3, 3]
        return extrinsic

    def mitsuba_ray_starts(self, width: int, height: int, near: float) -> np.ndarray:
        """How far along each pixel's ray (from its origin here) Mitsuba's sensor starts it, given its
        near clip (height, width): a pinhole's starts on the near plane, near / cos of the ray's
        angle to the optical axis."""
        _, directions = self.rays(width, height)
        return near / (directions @ self.basis()[2])

    def mitsuba_sensor(self, width: int, height: int) -> MitsubaSensor:
        """This camera as Mitsuba's sensor of a width x height film; a SceneError where Mitsuba has none."""
        raise SceneError(f"Mitsuba 3 has no sensor of the {self.model} camera model, so this camera cannot be "
                         "checked against Mitsuba or exported for it", key="model")
