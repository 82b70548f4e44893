"""The images a render or a cast can make (AOVs): the one table of what each one is.

Everything that needs a fact about an AOV (its element type, its channels, its value on a miss, its
bytes per pixel, its EXR channel names, whether cast makes it) reads it here; nothing else keeps a
table of its own.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_REAL = {"fp32": np.float32, "fp64": np.float64}


@dataclass(frozen=True)
class Aov:
    name: str
    channels: int  # 1: an (H, W) image; 2 or 3: (H, W, channels)
    real: bool  # the render's precision (float32 or float64); False: int32
    miss: str  # what a pixel without a hit holds (for messages and the docs)
    exr: tuple[str, ...]  # its EXR channel names, one per channel
    cast: bool  # cast returns it too (the per-ray results)
    # the kernel computes it; else the host derives it after the kernel from the AOV (or AOVs) named here
    from_aov: str | tuple[str, ...] | None = None

    def dtype(self, precision: str = "fp32") -> np.dtype:
        return np.dtype(_REAL[precision] if self.real else np.int32)

    def itemsize(self, precision: str = "fp32") -> int:
        """Bytes per pixel."""
        return self.channels * self.dtype(precision).itemsize

    def shape(self, leading: tuple) -> tuple:
        """The array's shape for these leading dimensions (pixels or rays)."""
        return tuple(leading) + ((self.channels,) if self.channels > 1 else ())

    def empty(self, leading: tuple, precision: str = "fp32") -> np.ndarray:
        return np.empty(self.shape(leading), self.dtype(precision))


# the kernel's images in the kernels' order (engine/launch/signatures.py lists each image's buffer in this
# order), then those the host derives from them
TABLE = {
    aov.name: aov
    for aov in (
        Aov("depth", 1, True, "+inf", ("Z",), True),
        Aov("normal", 3, True, "(0, 0, 0)", ("N.X", "N.Y", "N.Z"), True),
        Aov("id", 1, False, "-1", ("id",), True),
        Aov("zdepth", 1, True, "+inf", ("zdepth",), False),
        Aov("position", 3, True, "(0, 0, 0)", ("P.X", "P.Y", "P.Z"), False),
        Aov("shaded", 3, True, "the background colour", ("R", "G", "B"), False),
        Aov("primitive", 1, False, "-1", ("primitive",), False),  # index within its shape (batch)
        # (u, v) of the triangle hit, hit = (1 - u - v) a + u b + v c; (0, 0) for other shapes
        Aov("barycentric", 2, True, "(0, 0)", ("bary.u", "bary.v"), False),
        # the hit shape's `label` (class masks beside the instance ids): labels[id], -1 for a miss
        # or a shape without one
        Aov("label", 1, False, "-1", ("label",), False, from_aov="id"),
        # data sets (engine/queries/motion.py, from the hit point, the shape and its primitive): the
        # hit point in its shape's own space (Shape.object_poses), and the forward optical flow in
        # pixels to the next frame (t + 1/fps: the shapes moved, the camera there)
        Aov("object_coordinates", 3, True, "(0, 0, 0)", ("O.X", "O.Y", "O.Z"), False,
            from_aov=("position", "id", "primitive")),
        Aov("flow", 2, True, "(0, 0)", ("flow.x", "flow.y"), False, from_aov=("position", "id", "primitive")),
    )
}

# the images of every render and cast (and their default), and every image a render can make
AOVS = tuple(name for name, aov in TABLE.items() if aov.cast)
RENDER_AOVS = tuple(TABLE)
# every AOV a cast can return (per ray, where it means something for a ray given in world coordinates)
CAST_AOVS = ("depth", "normal", "id", "position", "primitive", "barycentric", "label")


def kernel_aovs(aovs) -> tuple[str, ...]:
    """The images the kernel makes for a request (in the table's order): those asked that it
    computes, and those the others are derived from (label needs id)."""
    needed = set()
    for name in aovs:
        source = TABLE[name].from_aov or name
        needed.update((source,) if isinstance(source, str) else source)
    return tuple(name for name in TABLE if name in needed)


def image_bytes(aovs, pixels: int, precision: str = "fp32") -> int:
    """Bytes of the arrays a render of this many pixels returns for these AOVs."""
    return pixels * sum(TABLE[name].itemsize(precision) for name in aovs)


def empty_images(aovs, precision: str = "fp32") -> dict:
    """Zero-size (0, 0, ...) arrays of these AOVs' types and channels (what a writer needs to know
    of a render before its first band)."""
    return {name: TABLE[name].empty((0, 0), precision) for name in aovs}
