"""A data set's image files: PNG bytes of grey (8 or 16 bit) and RGB images, and the image forms of
ids and masks.

Ids in image files. The raw ``id`` image holds the shape's index and -1 where a ray hits nothing;
image formats have no -1, so an 8- or 16-bit id image (and every mask) holds 0 for the background
and id + 1 for shape id (``id_image``); a BOP or PNG mask is 255 where the object is, 0 elsewhere."""
from __future__ import annotations

import struct

import numpy as np
from isal import isal_zlib

# The data set's PNGs are deflated by ISA-L (isal_zlib: the zlib format, read by every PNG
# reader), at its level 2: the size of zlib's level 1 in a quarter of its time or less, and encoding
# is most of a view's host work (docs/benchmarks.md, "Data sets (issue 40)")
PNG_LEVEL = 2


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", isal_zlib.crc32(kind + data))


def png_bytes(image: np.ndarray, level: int = PNG_LEVEL) -> bytes:
    """The PNG of an (H, W) uint8 or uint16 grey image or an (H, W, 3) uint8 RGB image (16-bit
    samples big-endian, as PNG stores them), every row with filter 0 (none); level: ISA-L's, 0 to 3."""
    image = np.asarray(image)
    if image.ndim == 2 and image.dtype in (np.uint8, np.uint16):
        colour, samples = 0, image.astype(">u2" if image.dtype == np.uint16 else np.uint8, copy=False)
    elif image.ndim == 3 and image.shape[2] == 3 and image.dtype == np.uint8:
        colour, samples = 2, image
    else:
        raise ValueError(f"png_bytes: expected an (H, W) uint8/uint16 or (H, W, 3) uint8 image, got "
                         f"{image.dtype}{list(image.shape)}")
    height, width = image.shape[:2]
    depth = 16 if samples.dtype.itemsize == 2 else 8
    rows = np.ascontiguousarray(samples).view(np.uint8).reshape(height, -1)
    lines = np.zeros((height, rows.shape[1] + 1), np.uint8)
    lines[:, 1:] = rows
    header = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + _chunk(b"IDAT", isal_zlib.compress(lines, level))
            + _chunk(b"IEND", b""))


def id_image(ids: np.ndarray, bits: int = 16) -> np.ndarray:
    """The raw id image (int32, -1 on a miss) as an image file's: 0 for the background, id + 1 for
    shape id, in uint8 (bits 8) or uint16 (bits 16); a RequestError-free ValueError where an id does
    not fit."""
    dtype = {8: np.uint8, 16: np.uint16}[bits]
    ids = np.asarray(ids)
    if ids.size and int(ids.max()) + 1 > np.iinfo(dtype).max:
        raise ValueError(f"id_image: shape id {int(ids.max())} does not fit a {bits}-bit id image (id + 1 at most "
                         f"{np.iinfo(dtype).max})")
    return (ids.astype(np.int64) + 1).astype(dtype)


def mask_image(mask: np.ndarray) -> np.ndarray:
    """A boolean mask as a PNG mask's uint8 image: 255 where True, 0 elsewhere."""
    return np.asarray(mask, bool).astype(np.uint8) * np.uint8(255)
