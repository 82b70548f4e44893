"""A render's files: the images streamed band by band into one EXR, .npz or PNG (the format follows
the extension) and PNG previews, all replaced together."""
from __future__ import annotations

import tempfile
from contextlib import ExitStack
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from ..model.aovs import empty_images
from ..model.errors import RequestError
from .exr import _ZIP_LINES, ExrWriter, exr_channel_arrays
from .files import replace_together
from .npz import CAMERA_ARRAYS, NpzWriter
from .png import PREVIEWS, PngWriter, preview_paths


def frame_bands(frame, rows: int = 256) -> Iterator[dict]:
    """A whole frame as bands of rows (views)."""
    height = next(iter(frame.values())).shape[0]
    for start in range(0, height, rows):
        yield {name: array[start:start + rows] for name, array in frame.items()}


def band_rows(width: int, budget_pixels: int = 1 << 22) -> int:
    """Rows per band: whole EXR chunks, about budget_pixels per band (4 Mpx: ~80 MB of fp32 images)."""
    return max(_ZIP_LINES, budget_pixels // max(width, 1) // _ZIP_LINES * _ZIP_LINES)


# -o decides the format from its extension (scene-format.md, "Output files")
OUTPUT_FORMATS = {
    ".exr": "every AOV as channels of one OpenEXR file",
    ".npz": "every AOV as a numpy array under its name, with the camera's K and pose",
    ".png": "the preview of one AOV (the first asked for)",
}


def output_format(path) -> str:
    """"exr", "npz" or "png" from the path's extension; any other is a RequestError."""
    suffix = Path(path).suffix.lower()
    if suffix not in OUTPUT_FORMATS:
        raise RequestError(f"{path}: expected OUT.exr, OUT.npz or OUT.png (the format follows the extension: "
                           f"{'; '.join(f'{k} {v}' for k, v in OUTPUT_FORMATS.items())}), got "
                           f"{repr(suffix) if suffix else 'no extension'}")
    return suffix[1:]


class _ExrBands:
    """ExrWriter fed with bands of AOVs (name -> array) rather than of channels."""

    def __init__(self, writer: ExrWriter):
        self.writer = writer

    def write(self, band: dict) -> None:
        self.writer.write({name: array for name, (array, _) in exr_channel_arrays(band).items()})

    def close(self) -> None:
        self.writer.close()

    def stop(self) -> None:
        self.writer.stop()


def write_images(out, bands: Iterable[dict], *, width: int, height: int, aovs, previews: bool = False,
                 comment: str | None = None, camera=None, format: str | None = None) -> list[Path]:
    """Stream the images of a render into `out`, whose extension says what it is (output_format;
    or `format`, "exr", "npz" or "png", whatever the name):
    OUT.exr (every AOV's channels; camera in its header), OUT.npz (every AOV as an array, and the
    camera as arrays K and pose) or OUT.png (the preview of the first AOV; it must have one); with
    previews (.exr or .npz), also OUT.<aov>.png for each AOV that has one. All are replaced together
    (see replace_together). bands: name -> (rows, width, ...) arrays, top to bottom, covering the
    image once. Memory: a few bands (the one being made, and at most two waiting per writer while
    the background compresses); a preview that needs the whole image's scale (depth) keeps its AOV
    in an unnamed temporary file beside the output and makes its rows in a second pass, and an
    .npz keeps each AOV's rows so until its member is written. camera: (K, pose) of the image, or None.
    Returns the paths written."""
    aovs = tuple(aovs)
    out = Path(out)
    kind = output_format(out) if format is None else format
    if kind not in ("exr", "npz", "png"):
        raise RequestError(f"format: expected exr, npz or png, got {format!r}")
    if kind == "png":
        if previews:
            raise RequestError(f"{out}: a .png output is itself a preview; previews go beside an .exr or .npz")
        if not aovs or aovs[0] not in PREVIEWS:
            raise RequestError(f"{out}: a .png shows the preview of the first AOV asked, and "
                               f"{aovs[0] if aovs else 'none'} has none (those with one: {', '.join(PREVIEWS)})")
        pngs = {aovs[0]: out}
        targets = [out]
    else:
        pngs = preview_paths(out, aovs) if previews else {}
        targets = [out, *pngs.values()]
    with replace_together(targets) as temporaries, ExitStack() as files:
        main = None
        if kind == "exr":
            channels = {name: kind for name, (_, kind) in exr_channel_arrays(empty_images(aovs)).items()}
            main = _ExrBands(ExrWriter(files.enter_context(open(temporaries[0], "wb")), width, height, channels, comment,
                                       camera))
        elif kind == "npz":
            # (K None: a camera model without one, orthographic or a panorama: its pose alone)
            arrays = None if camera is None else {k: v for k, v in zip(CAMERA_ARRAYS, camera) if v is not None}
            main = NpzWriter(files.enter_context(open(temporaries[0], "wb")), width, height, arrays, out.parent)
        if main is not None:
            files.callback(main.stop)  # after a failure: no background job writes on (closes run last first)
        png_temporaries = temporaries if kind == "png" else temporaries[1:]
        writers = {name: PngWriter(files.enter_context(open(tmp, "wb")), width, height) for name, tmp in zip(pngs, png_temporaries)}
        for writer in writers.values():
            files.callback(writer.stop)
        makers = {name: PREVIEWS[name]() for name in pngs}
        # a preview that needs the whole image's scale keeps its AOV in an unnamed file meanwhile
        spills = {name: files.enter_context(tempfile.TemporaryFile(dir=out.parent))
                  for name, maker in makers.items() if maker.two_pass}
        layouts = {}
        for band in bands:
            if main is not None:
                main.write({name: band[name] for name in aovs})
            for name, maker in makers.items():
                maker.measure(band[name])
                if name in spills:
                    array = np.ascontiguousarray(band[name], dtype=np.float32)  # as the EXR stores it
                    layouts[name] = array.shape[1:]
                    spills[name].write(array.data)  # (numpy's tofile reports a full disk as a short write)
                else:
                    writers[name].write(maker.rgb(band[name]))
        if main is not None:
            main.close()
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


def camera_of(frame):
    """(K, pose) of a render's Frame (its intrinsics and pose), or None (a plain dict of images)."""
    K, pose = getattr(frame, "intrinsics", None), getattr(frame, "pose", None)
    return None if pose is None else (K, pose)  # (K None: a camera model without one)


def write_exr(path, frame, comment: str | None = None) -> None:
    """One OpenEXR file of a frame's images (every AOV's channels, see pyclray.io.exr), replaced as
    a whole (see replace_together); a render's Frame also puts its camera (intrinsics and pose) in
    the header. pyclray.read_exr reads it back. An fp64 frame is stored as 32-bit floats (OpenEXR
    has no 64-bit float channels): use write_npz to keep float64."""
    _write_frame(path, frame, "exr", comment=comment)


def write_npz(path, frame) -> None:
    """One .npz file of a frame's images (every AOV as an array under its name, in its own dtype)
    and, for a render's Frame, its camera as arrays `K` (its intrinsics, in the frame's own pixels:
    a window's too) and `pose` (camera-to-world), OpenCV's convention. Replaced as a whole;
    pyclray.read_npz or numpy.load reads it back."""
    _write_frame(path, frame, "npz")


def _write_frame(path, frame, kind: str, **options) -> None:
    if not frame:
        raise RequestError("frame: expected at least one image, got none")
    height, width = next(iter(frame.values())).shape[:2]
    write_images(path, frame_bands(frame), width=width, height=height, aovs=tuple(frame), format=kind,
                 camera=camera_of(frame), **options)
