"""The orthographic camera (pyclray.Orthographic): parallel rays along the view direction from the
pixel centres of a plane through the eye; the same rays as Mitsuba 3's orthographic sensor."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SceneError, no_unknown_keys, number, vector3
from .base import CameraModel, LookAt, MitsubaSensor
from .perspective import CAMERA, look_at_rows, packed_space

TABLE_KEYS = ("eye", "target", "up", "height")


@dataclass(frozen=True)
class Orthographic(CameraModel):
    """``Orthographic(eye, target, up=None, height=2.0)``: rays along w = normalize(target - eye)
    from the plane through ``eye`` perpendicular to it; the image spans ``height`` scene units
    vertically (its width follows the aspect ratio), centred on the eye. Pixel (row j, column i)
    starts at eye + (i + 0.5 - width / 2) s right + (j + 0.5 - height_px / 2) s down, s = height /
    height_px the pixel's size; depth is measured from that plane."""

    model = "orthographic"
    keys = TABLE_KEYS
    struct = CAMERA
    mitsuba_plugin = "orthographic"
    rays_from_eye = False

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] | None = None
    height: float = 2.0

    def __post_init__(self):
        object.__setattr__(self, "eye", vector3("eye", self.eye))
        object.__setattr__(self, "target", vector3("target", self.target))
        object.__setattr__(self, "up", (0.0, 1.0, 0.0) if self.up is None else vector3("up", self.up))
        object.__setattr__(self, "height", number("height", self.height, positive=True))
        self.basis()

    @classmethod
    def from_table(cls, table: dict) -> "Orthographic":
        no_unknown_keys(table, TABLE_KEYS, required=("eye", "target"))
        return cls(**table)

    def table(self) -> dict:
        """The [camera] table that loads as this camera."""
        return {"model": self.model, "eye": self.eye, "target": self.target, "up": self.up, "height": self.height}

    @property
    def fixed_keys(self) -> tuple[str, ...]:
        return ()

    def basis(self) -> np.ndarray:
        cached = self.__dict__.get("_basis")
        if cached is None:
            cached = look_at_rows(self.eye, self.target, self.up)
            cached.setflags(write=False)
            object.__setattr__(self, "_basis", cached)
        return cached

    def pack(self, width: int, height: int, precision: str, box_origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        return packed_space(self.basis(), width, height, precision, box_origin)

    def offsets(self, width: int, height: int, window=None) -> tuple[np.ndarray, np.ndarray]:
        """(ox, oy): each column's and row's offset from the eye along u (left) and v (up)."""
        col0, row0, columns, rows = (0, 0, width, height) if window is None else window
        size = self.height / height
        ox = (width / 2 - 0.5 - np.arange(col0, col0 + columns)) * size
        oy = (height / 2 - 0.5 - np.arange(row0, row0 + rows)) * size
        return ox, oy

    def project(self, points, width: int, height: int):
        """The pixel whose ray passes through each point (offsets' inverse: column width / 2 - 0.5 -
        (p - eye).u / s, row height / 2 - 0.5 - (p - eye).v / s, s the pixel's size) and its depth
        along w from the plane through the eye."""
        u, v, w = self.basis()
        relative = np.asarray(points, np.float64) - np.array(self.eye)
        size = self.height / height
        pixels = np.stack([width / 2 - 0.5 - relative @ u / size, height / 2 - 0.5 - relative @ v / size], axis=-1)
        return pixels, relative @ w

    def rays(self, width: int, height: int, window=None):
        u, v, w = self.basis()
        ox, oy = self.offsets(width, height, window)
        origins = np.array(self.eye) + ox[None, :, None] * u + oy[:, None, None] * v
        return origins, np.broadcast_to(w, origins.shape).copy()

    def mitsuba_sensor(self, width: int, height: int) -> MitsubaSensor:
        """Mitsuba's orthographic sensor maps its film to x in [-1, 1], y in [-1 / aspect, 1 / aspect]
        of its camera space (orthographic.cpp), so to_world is the look-at's frame (Mitsuba's camera
        axes: x left, y up, z forward) scaled by height * aspect / 2 (uniformly: a similarity, which
        the XML reader takes; Mitsuba's rays then start near_clip times that scale along w)."""
        scale = self.mitsuba_scale(width, height)
        to_world = np.eye(4)
        to_world[:3, :3] = self.basis().T * scale
        to_world[:3, 3] = self.eye
        return MitsubaSensor(self.mitsuba_plugin, {}, width, height, to_world=to_world)

    def mitsuba_scale(self, width: int, height: int) -> float:
        return self.height * (width / height) / 2

    def mitsuba_ray_starts(self, width: int, height: int, near: float) -> np.ndarray:
        """How far along each ray (from this camera's origin) Mitsuba's ray starts: its near clip,
        scaled by to_world along w."""
        return np.full((height, width), near * self.mitsuba_scale(width, height))

    @classmethod
    def from_mitsuba(cls, sensor: MitsubaSensor) -> "Orthographic":
        """The camera of Mitsuba's orthographic sensor (to_world a rotation, translation and uniform
        scale s): eye the translation, looking along its z, up its y; height 2 s / aspect."""
        matrix = sensor.to_world
        columns = matrix[:3, :3].T  # left, up, forward (each of length s)
        scale = float(np.linalg.norm(columns[0]))
        left, up, forward = columns / np.linalg.norm(columns, axis=1)[:, None]
        eye = matrix[:3, 3]
        if sensor.look_at is not None:
            origin, target, up_given = (tuple(float(c) for c in v) for v in sensor.look_at)
            if scale == 1.0:
                return cls(origin, target, up_given, 2.0 * sensor.height / sensor.width)
        return cls(tuple(eye), tuple(eye + forward), tuple(up), 2.0 * scale * sensor.height / sensor.width)
