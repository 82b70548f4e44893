"""The equirectangular camera (pyclray.Equirectangular): a panorama about the eye, column i a
longitude, row j a latitude; the rays in float64 (kernels/camera.h reads them as the lens models')."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import SceneError, _shown, no_unknown_keys, number, vector3
from .base import CameraModel, RayTable
from .lens import TABLES_KEPT
from .perspective import CAMERA, look_at_rows, packed_space

TABLE_KEYS = ("eye", "target", "up", "longitude", "latitude")


def _range(key: str, value, low: float, high: float, span: float) -> tuple[float, float]:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise SceneError(f"expected [min, max] in degrees, got {_shown(value)}", key=key)
    lo, hi = (number(key, v) for v in value)
    if not (low <= lo < hi <= high and hi - lo <= span):
        raise SceneError(f"expected [min, max] degrees with {low:g} <= min < max <= {high:g} and max - min <= {span:g}, "
                         f"got [{lo!r}, {hi!r}]", key=key)
    return lo, hi


@dataclass(frozen=True)
class Equirectangular(CameraModel):
    """A panorama about ``eye``: ``Equirectangular(eye, target=None, up=None, longitude=(-180, 180),
    latitude=(-90, 90))``. The view direction (target - eye; default -z) is the image's centre,
    up (default +y) its north; column i looks at longitude lon_min + (i + 0.5) / width
    (lon_max - lon_min), growing to the viewer's right (the image is not mirrored), row j at
    latitude lat_max - (j + 0.5) / height (lat_max - lat_min): row 0 is the top. Degrees."""

    model = "equirectangular"
    keys = TABLE_KEYS
    struct = CAMERA
    has_zdepth = False

    eye: tuple[float, float, float]
    target: tuple[float, float, float] | None = None
    up: tuple[float, float, float] | None = None
    longitude: tuple[float, float] = (-180.0, 180.0)
    latitude: tuple[float, float] = (-90.0, 90.0)

    def __post_init__(self):
        eye = vector3("eye", self.eye)
        object.__setattr__(self, "eye", eye)
        target = (eye[0], eye[1], eye[2] - 1.0) if self.target is None else vector3("target", self.target)
        object.__setattr__(self, "target", target)
        object.__setattr__(self, "up", (0.0, 1.0, 0.0) if self.up is None else vector3("up", self.up))
        object.__setattr__(self, "longitude", _range("longitude", self.longitude, -360.0, 360.0, 360.0))
        object.__setattr__(self, "latitude", _range("latitude", self.latitude, -90.0, 90.0, 180.0))
        self.basis()

    @classmethod
    def from_table(cls, table: dict) -> "Equirectangular":
        no_unknown_keys(table, TABLE_KEYS, required=("eye",))
        return cls(**table)

    def table(self) -> dict:
        """The [camera] table that loads as this camera."""
        return {"model": self.model, "eye": self.eye, "target": self.target, "up": self.up, "longitude": self.longitude,
                "latitude": self.latitude}

    @property
    def fixed_keys(self) -> tuple[str, ...]:
        return ("longitude", "latitude")

    def basis(self) -> np.ndarray:
        cached = self.__dict__.get("_basis")
        if cached is None:
            cached = look_at_rows(self.eye, self.target, self.up)
            cached.setflags(write=False)
            object.__setattr__(self, "_basis", cached)
        return cached

    def space_directions(self, width: int, height: int):
        """Each pixel's unit direction in the camera's space (u left, v up, w forward), all in the
        field (a RayTable), once per ranges and size."""
        return panorama_table(self.longitude, self.latitude, width, height)

    def pack(self, width: int, height: int, precision: str, box_origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        return packed_space(self.basis(), width, height, precision, box_origin)

    def rays(self, width: int, height: int, window=None):
        return self.rays_from_table(width, height, window)


@lru_cache(maxsize=TABLES_KEPT)
def panorama_table(longitude: tuple, latitude: tuple, width: int, height: int) -> RayTable:
    """Pixel (row j, column i) looks at longitude lon_min + (i + 0.5) / width (lon_max - lon_min)
    (to the right of w) and latitude lat_max - (j + 0.5) / height (lat_max - lat_min) (toward v)."""
    lon0, lon1 = np.radians(longitude)
    lat0, lat1 = np.radians(latitude)
    lon = lon0 + (np.arange(width) + 0.5) / width * (lon1 - lon0)
    lat = lat1 - (np.arange(height) + 0.5) / height * (lat1 - lat0)
    cos_lat = np.cos(lat)[:, None]
    d = np.stack(np.broadcast_arrays(-cos_lat * np.sin(lon)[None, :], np.sin(lat)[:, None], cos_lat * np.cos(lon)[None, :]),
                 axis=-1)
    return RayTable(np.ascontiguousarray(d), np.ones((height, width), bool))
