"""A render's files: the images streamed band by band into one EXR and its PNG previews, all
replaced together."""
from __future__ import annotations

import tempfile
from contextlib import ExitStack
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from ..model.aovs import empty_images
from .exr import _ZIP_LINES, ExrWriter, exr_channel_arrays
from .files import replace_together
from .png import PREVIEWS, PngWriter, preview_paths


def frame_bands(frame, rows: int = 256) -> Iterator[dict]:
    """A whole frame as bands of rows (views)."""
    height = next(iter(frame.values())).shape[0]
    for start in range(0, height, rows):
        yield {name: array[start:start + rows] for name, array in frame.items()}


def band_rows(width: int, budget_pixels: int = 1 << 22) -> int:
    """Rows per band: whole EXR chunks, about budget_pixels per band (4 Mpx: ~80 MB of fp32 images)."""
    return max(_ZIP_LINES, budget_pixels // max(width, 1) // _ZIP_LINES * _ZIP_LINES)


def write_images(out, bands: Iterable[dict], *, width: int, height: int, aovs, previews: bool = False,
                 comment: str | None = None, camera=None) -> list[Path]:
    """Stream the images of a render into OUT.exr and, with previews, OUT.<aov>.png for each AOV
    that has one, all replaced together (see replace_together). bands: name -> (rows, width, ...)
    arrays, top to bottom, covering the image once. Memory: a few bands (the one being made, and
    at most two waiting per writer while the background compresses); a preview that needs the
    whole image's scale (depth) keeps its AOV in an unnamed temporary file beside the output and
    makes its rows in a second pass. camera: (K, pose) of the image for the EXR's header, or None.
    Returns the paths written."""
    aovs = tuple(aovs)
    pngs = preview_paths(out, aovs) if previews else {}
    targets = [Path(out), *pngs.values()]
    channels = {name: kind for name, (_, kind) in exr_channel_arrays(empty_images(aovs)).items()}
    with replace_together(targets) as temporaries, ExitStack() as files:
        exr = ExrWriter(files.enter_context(open(temporaries[0], "wb")), width, height, channels, comment, camera)
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


def camera_of(frame):
    """(K, pose) of a render's Frame (its intrinsics and pose), or None (a plain dict of images)."""
    K, pose = getattr(frame, "intrinsics", None), getattr(frame, "pose", None)
    return None if K is None or pose is None else (K, pose)


def write_exr(path, frame, comment: str | None = None) -> None:
    """One EXR file of a frame's images (replaced as a whole, see replace_together); a render's
    Frame also puts its camera (intrinsics and pose) in the header."""
    height, width = next(iter(frame.values())).shape[:2]
    write_images(path, frame_bands(frame), width=width, height=height, aovs=tuple(frame), comment=comment,
                 camera=camera_of(frame))
