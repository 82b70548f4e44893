"""The view's images: one AOV of a scene rendered from a camera at a size, shown as its preview
(the colours `pyclray render --png` writes), encoded for the page: JPEG while the user moves
(small, fast to encode and decode), PNG when settled (lossless)."""
from __future__ import annotations

import io
import time
from dataclasses import dataclass

import numpy as np

# The AOVs the page offers, in its selector's order: those with a preview (positions have none);
# primitive only for a scene with a batch, label only for a scene with a label
AOVS = ("shaded", "depth", "zdepth", "normal", "id", "primitive", "label")
JPEG_QUALITY = 85
# zlib's fastest level: quicker than level 6, for a slightly larger file (docs/benchmarks.md, "Why the
# engine does what it does")
PNG_LEVEL = 1


def offered_aovs(scene, asked: str) -> tuple[str, ...]:
    """The AOVs this scene has something to show in (and the one asked for on the command line)."""
    def offered(name):
        if name == "primitive":
            return any(shape.primitive_count() > 1 for shape in scene.shapes)
        if name == "label":
            return any(shape.label is not None for shape in scene.shapes)
        if name == "zdepth":  # the depth along an optical axis: not a panorama's nor a wide fisheye's
            return scene.camera.has_zdepth
        return True

    return tuple(name for name in AOVS if name == asked or offered(name))


@dataclass
class Picture:
    """One rendered view: its RGB preview (height, width, 3) uint8 and the seconds it took."""

    rgb: np.ndarray
    seconds: float


def render_picture(scene, camera, aov: str, size: tuple[int, int]) -> Picture:
    """The preview of `aov` of the scene seen by `camera` at `size` (width, height): the scene's
    shapes stay prepared on the device, so a new camera or size uploads the camera only."""
    from ...engine.api import render
    from ...io.png import preview

    start = time.perf_counter()
    if size != (scene.image.width, scene.image.height):
        scene = scene.with_size(*size)
    frame = render(scene, aovs=(aov,), camera=camera)
    rgb = preview(aov, frame[aov])
    return Picture(rgb, time.perf_counter() - start)


def encode(rgb: np.ndarray, lossless: bool) -> tuple[str, bytes]:
    """(MIME type, bytes) of the image for the page."""
    from PIL import Image

    buffer = io.BytesIO()
    if lossless:
        Image.fromarray(rgb).save(buffer, "PNG", compress_level=PNG_LEVEL)
        return "image/png", buffer.getvalue()
    Image.fromarray(rgb).save(buffer, "JPEG", quality=JPEG_QUALITY)
    return "image/jpeg", buffer.getvalue()
