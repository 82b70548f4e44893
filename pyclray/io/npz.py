"""NumPy .npz files of a render: every AOV asked as an array under its name (in the render's own
types: an fp64 render stays float64, ids and labels int32), and the camera's pinhole intrinsics `K`
(3x3) and pose `pose` (4x4, camera-to-world, OpenCV's convention: see Camera.intrinsics and
Camera.pose), so that a depth map meets the vision tools without conversion.

The file is what numpy.savez_compressed writes (a zip of deflated .npy members) and numpy.load
reads: a 640x480 view's depth, normal and id take a fraction of their 6 MB (misses and flat
regions compress well). It is written band by band (NpzWriter): a zip member must be written in one piece, so each
AOV's rows wait in an unnamed temporary file beside the output until the last band, and are then
copied into its member; memory stays a few bands, whatever the image size.
"""
from __future__ import annotations

import shutil
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from ..model.errors import OutputError
from .files import reason

CAMERA_ARRAYS = ("K", "pose")  # the arrays beside the AOVs, when the camera is known: (K, pose)


class NpzWriter:
    """Writes an .npz of (height, width, ...) arrays from bands of rows, top to bottom, and of whole
    `extra` arrays (K, pose). write(band) takes name -> (rows, width, ...) arrays (every band the
    same names); close() writes the members, each array's .npy header and then its rows; stop()
    abandons the file after a failure (the spill files vanish with their handles)."""

    def __init__(self, file, width: int, height: int, extra: dict | None = None, spill_folder=None):
        self.file, self.width, self.height = file, width, height
        self.extra = dict(extra or {})
        self.spill_folder = spill_folder
        self.spills: dict = {}  # name -> [unnamed file, dtype, trailing shape, rows written]

    def write(self, band: dict) -> None:
        for name, array in band.items():
            array = np.ascontiguousarray(array)
            if name not in self.spills:
                spill = tempfile.TemporaryFile(dir=self.spill_folder, prefix=".pyclray-npz-")
                self.spills[name] = [spill, array.dtype, array.shape[2:], 0]
            entry = self.spills[name]
            if array.dtype != entry[1] or array.shape[1:] != (self.width, *entry[2]):
                raise ValueError(f"NpzWriter: {name}: a band of {array.dtype}{list(array.shape)} after {entry[1]}")
            entry[0].write(array.data)  # (a full disk is an OSError here, not a short write)
            entry[3] += array.shape[0]

    def close(self) -> None:
        for name, (_, _, _, rows) in self.spills.items():
            if rows != self.height:
                raise ValueError(f"NpzWriter: {name}: {rows} of {self.height} rows written")
        with zipfile.ZipFile(self.file, "w", zipfile.ZIP_DEFLATED, allowZip64=True) as archive:
            for name, (spill, dtype, trailing, _) in self.spills.items():
                header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                          "shape": (self.height, self.width, *trailing)}
                with archive.open(f"{name}.npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array_header_1_0(member, header)
                    spill.seek(0)
                    shutil.copyfileobj(spill, member, 1 << 22)
            for name, array in self.extra.items():
                with archive.open(f"{name}.npy", "w") as member:
                    np.lib.format.write_array(member, np.ascontiguousarray(array), allow_pickle=False)
        self.stop()

    def stop(self) -> None:
        for spill, *_ in self.spills.values():
            spill.close()


def read_npz(path) -> dict:
    """The arrays of an .npz written by write_npz or `pyclray render -o OUT.npz`: AOV name -> array
    (as render returns them), and K and pose where the file has them. A missing, unreadable or
    damaged file, or one that is not an .npz, raises OutputError of one line."""
    path = Path(path)
    try:
        with open(path, "rb") as handle:
            magic = handle.read(2)
    except OSError as error:
        raise OutputError(f"cannot read {path}: {reason(error)}") from None
    if magic != b"PK":  # a zip archive (numpy.load would take anything else for a pickle or an .npy)
        raise OutputError(f"cannot read {path}: not an .npz file")
    try:
        with np.load(path, allow_pickle=False) as archive:
            return {name: archive[name] for name in archive.files}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as error:
        detail = " ".join(str(error).split()) or type(error).__name__
        raise OutputError(f"cannot read {path}: a damaged .npz file ({detail})") from None
