"""OpenEXR files: one multi-channel file per render, written band by band, and read back.

EXR channels (one part, scanlines, ZIP compression, 32-bit):
  Z              FLOAT  distance from the eye along the ray (+inf on a miss)
  N.X, N.Y, N.Z  FLOAT  unit world-space normal (0 on a miss)
  id             UINT   the shape id's int32 bit pattern: read it with .view(numpy.int32),
                        which gives -1 (stored as 4294967295) on a miss
  zdepth         FLOAT  depth along the camera's optical axis (+inf on a miss)
  P.X, P.Y, P.Z  FLOAT  world-space hit point (0 on a miss)
  R, G, B        FLOAT  the shaded image, linear RGB (the background colour on a miss)
  label          UINT   the hit shape's label, int32 bit pattern as id (-1: a miss or no label)
An fp64 render is stored as 32-bit floats: OpenEXR has no 64-bit float channel type (its pixel
types are UINT, HALF and FLOAT).

The camera, in the header (camera_attributes), where the writer was given it:
  intrinsics     m33d  K of this image, OpenCV's (pixels; [u, v, 1] ~ K [x, y, z], row-major as written)
  pose           m44d  camera-to-world, OpenCV's axes (x right, y down, z forward), for column
                       vectors: p_world = pose @ [p_camera, 1] (row-major as written)
  worldToCamera  m44f  OpenEXR's standard attribute, in its own convention: Imath's row vectors
                       ([p_camera, 1] = [p_world, 1] @ M) and RenderMan's camera space (x right,
                       y up, z forward, left-handed)

The encoder takes the image in bands of whole rows (ExrWriter), so a command never needs the whole
image in memory. It is ours: the OpenEXR package writes only whole arrays; its reader is the
reference the tests hold our files to.
"""
from __future__ import annotations

import io
import os
import struct
import sys
import tempfile
import threading
import zlib
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager, redirect_stderr, redirect_stdout, suppress
from pathlib import Path

import numpy as np

from ..model.aovs import TABLE
from ..model.errors import OutputError
from .files import Background, reason

EXR_CHANNELS = {name: aov.exr for name, aov in TABLE.items()}


_EXR_TYPES = {"UINT": (0, "<u4"), "FLOAT": (2, "<f4")}
_ZIP_LINES = 16  # scanlines per chunk with ZIP compression
_ZIP_LEVEL = 4  # OpenEXR's default zlib level


def exr_channel_arrays(images) -> dict:
    """EXR channel name -> (2-D array or view, pixel type) for the images given (a Frame or a band
    of one). Views, not copies: each chunk converts its own rows."""
    channels = {}
    for aov, names in EXR_CHANNELS.items():
        if aov not in images:
            continue
        array = np.asarray(images[aov])
        kind = "UINT" if array.dtype.kind in "iu" else "FLOAT"
        for k, name in enumerate(names):
            channels[name] = (array[..., k] if len(names) > 1 else array, kind)
    return channels


def _attribute(name: str, kind: str, value: bytes) -> bytes:
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


def camera_attributes(intrinsics, pose) -> list[bytes]:
    """The header attributes of a render's camera (see the module's docstring): K and the pose in
    OpenCV's convention, and OpenEXR's standard worldToCamera."""
    pose = np.asarray(pose, np.float64)
    axes = pose[:3, :3] * [1.0, -1.0, 1.0]  # columns: RenderMan's x right, y up, z forward
    world_to_camera = np.eye(4)  # Imath's row-vector form: the transpose of the column-vector matrix
    world_to_camera[:3, :3] = axes
    world_to_camera[3, :3] = -(pose[:3, 3] @ axes)
    return [
        # (no intrinsics for a camera model without K: orthographic, a panorama)
        *([] if intrinsics is None else [_attribute("intrinsics", "m33d", np.asarray(intrinsics, "<f8").tobytes())]),
        _attribute("pose", "m44d", pose.astype("<f8").tobytes()),
        _attribute("worldToCamera", "m44f", world_to_camera.astype("<f4").tobytes()),
    ]


def _zip_chunk(raw: np.ndarray) -> bytes:
    """OpenEXR's ZIP compression of one chunk: bytes split into even and odd positions, each
    byte replaced by its difference to the previous one (+128, mod 256), then zlib; stored raw
    where that is not smaller (as OpenEXR does, and its reader expects)."""
    raw = raw.reshape(-1)
    split = raw.reshape(-1, 2).T.reshape(-1)  # even bytes, then odd bytes (a chunk's size is even)
    delta = np.empty_like(split)
    delta[:1] = split[:1]
    np.subtract(split[1:], split[:-1], out=delta[1:])
    delta[1:] += 128
    packed = zlib.compress(delta, _ZIP_LEVEL)
    return packed if len(packed) < raw.size else raw.tobytes()


class ExrWriter:
    """Writes a single-part scanline OpenEXR file (ZIP) from bands of rows, top to bottom.

    channels: name -> "FLOAT" or "UINT"; write(band) takes name -> (rows, width) arrays (floats of
    any width are rounded to float32; integers are stored by their 32-bit pattern), any number of
    rows at a time, and returns at once: the chunks are compressed (on up to 4 threads) and
    written in the background; close() waits for them and finishes the file (an error if rows are
    missing); stop() abandons the file after a failure. camera: (K, pose) of the image, for the
    header (camera_attributes), or None."""

    def __init__(self, file, width: int, height: int, channels: dict, comment: str | None = None, camera=None):
        self.file, self.width, self.height = file, width, height
        self.names = sorted(channels)  # OpenEXR keeps channels sorted by name, in the file too
        self.kinds = [channels[name] for name in self.names]
        chlist = b"".join(
            name.encode() + b"\0" + struct.pack("<iB3xii", _EXR_TYPES[kind][0], 0, 1, 1)
            for name, kind in zip(self.names, self.kinds)
        ) + b"\0"
        box = struct.pack("<iiii", 0, 0, width - 1, height - 1)
        header = [
            _attribute("channels", "chlist", chlist),
            _attribute("compression", "compression", bytes([3])),  # ZIP_COMPRESSION
            _attribute("dataWindow", "box2i", box),
            _attribute("displayWindow", "box2i", box),
            _attribute("lineOrder", "lineOrder", bytes([0])),  # INCREASING_Y
            _attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
            _attribute("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
            _attribute("screenWindowWidth", "float", struct.pack("<f", 1.0)),
        ]
        if comment:
            header.append(_attribute("comment", "string", comment.encode()))
        if camera is not None:  # (K, pose) of this image
            header += camera_attributes(*camera)
        version = 2 | (0x400 if max(map(len, self.names + ["comment"])) > 31 else 0)  # long names
        self.file.write(struct.pack("<ii", 20000630, version) + b"".join(header) + b"\0")
        self.chunks = -(-height // _ZIP_LINES)
        self.table_at = self.file.tell()
        self.offsets: list[int] = []
        self.file.write(bytes(8 * self.chunks))  # the chunk offset table, filled in by close()
        self.pending: dict | None = None  # rows not yet a whole chunk
        self.rows = 0
        self.compressors = ThreadPoolExecutor(max_workers=max(1, min(4, os.cpu_count() or 1)))
        self.background = Background()

    def _chunk(self, band: dict) -> bytes:
        """One chunk, compressed: its bytes as OpenEXR lays them out (per scanline, each
        channel's row in turn), converted in one copy."""
        rows = next(iter(band.values())).shape[0]
        raw = np.empty((rows, len(self.names), self.width), "<u4")
        for c, (name, kind) in enumerate(zip(self.names, self.kinds)):
            array = band[name]
            if kind == "UINT":
                raw[:, c, :] = array.view("<u4") if array.dtype.itemsize == 4 else array.astype("<i4").view("<u4")
            else:
                raw.view("<f4")[:, c, :] = array  # rounded to float32 (an fp64 render too)
        return _zip_chunk(raw.view(np.uint8))

    def _write_chunks(self, band: dict, first_row: int, rows: int) -> None:
        starts = range(0, rows, _ZIP_LINES)
        chunks = [{n: a[s:s + _ZIP_LINES] for n, a in band.items()} for s in starts]
        for start, data in zip(starts, self.compressors.map(self._chunk, chunks)):
            self.offsets.append(self.file.tell())
            self.file.write(struct.pack("<ii", first_row + start, len(data)))
            self.file.write(data)

    def write(self, band: dict) -> None:
        band = {name: band[name] for name in self.names}  # channel name -> (rows, width)
        if self.pending is not None:  # the rows left over from the last band come first
            band = {n: np.concatenate([self.pending[n], a]) for n, a in band.items()}
            self.pending = None
        rows = band[self.names[0]].shape[0]
        if self.rows + rows > self.height:
            raise ValueError(f"ExrWriter: {self.rows + rows} rows written, the image has {self.height}")
        whole = rows if self.rows + rows == self.height else rows - rows % _ZIP_LINES
        if whole:
            self.background.submit(self._write_chunks, {n: a[:whole] for n, a in band.items()}, self.rows, whole)
        self.rows += whole
        if whole < rows:
            self.pending = {n: np.array(a[whole:]) for n, a in band.items()}

    def close(self) -> None:
        self.background.finish()
        self.stop()
        if self.rows != self.height or self.pending is not None:
            raise ValueError(f"ExrWriter: {self.rows} of {self.height} rows written")
        end = self.file.tell()
        self.file.seek(self.table_at)
        self.file.write(struct.pack(f"<{self.chunks}Q", *self.offsets))
        self.file.seek(end)

    def stop(self) -> None:
        self.background.stop()
        self.compressors.shutdown(wait=True, cancel_futures=True)


EXR_MAGIC = b"\x76\x2f\x31\x01"  # the first four bytes of every OpenEXR file
CAMERA_ATTRIBUTES = {"intrinsics": (3, 3), "pose": (4, 4), "worldToCamera": (4, 4)}


def read_exr(path, header: bool = False):
    """The images of an EXR written by write_exr or `pyclray render`, as render returns them: AOV
    name -> array, for each AOV whose channels the file holds (ids and labels as int32).
    header=True: (images, header), the header a dict of the file's attributes as OpenEXR reads
    them, with the camera's (see camera_attributes) as float64 numpy arrays: header["intrinsics"]
    (K) and header["pose"] where the file has them.

    A missing, unreadable or damaged file, or one that is not OpenEXR, raises OutputError of one
    line ("cannot read PATH: ..."), and nothing is printed: OpenEXR's own messages, which its C
    library writes to the process's stdout and stderr, are caught and put into the error."""
    path = Path(path)
    try:
        with open(path, "rb") as handle:
            magic = handle.read(len(EXR_MAGIC))
    except OSError as error:
        raise OutputError(f"cannot read {path}: {reason(error)}") from None
    if magic != EXR_MAGIC:
        raise OutputError(f"cannot read {path}: not an OpenEXR file")
    import OpenEXR

    try:
        with _output_captured() as captured, OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {name: channel.pixels for name, channel in exr.channels().items()}
            attributes = dict(exr.header()) if header else None
    except Exception as error:  # OpenEXR raises RuntimeError, ValueError, ... for a damaged file
        detail = " ".join((captured.text.strip().splitlines() or [str(error)])[0].split())
        raise OutputError(f"cannot read {path}: a damaged OpenEXR file ({detail})") from None
    images = _images(channels)
    if not header:
        return images
    for name, shape in CAMERA_ATTRIBUTES.items():
        if name in attributes:
            attributes[name] = np.asarray(attributes[name], np.float64).reshape(shape)
    return images, attributes


def _images(channels: dict) -> dict:
    out = {}
    for name, aov in TABLE.items():  # every AOV whose channels the file has, as render returns it
        if all(channel in channels for channel in aov.exr):
            planes = [channels[channel] for channel in aov.exr]
            image = planes[0] if aov.channels == 1 else np.stack(planes, axis=-1)
            out[name] = image if aov.real else image.view(np.int32)  # integers: their 32-bit pattern
    return out


class _Captured:
    text = ""


@contextmanager
def _output_captured():
    """What C code writes to the process's stdout and stderr (file descriptors 1 and 2) and what is
    printed to sys.stdout or sys.stderr during the block, kept in .text instead of printed.
    Python's own buffers are flushed first. Another thread printing meanwhile is caught too: only
    OpenEXR's reads run in such a block (they take milliseconds)."""
    captured = _Captured()
    for stream in (sys.stdout, sys.stderr):
        with suppress(Exception):
            stream.flush()
    python = io.StringIO()  # what the binding prints through Python's sys.stdout (its warnings)
    with _capture_lock, tempfile.TemporaryFile() as sink, redirect_stdout(python), redirect_stderr(python):
        saved = [os.dup(fd) for fd in (1, 2)]
        try:
            for fd in (1, 2):
                os.dup2(sink.fileno(), fd)
            try:
                yield captured
            finally:
                for fd, original in zip((1, 2), saved):
                    os.dup2(original, fd)
                sink.seek(0)
                captured.text = sink.read().decode("utf-8", "replace") + python.getvalue()
        finally:
            for original in saved:
                os.close(original)


_capture_lock = threading.Lock()
