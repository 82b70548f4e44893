"""The scene's camera and image size. The camera models are pyclray.model.cameras (the perspective
camera, pyclray.Camera, is the one named here, with its image plane and limits, for the modules
that take them from here)."""
from __future__ import annotations

from dataclasses import dataclass

from .cameras import MAX_IMAGE_SIDE
from .cameras.perspective import MAX_PLANE_REACH, MAX_PRINCIPAL_POINT, MIN_PIXEL_TAN, Camera, ImagePlane
from .errors import integer

__all__ = ["MAX_IMAGE_SIDE", "MAX_PLANE_REACH", "MAX_PRINCIPAL_POINT", "MIN_PIXEL_TAN", "Camera", "Image", "ImagePlane"]


@dataclass(frozen=True)
class Image:
    width: int = 512
    height: int = 512

    def __post_init__(self):
        integer("width", self.width, minimum=1, maximum=MAX_IMAGE_SIDE)
        integer("height", self.height, minimum=1, maximum=MAX_IMAGE_SIDE)
