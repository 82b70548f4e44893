"""PNG files written band by band (PngWriter), and the previews of each AOV (depth and zdepth as
disparity greys, normals as n * 0.5 + 0.5, ids as a colour per shape, labels as a colour per label,
shaded as clamped sRGB)."""
from __future__ import annotations

import functools
import struct
import zlib
from pathlib import Path

import numpy as np

from .files import Background, write_together


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


class PngWriter:
    """Writes an 8-bit RGB PNG from bands of rows ((rows, width, 3) uint8), top to bottom: one
    zlib stream over all rows, its output in IDAT chunks as it comes. write() returns at once: the
    compression runs in the background (see Background); close() waits for it and ends the file;
    stop() abandons it after a failure."""

    def __init__(self, file, width: int, height: int):
        self.file, self.width, self.height, self.rows = file, width, height, 0
        self.zip = zlib.compressobj(6)
        self.background = Background()
        header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
        self.file.write(b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", header))

    def write(self, rgb: np.ndarray) -> None:
        self.rows += rgb.shape[0]
        if self.rows > self.height:
            raise ValueError(f"PngWriter: {self.rows} rows written, the image has {self.height}")
        self.background.submit(self._compress, rgb)

    def _compress(self, rgb: np.ndarray) -> None:
        rows = rgb.shape[0]
        lines = np.zeros((rows, 1 + 3 * self.width), np.uint8)  # filter type 0 (none) per row
        lines[:, 1:] = np.asarray(rgb, np.uint8).reshape(rows, 3 * self.width)
        self._emit(self.zip.compress(lines))

    def _emit(self, data: bytes) -> None:
        if data:
            self.file.write(_png_chunk(b"IDAT", data))

    def close(self) -> None:
        self.background.finish()
        self.stop()
        if self.rows != self.height:
            raise ValueError(f"PngWriter: {self.rows} of {self.height} rows written")
        self._emit(self.zip.flush())
        self.file.write(_png_chunk(b"IEND", b""))

    def stop(self) -> None:
        self.background.stop()


def _png_bytes(rgb: np.ndarray) -> bytes:
    """A whole image as PNG bytes."""
    import io

    buffer = io.BytesIO()
    writer = PngWriter(buffer, rgb.shape[1], rgb.shape[0])
    writer.write(rgb)
    writer.close()
    return buffer.getvalue()


def write_png(path, rgb: np.ndarray) -> None:
    write_together([(path, lambda tmp: Path(tmp).write_bytes(_png_bytes(np.ascontiguousarray(rgb, dtype=np.uint8))))])


# -- previews ---------------------------------------------------------------------------------------
class DepthPreview:
    """Near bright, far dark, misses black: inverse distance (disparity) scaled between the
    nearest and the farthest hit, to grey levels 255 (nearest) down to 48 (farthest), so that even
    the farthest hit stays apart from the black of a miss. Disparity keeps contrast near the eye
    when a ground plane runs to the horizon. Two passes: measure() sees every band (the scale is
    the whole image's), then rgb() turns each band into grey rows."""

    two_pass = True

    def __init__(self):
        self.low, self.high = np.inf, -np.inf

    def measure(self, depth) -> None:
        hit = np.isfinite(depth) & (depth > 0)
        if hit.any():
            inverse = 1.0 / depth[hit].astype(np.float64)
            self.low, self.high = min(self.low, inverse.min()), max(self.high, inverse.max())

    def rgb(self, depth) -> np.ndarray:
        hit = np.isfinite(depth) & (depth > 0)
        grey = np.zeros(depth.shape, np.uint8)
        if hit.any():
            inverse = 1.0 / depth[hit].astype(np.float64)
            g = (inverse - self.low) / (self.high - self.low) if self.high > self.low else np.ones_like(inverse)
            grey[hit] = np.round(48 + 207 * g).astype(np.uint8)
        return np.repeat(grey[..., None], 3, axis=-1)


class OnePassPreview:
    """A preview whose rows depend on their band alone: rgb() turns each band as it comes."""

    two_pass = False

    def measure(self, band) -> None:
        pass


class NormalPreview(OnePassPreview):
    """n * 0.5 + 0.5 as RGB; misses (zero normal) black."""

    def rgb(self, normal) -> np.ndarray:
        normal = np.asarray(normal)
        level = normal.astype(np.float32) * np.float32(127.5) + np.float32(127.5)  # (n * 0.5 + 0.5) * 255
        np.minimum(np.maximum(level, 0, out=level), 255, out=level)  # a unit normal is within; rounding may not be
        rgb = np.rint(level, out=level).astype(np.uint8)
        rgb[~np.any(normal != 0, axis=-1)] = 0
        return rgb


PREVIEWS = {"depth": DepthPreview, "normal": NormalPreview}


def preview(aov: str, image: np.ndarray) -> np.ndarray:
    """The (H, W, 3) uint8 preview of one AOV's whole image, as `pyclray render --png` writes it."""
    maker = PREVIEWS[aov]()
    maker.measure(image)
    return np.ascontiguousarray(maker.rgb(image))


def srgb_preview(linear: np.ndarray) -> np.ndarray:
    """Linear RGB clamped to [0, 1] and encoded with the sRGB transfer curve (IEC 61966-2-1), NaN black.
    A float32 image (the render's) is looked up in tables of the same levels, bit for bit
    (_srgb_float32, quicker, for pyclray view's frames; docs/benchmarks.md, "Why the engine does what it
    does")."""
    linear = np.asarray(linear)
    if linear.dtype == np.float32:
        return _srgb_float32(linear)
    return _srgb_levels(linear)


def _srgb_levels(linear) -> np.ndarray:
    """The formula, in float64."""
    c = np.clip(np.nan_to_num(np.asarray(linear, np.float64), nan=0.0), 0.0, 1.0)
    encoded = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    return np.round(encoded * 255).astype(np.uint8)


def _srgb_float32(linear: np.ndarray) -> np.ndarray:
    """_srgb_levels of float32 values by their bits: the top 16 bits pick a bucket of 2^16
    consecutive floats, whose level is base, plus step where the value reaches the bucket's
    threshold (thr: +inf in the buckets the levels do not step in)."""
    base, step, thr = _srgb_tables()
    x = np.ascontiguousarray(linear)
    # the buckets as intp once for three takes (a uint32 index is converted at each fancy index),
    # the threshold's float32 lookup compared and dropped before the step's (the large temporaries
    # in this order are quicker: docs/benchmarks.md, "Data sets (issue 40)")
    bucket = (x.view(np.uint32) >> 16).astype(np.intp)
    levels = base.take(bucket)
    stepped = x >= thr.take(bucket)
    levels += step.take(bucket) * stepped
    return levels


@functools.cache
def _srgb_tables():
    """(base, step, thr) of _srgb_float32, from _srgb_levels itself (once). A bucket spans
    under 1 % of its values, less than one level of the curve (at most 3295 levels per unit, below
    0.0031308, where the buckets are narrower still): at most one step per bucket, found by bisection
    on its 16 low bits. Negative values and NaN (whose bits sort above +inf) are level 0, +inf 255;
    +inf and 65535 NaNs share one bucket: base 0, step 255 at inf."""
    buckets = np.arange(1 << 16, dtype=np.uint32)
    low, high = buckets << 16, (buckets << 16) | 0xFFFF

    def level(bits):
        with np.errstate(invalid="ignore"):  # signalling NaNs among the bits
            return _srgb_levels(bits.view(np.float32)).astype(np.int32)

    base, top = level(low), level(high)
    step = top - base
    thr = np.full(1 << 16, np.inf, np.float32)
    infinity = 0x7F80  # the bucket of +inf (0x7F800000) and the NaNs after it
    stepping = np.flatnonzero((buckets < infinity) & (step != 0))
    assert np.all(step[stepping] == 1), "sRGB levels: more than one step in a bucket"
    below, at = low[stepping], high[stepping]  # level(below) = base, level(at) = top
    for _ in range(17):
        middle = below + (at - below) // 2
        up = level(middle) == top[stepping]
        at, below = np.where(up, middle, at), np.where(up, below, middle)
    thr[stepping] = at.view(np.float32)
    base[buckets >= infinity], step[buckets >= infinity] = 0, 0
    step[infinity] = 255
    return base.astype(np.uint8), step.astype(np.uint8), thr


def colors_of(k) -> np.ndarray:
    """(..., 3) uint8: the colour of each id (or label) k >= 0: hues stepped by the golden angle
    (neighbouring ids far apart on the colour wheel), saturation and value alternating in a short
    cycle so that ids many hues apart still differ; never black (black is a miss). A function of k
    alone: any band, any image gives k the same colour, whatever the largest k."""
    k = np.asarray(k, np.int64)
    hue = (k * 0.618033988749895) % 1.0
    saturation = np.array([0.85, 0.55, 0.95])[k % 3]
    value = np.array([0.95, 0.8, 0.65, 0.9])[(k // 3) % 4]
    sector = np.floor(hue * 6).astype(int) % 6
    f = hue * 6 - np.floor(hue * 6)
    p, q, t = value * (1 - saturation), value * (1 - f * saturation), value * (1 - (1 - f) * saturation)
    rgb = np.select(
        [sector[..., None] == s for s in range(6)],
        [np.stack(c, axis=-1) for c in ((value, t, p), (q, value, p), (p, value, t), (p, q, value), (t, p, value), (value, p, q))],
    )
    return np.round(rgb * 255).astype(np.uint8)


def id_preview(ids: np.ndarray) -> np.ndarray:
    """Each shape id (or label) in its own colour (colors_of), misses (-1) black. Colours are made
    for the distinct values present only, so a label of 2^31 - 1 costs what a label of 1 does."""
    ids = np.asarray(ids)
    rgb = np.zeros(ids.shape + (3,), np.uint8)
    hit = ids >= 0
    if hit.any():
        present, index = np.unique(ids[hit], return_inverse=True)
        rgb[hit] = colors_of(present)[index.reshape(-1)]
    return rgb


class IdPreview(OnePassPreview):
    """Each shape id in its own colour (colors_of), misses black: one pass (a colour per id)."""

    def rgb(self, ids) -> np.ndarray:
        return id_preview(ids)


class ShadedPreview(OnePassPreview):
    """The shaded image clamped to [0, 1] and sRGB-encoded (srgb_preview): one pass."""

    def rgb(self, linear) -> np.ndarray:
        return srgb_preview(linear)


class LabelPreview(IdPreview):
    """Each label in its own colour (the colours of ids: label k as id k), misses and shapes
    without a label (-1) black."""


# AOV -> its preview, in the order of the files (zdepth is shown like depth; positions have none)
PREVIEWS.update({"id": IdPreview, "zdepth": DepthPreview, "shaded": ShadedPreview, "primitive": IdPreview,
                 "label": LabelPreview})


def preview_paths(out, aovs=tuple(PREVIEWS)) -> dict:
    """OUT.exr (or OUT.npz) -> {"depth": OUT.depth.png, "normal": OUT.normal.png} (for the AOVs
    given that have one)."""
    out = Path(out)
    stem = out.with_suffix("") if out.suffix.lower() in (".exr", ".npz") else out
    return {name: stem.with_name(f"{stem.name}.{name}.png") for name in PREVIEWS if name in aovs}
