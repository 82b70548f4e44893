"""The camera models: each a class implementing base.CameraModel (its [camera] keys and their
checks, its packed struct, its float64 pixel-centre rays, its Mitsuba sensor where Mitsuba has one),
registered here under its ``model`` name, which a scene file's ``[camera] model`` key selects.
A new model is one module here, its line in CAMERAS, its OpenCL ray function and its tests."""
from __future__ import annotations

from .base import MAX_IMAGE_SIDE, CameraModel, LookAt, MitsubaSensor
from .equirectangular import Equirectangular
from .fisheye import Fisheye
from .orthographic import Orthographic
from .perspective import Camera, ImagePlane

DEFAULT_MODEL = "perspective"  # a [camera] table without a model key

# model name -> its class
CAMERAS: dict[str, type[CameraModel]] = {
    "perspective": Camera,
    "fisheye": Fisheye,
    "orthographic": Orthographic,
    "equirectangular": Equirectangular,
}

__all__ = ["CAMERAS", "DEFAULT_MODEL", "MAX_IMAGE_SIDE", "Camera", "CameraModel", "Equirectangular", "Fisheye",
           "ImagePlane", "LookAt", "MitsubaSensor", "Orthographic"]
