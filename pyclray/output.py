"""Writers: one multi-channel OpenEXR file, and PNG previews a person can look at.

EXR channels (scanline, ZIP compression, 32-bit):
  Z              FLOAT  distance from the eye along the ray (+inf on a miss)
  N.X, N.Y, N.Z  FLOAT  unit world-space normal (0 on a miss)
  id             UINT   the shape id's int32 bit pattern: read it with .view(numpy.int32),
                        which gives -1 (stored as 4294967295) on a miss
  zdepth         FLOAT  depth along the camera's optical axis (+inf on a miss)
  P.X, P.Y, P.Z  FLOAT  world-space hit point (0 on a miss)
  R, G, B        FLOAT  the shaded image, linear RGB (the background colour on a miss)
Every file is written to a temporary file beside the target and renamed, so a failure never
leaves a partial or clobbered output behind.
"""
from __future__ import annotations

import os
import struct
import tempfile
import zlib
from contextlib import contextmanager
from pathlib import Path

import numpy as np

EXR_CHANNELS = {
    "depth": ("Z",), "normal": ("N.X", "N.Y", "N.Z"), "id": ("id",),
    "zdepth": ("zdepth",), "position": ("P.X", "P.Y", "P.Z"), "shaded": ("R", "G", "B"),
}
ID_MISS_UINT = 0xFFFFFFFF


@contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; rename it to ``path`` only if the block succeeds."""
    path = Path(path)
    handle, tmp = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", prefix=f".{path.name}.", suffix=".tmp")
    os.close(handle)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # as an ordinary new file, not mkstemp's 0600
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def exr_channels(frame) -> dict:
    """EXR channel name -> 2-D array for the images in the frame."""
    channels = {}
    if "depth" in frame:
        channels["Z"] = np.ascontiguousarray(frame["depth"], dtype=np.float32)
    if "normal" in frame:
        for k, name in enumerate(EXR_CHANNELS["normal"]):
            channels[name] = np.ascontiguousarray(frame["normal"][..., k], dtype=np.float32)
    if "id" in frame:
        channels["id"] = np.ascontiguousarray(frame["id"], dtype=np.int32).view(np.uint32)
    for aov in ("zdepth", "position", "shaded"):
        if aov in frame:
            image = np.asarray(frame[aov])
            for k, name in enumerate(EXR_CHANNELS[aov]):
                channels[name] = np.ascontiguousarray(image if image.ndim == 2 else image[..., k], dtype=np.float32)
    return channels


def write_exr(path, frame, comment: str | None = None) -> None:
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if comment:
        header["comment"] = comment
    with atomic_path(path) as tmp:
        with OpenEXR.File(header, exr_channels(frame)) as exr:
            exr.write(tmp)


def read_exr(path) -> dict:
    """The images of an EXR written by write_exr, as render returns them."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as exr:
        channels = {name: channel.pixels for name, channel in exr.channels().items()}
    out = {}
    if "Z" in channels:
        out["depth"] = channels["Z"]
    if "N.X" in channels:
        out["normal"] = np.stack([channels[c] for c in EXR_CHANNELS["normal"]], axis=-1)
    if "id" in channels:
        out["id"] = channels["id"].view(np.int32)
    if "zdepth" in channels:
        out["zdepth"] = channels["zdepth"]
    for aov in ("position", "shaded"):
        if all(name in channels for name in EXR_CHANNELS[aov]):
            out[aov] = np.stack([channels[c] for c in EXR_CHANNELS[aov]], axis=-1)
    return out


def _png_bytes(rgb: np.ndarray) -> bytes:
    """A minimal 8-bit RGB PNG encoder (zlib and struct are all it takes)."""
    height, width, _ = rgb.shape
    rows = np.concatenate([np.zeros((height, 1), np.uint8), rgb.reshape(height, width * 3)], axis=1)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6)) + chunk(b"IEND", b"")


def write_png(path, rgb: np.ndarray) -> None:
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(_png_bytes(np.ascontiguousarray(rgb, dtype=np.uint8)))


def depth_preview(depth: np.ndarray) -> np.ndarray:
    """Near bright, far dark, misses black: inverse distance (disparity) scaled between the
    nearest and the farthest hit, to grey levels 255 (nearest) down to 48 (farthest), so that even
    the farthest hit stays apart from the black of a miss. Disparity keeps contrast near the eye
    when a ground plane runs to the horizon."""
    hit = np.isfinite(depth) & (depth > 0)
    grey = np.zeros(depth.shape, np.uint8)
    if hit.any():
        inverse = 1.0 / depth[hit].astype(np.float64)
        low, high = inverse.min(), inverse.max()
        g = (inverse - low) / (high - low) if high > low else np.ones_like(inverse)
        grey[hit] = np.round(48 + 207 * g).astype(np.uint8)
    return np.repeat(grey[..., None], 3, axis=-1)


def normal_preview(normal: np.ndarray) -> np.ndarray:
    """n * 0.5 + 0.5 as RGB; misses (zero normal) black."""
    normal = np.asarray(normal, np.float64)
    rgb = np.round(np.clip(normal * 0.5 + 0.5, 0, 1) * 255).astype(np.uint8)
    rgb[~np.any(normal != 0, axis=-1)] = 0
    return rgb


def srgb_preview(linear: np.ndarray) -> np.ndarray:
    """Linear RGB clamped to [0, 1] and encoded with the sRGB transfer curve (IEC 61966-2-1)."""
    c = np.clip(np.nan_to_num(np.asarray(linear, np.float64), nan=0.0), 0.0, 1.0)
    encoded = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    return np.round(encoded * 255).astype(np.uint8)


def id_colors(count: int) -> np.ndarray:
    """(count, 3) uint8: distinct, bright colours, one per shape id: hues stepped by the golden
    angle (neighbouring ids far apart on the colour wheel), saturation and value alternating in a
    short cycle so that ids many hues apart still differ; never black (black is a miss)."""
    k = np.arange(count)
    hue = (k * 0.618033988749895) % 1.0
    saturation = np.array([0.85, 0.55, 0.95])[k % 3]
    value = np.array([0.95, 0.8, 0.65, 0.9])[(k // 3) % 4]
    sector = np.floor(hue * 6).astype(int) % 6
    f = hue * 6 - np.floor(hue * 6)
    p, q, t = value * (1 - saturation), value * (1 - f * saturation), value * (1 - (1 - f) * saturation)
    rgb = np.select(
        [sector[:, None] == s for s in range(6)],
        [np.stack(c, axis=-1) for c in ((value, t, p), (q, value, p), (p, value, t), (p, q, value), (t, p, value), (value, p, q))],
    )
    return np.round(rgb * 255).astype(np.uint8)


def id_preview(ids: np.ndarray) -> np.ndarray:
    """Each shape id in its own colour (id_colors), misses (-1) black."""
    ids = np.asarray(ids)
    rgb = np.zeros(ids.shape + (3,), np.uint8)
    hit = ids >= 0
    if hit.any():
        rgb[hit] = id_colors(int(ids.max()) + 1)[ids[hit]]
    return rgb


# AOV -> its preview (zdepth is shown like depth)
PREVIEWS = {
    "depth": depth_preview, "normal": normal_preview, "id": id_preview,
    "zdepth": depth_preview, "shaded": srgb_preview,
}


def preview_paths(out, aovs=("depth", "normal")) -> dict:
    """OUT.exr -> {"depth": OUT.depth.png, "normal": OUT.normal.png, ...}: one per AOV that has a preview."""
    out = Path(out)
    stem = out.with_suffix("") if out.suffix.lower() == ".exr" else out
    return {name: stem.with_name(f"{stem.name}.{name}.png") for name in aovs if name in PREVIEWS}
