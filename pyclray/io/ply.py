"""Point clouds as PLY files (binary little-endian): a render's hit pixels or a LiDAR scan's hits,
with their normals, ids and labels, readable by Open3D (``o3d.io.read_point_cloud``), trimesh and
plyfile. One ``vertex`` element: x, y, z (double: world coordinates keep their float64 digits far
from the origin), nx, ny, nz (float), id and label (int), and per source: a render's pixel ``row``
and ``column``; a scan's ``ring``, ``column`` and ``range``."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model.errors import RequestError
from .files import write_together

# numpy type -> the PLY type name
_PLY_TYPES = {np.dtype("<f8"): "double", np.dtype("<f4"): "float", np.dtype("<i4"): "int", np.dtype("<u1"): "uchar"}


def cloud_of(data) -> dict:
    """The PLY vertex properties (name -> (M,) array, in file order) of a render's Frame or dict of
    images (its hit pixels, id >= 0, in row-major order: needs position and id; normal and label
    where it has them) or of a Scan (its points in the world)."""
    if "points_world" in data:  # a LiDAR scan
        ring, column = data["ring"], data["column"]
        points = np.asarray(data["points_world"], np.float64)
        normals = np.asarray(data["normal"])[ring, column]
        extra = {"id": data["id"][ring, column], "label": data["label"][ring, column], "ring": ring, "column": column,
                 "range": data["point_range"]}
    else:
        missing = [name for name in ("position", "id") if name not in data]
        if missing:
            raise RequestError(f"a point cloud of a render needs its {' and '.join(missing)} image"
                               f"{'s' if len(missing) > 1 else ''} (aovs=(\"position\", \"normal\", \"id\", \"label\"))")
        ids = np.asarray(data["id"])
        rows, columns = np.nonzero(ids >= 0)
        points = np.asarray(data["position"], np.float64)[rows, columns]
        normals = np.asarray(data["normal"])[rows, columns] if "normal" in data else None
        extra = {"id": ids[rows, columns]}
        if "label" in data:
            extra["label"] = np.asarray(data["label"])[rows, columns]
        extra.update(row=rows, column=columns)
    cloud = {"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]}
    if normals is not None:
        normals = np.asarray(normals, np.float32)
        cloud.update(nx=normals[:, 0], ny=normals[:, 1], nz=normals[:, 2])
    cloud.update({name: np.asarray(value, np.float32 if name == "range" else np.int32) for name, value in extra.items()})
    return cloud


def ply_bytes(cloud: dict, comment: str | None = None) -> bytes:
    """A binary little-endian PLY file of one vertex element with these properties."""
    count = len(next(iter(cloud.values())))
    dtype = np.dtype([(name, np.asarray(array).dtype.newbyteorder("<")) for name, array in cloud.items()])
    table = np.empty(count, dtype)
    for name, array in cloud.items():
        table[name] = array
    lines = ["ply", "format binary_little_endian 1.0"]
    if comment:
        lines.append("comment " + " ".join(comment.split()))
    lines.append(f"element vertex {count}")
    lines += [f"property {_PLY_TYPES[dtype.fields[name][0]]} {name}" for name in cloud]
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode("ascii") + table.tobytes()


def write_ply(path, data, comment: str | None = None) -> Path:
    """Write a render's hit pixels (a Frame with position and id, and normal and label if it has
    them) or a LiDAR Scan's hits as a binary PLY point cloud (see the module's docstring), replaced
    as a whole (io/files.py). Returns the path."""
    path = Path(path)
    payload = ply_bytes(cloud_of(data), comment)

    def write(temporary: str) -> None:
        with open(temporary, "wb") as file:
            file.write(payload)

    return write_together([(path, write)])[0]


def write_scan_npz(path, scan) -> Path:
    """A Scan as one .npz file: every array under its name, with ``pose`` (the sensor's 4x4
    sensor-to-world at the scan's start) and ``t``; replaced as a whole. numpy.load reads it."""
    import io

    buffer = io.BytesIO()
    np.savez(buffer, **scan, pose=np.asarray(scan.pose, np.float64), t=np.float64(scan.t))
    payload = buffer.getvalue()

    def write(temporary: str) -> None:
        with open(temporary, "wb") as file:
            file.write(payload)

    return write_together([(Path(path), write)])[0]
