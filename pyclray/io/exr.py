"""Writers: one multi-channel OpenEXR file and PNG previews, streamed band by band, and the one
place that replaces the files of a command together (replace_together / write_together).

EXR channels (one part, scanlines, ZIP compression, 32-bit):
  Z              FLOAT  distance from the eye along the ray (+inf on a miss)
  N.X, N.Y, N.Z  FLOAT  unit world-space normal (0 on a miss)
  id             UINT   the shape id's int32 bit pattern: read it with .view(numpy.int32),
                        which gives -1 (stored as 4294967295) on a miss
  zdepth         FLOAT  depth along the camera's optical axis (+inf on a miss)
  P.X, P.Y, P.Z  FLOAT  world-space hit point (0 on a miss)
  R, G, B        FLOAT  the shaded image, linear RGB (the background colour on a miss)
An fp64 render is stored as 32-bit floats: OpenEXR has no 64-bit float channel type (its pixel
types are UINT, HALF and FLOAT).

Both encoders take the image in bands of whole rows (ExrWriter, PngWriter), so a command never
needs the whole image in memory: `write_images` streams the bands of a render into the EXR and the
previews. The EXR encoder is ours (as the PNG one): the OpenEXR package writes only whole arrays;
its reader is the reference the tests hold our files to.

Every file is written to a temporary file beside its target, flushed to disk, and renamed only
once every file of the command is written, so a failure (or Ctrl-C) never leaves a partial,
clobbered or mixed set of outputs behind.
"""
from __future__ import annotations

import os
import signal
import struct
import tempfile
import threading
import zlib
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from .errors import OutputError

EXR_CHANNELS = {
    "depth": ("Z",), "normal": ("N.X", "N.Y", "N.Z"), "id": ("id",),
    "zdepth": ("zdepth",), "position": ("P.X", "P.Y", "P.Z"), "shaded": ("R", "G", "B"),
}
ID_MISS_UINT = 0xFFFFFFFF


# -- replacing the files of one command together ------------------------------------------------
def _reason(error: OSError) -> str:
    return (error.strerror or str(error)).lower() if isinstance(error, OSError) else str(error)


def check_target(path) -> None:
    """Raise OutputError if path cannot be an output file (its folder is missing, or it is a folder)."""
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        raise OutputError(f"cannot write {path}: the folder {folder} does not exist; nothing was replaced")
    if path.is_dir():
        raise OutputError(f"cannot write {path}: it is a folder; nothing was replaced")


def _fsync(path, *, folder: bool = False) -> None:
    fd = os.open(path, os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if folder else 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextmanager
def _interrupts_deferred():
    """Hold Ctrl-C (SIGINT) back while the block runs, then raise it: the renames of
    replace_together are all done or none, never half."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught = []
    previous = signal.signal(signal.SIGINT, lambda number, frame: caught.append(number))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt


@contextmanager
def replace_together(paths: Iterable) -> Iterator[list[str]]:
    """Replace the files ``paths`` together or not at all.

    Yields one temporary path per target (same folder, hidden name, in the order given); the block
    writes each temporary (in any order, by any means: a numpy tofile, an encoder, a video writer
    given the path). When the block ends normally, every temporary is flushed to disk (fsync) and
    then all are renamed onto their targets; old files of the same names are replaced only then.
    If the block raises (or Ctrl-C arrives), or a flush or a rename fails, the temporaries are
    removed, targets already renamed get their old file back, and the old files stay as they were.
    Write failures (OSError: read-only folder, full disk, a target that is a folder, a missing
    folder) are raised as OutputError naming the path and the reason; other exceptions pass
    through after the clean-up.

    For a folder of frames, give one path per frame file (the folder must exist). Writers with a
    callback per file use write_together.
    """
    targets = [Path(p) for p in paths]
    if len({os.path.abspath(t) for t in targets}) != len(targets):
        raise OutputError("cannot write the same file twice in one command: " + ", ".join(map(str, targets)))
    for target in targets:
        check_target(target)
    temporaries: list[str] = []
    current = targets[0] if targets else None
    try:
        for target in targets:
            current = target
            handle, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
            os.close(handle)
            temporaries.append(tmp)
        current = None
        yield list(temporaries)
        umask = os.umask(0)
        os.umask(umask)
        for target, tmp in zip(targets, temporaries):
            current = target
            os.chmod(tmp, 0o666 & ~umask)  # as an ordinary new file, not mkstemp's 0600
            _fsync(tmp)
        with _interrupts_deferred():
            _rename_all(targets, temporaries)
            temporaries = []
        current = None
    except OSError as error:
        name = error.filename if current is None and getattr(error, "filename", None) else current
        if name is not None and str(name) in temporaries:  # a temporary's name means nothing to the user
            name = targets[temporaries.index(str(name))]
        what = f"cannot write {name if name is not None else ', '.join(map(str, targets))}"
        raise OutputError(f"{what}: {_reason(error)}; nothing was replaced") from None
    finally:
        for tmp in temporaries:
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass
    for folder in {t.parent for t in targets}:  # the renames themselves to disk (replaced by now)
        try:
            _fsync(folder, folder=True)
        except OSError:
            pass


def _rename_all(targets, temporaries) -> None:
    """Rename every temporary onto its target; if one rename fails, undo the ones done (each old
    file is kept under a hard link until all renames are through)."""
    backups: dict[Path, str | None] = {}
    done: list[Path] = []
    try:
        for target in targets:
            backups[target] = None
            if target.exists():
                backup = tempfile.mktemp(dir=target.parent, prefix=f".{target.name}.", suffix=".old")
                try:
                    os.link(target, backup)
                    backups[target] = backup
                except OSError:
                    pass  # no hard links here: a failed rename cannot restore this one
        for target, tmp in zip(targets, temporaries):
            os.replace(tmp, target)
            done.append(target)
    except BaseException:
        for target in reversed(done):
            try:
                if backups[target] is not None:
                    os.replace(backups[target], target)
                    backups[target] = None
                else:
                    os.unlink(target)
            except OSError:
                pass
        raise
    finally:
        for backup in backups.values():
            if backup is not None:
                try:
                    os.unlink(backup)
                except OSError:
                    pass


def write_together(outputs: Iterable[tuple[object, Callable[[str], None]]]) -> list[Path]:
    """Write the files of one command, replaced together or not at all (see replace_together).

    outputs: (final path, write) pairs; write(tmp) writes the complete file at the temporary path
    tmp (a str in the target's folder). Returns the final paths. Raises OutputError when a file
    cannot be written; then no target has changed.
    """
    outputs = list(outputs)
    with replace_together([path for path, _ in outputs]) as temporaries:
        for tmp, (_, write) in zip(temporaries, outputs):
            write(tmp)
    return [Path(path) for path, _ in outputs]


@contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; rename it to ``path`` only if the block succeeds."""
    with replace_together([path]) as (tmp,):
        yield tmp


# -- OpenEXR (scanlines, ZIP) ---------------------------------------------------------------------
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


def exr_channels(images) -> dict:
    """EXR channel name -> 2-D array (float32, or uint32 for id) as the file stores it."""
    out = {}
    for name, (array, kind) in exr_channel_arrays(images).items():
        out[name] = _stored(array, kind)
    return out


def _stored(array, kind: str) -> np.ndarray:
    if kind == "UINT":
        return np.ascontiguousarray(array).astype("<i4", copy=False).view("<u4")
    return np.ascontiguousarray(array, dtype="<f4")


def _attribute(name: str, kind: str, value: bytes) -> bytes:
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


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


class Background:
    """A writer's work, done in order on one thread of its own while the caller renders the next
    band: at most `depth` jobs wait (so at most that many bands are held); a job's error is raised
    in the caller by the next submit or by finish."""

    def __init__(self, depth: int = 2):
        self.pool = ThreadPoolExecutor(max_workers=1)
        self.pending: deque = deque()
        self.depth = depth

    def submit(self, job, *args) -> None:
        self.pending.append(self.pool.submit(job, *args))
        while len(self.pending) > self.depth or (self.pending and self.pending[0].done()):
            self.pending.popleft().result()

    def finish(self) -> None:
        while self.pending:
            self.pending.popleft().result()

    def stop(self) -> None:
        """After a failure: drop the waiting jobs and wait for the running one."""
        self.pool.shutdown(wait=True, cancel_futures=True)


class ExrWriter:
    """Writes a single-part scanline OpenEXR file (ZIP) from bands of rows, top to bottom.

    channels: name -> "FLOAT" or "UINT"; write(band) takes name -> (rows, width) arrays (floats of
    any width are rounded to float32; integers are stored by their 32-bit pattern), any number of
    rows at a time, and returns at once: the chunks are compressed (on up to 4 threads) and
    written in the background; close() waits for them and finishes the file (an error if rows are
    missing); stop() abandons the file after a failure."""

    def __init__(self, file, width: int, height: int, channels: dict, comment: str | None = None):
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


# -- PNG ------------------------------------------------------------------------------------------
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


def depth_preview(depth: np.ndarray) -> np.ndarray:
    """The depth preview of a whole image (see DepthPreview)."""
    return preview("depth", depth)


def normal_preview(normal: np.ndarray) -> np.ndarray:
    """The normal preview of a whole image (see NormalPreview)."""
    return preview("normal", normal)


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


class IdPreview(OnePassPreview):
    """Each shape id in its own colour (id_colors), misses black: one pass (a colour per id)."""

    def rgb(self, ids) -> np.ndarray:
        return id_preview(ids)


class ShadedPreview(OnePassPreview):
    """The shaded image clamped to [0, 1] and sRGB-encoded (srgb_preview): one pass."""

    def rgb(self, linear) -> np.ndarray:
        return srgb_preview(linear)


# AOV -> its preview, in the order of the files (zdepth is shown like depth; positions have none)
PREVIEWS.update({"id": IdPreview, "zdepth": DepthPreview, "shaded": ShadedPreview})


def preview_paths(out, aovs=tuple(PREVIEWS)) -> dict:
    """OUT.exr -> {"depth": OUT.depth.png, "normal": OUT.normal.png} (for the AOVs given that have one)."""
    out = Path(out)
    stem = out.with_suffix("") if out.suffix.lower() == ".exr" else out
    return {name: stem.with_name(f"{stem.name}.{name}.png") for name in PREVIEWS if name in aovs}


# -- a render's files -------------------------------------------------------------------------------
def frame_bands(frame, rows: int = 256) -> Iterator[dict]:
    """A whole frame as bands of rows (views)."""
    height = next(iter(frame.values())).shape[0]
    for start in range(0, height, rows):
        yield {name: array[start:start + rows] for name, array in frame.items()}


def band_rows(width: int, budget_pixels: int = 1 << 22) -> int:
    """Rows per band: whole EXR chunks, about budget_pixels per band (4 Mpx: ~80 MB of fp32 images)."""
    return max(_ZIP_LINES, budget_pixels // max(width, 1) // _ZIP_LINES * _ZIP_LINES)


def write_images(out, bands: Iterable[dict], *, width: int, height: int, aovs, previews: bool = False,
                 comment: str | None = None) -> list[Path]:
    """Stream the images of a render into OUT.exr and, with previews, OUT.<aov>.png for each AOV
    that has one, all replaced together (see replace_together). bands: name -> (rows, width, ...)
    arrays, top to bottom, covering the image once. Memory: a few bands (the one being made, and
    at most two waiting per writer while the background compresses); a preview that needs the
    whole image's scale (depth) keeps its AOV in an unnamed temporary file beside the output and
    makes its rows in a second pass.
    Returns the paths written."""
    aovs = tuple(aovs)
    pngs = preview_paths(out, aovs) if previews else {}
    targets = [Path(out), *pngs.values()]
    channels = {name: kind for name, (_, kind) in exr_channel_arrays(empty_images(aovs)).items()}
    with replace_together(targets) as temporaries, ExitStack() as files:
        exr = ExrWriter(files.enter_context(open(temporaries[0], "wb")), width, height, channels, comment)
        files.callback(exr.stop)  # after a failure: no background job writes on (closes run last first)
        writers = {name: PngWriter(files.enter_context(open(tmp, "wb")), width, height) for name, tmp in zip(pngs, temporaries[1:])}
        for writer in writers.values():
            files.callback(writer.stop)
        makers = {name: PREVIEWS[name]() for name in pngs}
        # a preview that needs the whole image's scale keeps its AOV in an unnamed file meanwhile
        spills = {name: files.enter_context(tempfile.TemporaryFile(dir=Path(out).parent))
                  for name, maker in makers.items() if maker.two_pass}
        layouts = {}
        for band in bands:
            exr.write({name: array for name, (array, _) in exr_channel_arrays(band).items()})
            for name, maker in makers.items():
                maker.measure(band[name])
                if name in spills:
                    array = np.ascontiguousarray(band[name], dtype=np.float32)  # as the EXR stores it
                    layouts[name] = array.shape[1:]
                    spills[name].write(array.data)  # (numpy's tofile reports a full disk as a short write)
                else:
                    writers[name].write(maker.rgb(band[name]))
        exr.close()
        for name, spill in spills.items():  # second pass: the previews that needed the whole image's scale
            spill.seek(0)
            shape = layouts.get(name, (width,))
            rows = band_rows(width)
            for start in range(0, height, rows):
                count = min(rows, height - start)
                array = np.fromfile(spill, np.float32, count * int(np.prod(shape))).reshape((count, *shape))
                writers[name].write(makers[name].rgb(array))
        for writer in writers.values():
            writer.close()
    return targets


def empty_images(aovs) -> dict:
    """Zero-size arrays of the AOVs' dtypes and channels (what exr_channel_arrays needs to know)."""
    shapes = {"normal": (0, 0, 3), "position": (0, 0, 3), "shaded": (0, 0, 3)}
    kinds = {"id": np.int32}
    return {aov: np.zeros(shapes.get(aov, (0, 0)), kinds.get(aov, np.float32)) for aov in aovs}


def write_exr(path, frame, comment: str | None = None) -> None:
    """One EXR file of a frame's images (replaced as a whole, see replace_together)."""
    height, width = next(iter(frame.values())).shape[:2]
    write_images(path, frame_bands(frame), width=width, height=height, aovs=tuple(frame), comment=comment)
