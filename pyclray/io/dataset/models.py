"""A data set's object models: each labelled shape's triangles in its own space, in millimetres, with
the rigid pose that places them (BOP's models/ and cam_R_m2c, cam_t_m2c), written as PLY with vertex
normals, and BOP's models_info (3D box and diameter)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model.errors import RequestError


@dataclass
class ObjectModel:
    """One object: obj_id (its label), the shapes that are it, its model (vertices in mm, faces) and,
    per shape, world_from_model (4x4, rigid, translation in scene units)."""

    obj_id: int
    name: str
    vertices: np.ndarray
    faces: np.ndarray


def rigid_split(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, S) with A = R S of the 3x3 part of an affine matrix: R a rotation (det +1), S symmetric (the
    polar decomposition; S takes the scale, shear and mirror that a rigid pose cannot carry, and goes
    into the model)."""
    A = np.asarray(matrix, np.float64)[:3, :3]
    U, sigma, Vt = np.linalg.svd(A)
    R = U @ Vt
    S = Vt.T @ np.diag(sigma) @ Vt
    if np.linalg.det(R) < 0:
        R, S = -R, -S
    return R, S


def model_pose(shape) -> tuple[np.ndarray, np.ndarray]:
    """(world_from_model 4x4 rigid, S): the shape's frame without the part S baked into its model."""
    frame = shape.object_pose()
    R, S = rigid_split(frame)
    pose = np.eye(4)
    pose[:3, :3] = R
    pose[:3, 3] = frame[:3, 3]
    return pose, S


def object_models(shapes, millimetres: float) -> dict[int, ObjectModel]:
    """obj_id -> ObjectModel of the labelled shapes (scene units times `millimetres` is mm). Shapes
    sharing a label must be one model (the same triangles once their scale is baked in); a labelled
    shape without a triangle model is a RequestError (BOP needs a mesh per object)."""
    models: dict[int, ObjectModel] = {}
    for shape in shapes:
        model = shape.object_model()
        if model is None or shape.object_pose() is None:
            raise RequestError(f"--format bop: {shape.describe()} has label {shape.label} but no triangle model (BOP "
                               "objects are meshes); remove its label to make it scenery, or make it a mesh")
        vertices, faces = model
        _, S = model_pose(shape)
        baked = (np.asarray(vertices, np.float64) @ S.T) * millimetres
        known = models.get(shape.label)
        if known is None:
            models[shape.label] = ObjectModel(shape.label, getattr(shape, "name", str(shape.label)), baked,
                                              np.asarray(faces, np.int64))
        elif not (known.vertices.shape == baked.shape and np.array_equal(known.faces, faces)
                  and np.allclose(known.vertices, baked, rtol=1e-9, atol=1e-9 * float(np.abs(baked).max() or 1))):
            raise RequestError(f"--format bop: {shape.describe()} has label {shape.label}, as {known.name!r}, but another "
                               "model: shapes sharing a label (a BOP obj_id) must be the same mesh at the same scale")
    return models


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit vertex normals: the area-weighted sum of the faces' normals at each vertex (0 where none)."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    weighted = np.cross(b - a, c - a)
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, faces[:, k], weighted)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.where(length > 0, normals / np.where(length > 0, length, 1.0), 0.0)


def ply_bytes(model: ObjectModel) -> bytes:
    """The model as an ASCII PLY (BOP's models are ASCII, with vertex normals): x y z nx ny nz per
    vertex as `property float` (9 significant digits: each float32 exactly), faces as `property list
    uchar int vertex_indices`."""
    normals = vertex_normals(model.vertices, model.faces)
    header = (
        "ply\nformat ascii 1.0\ncomment pyclray data set model, mm\n"
        f"element vertex {len(model.vertices)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        f"element face {len(model.faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    rows = np.hstack([model.vertices, normals]).astype(np.float32).astype(np.float64)
    vertex_lines = ("%.9g %.9g %.9g %.9g %.9g %.9g\n" * len(rows)) % tuple(rows.ravel().tolist())
    face_lines = ("3 %d %d %d\n" * len(model.faces)) % tuple(model.faces.ravel().tolist())
    return (header + vertex_lines + face_lines).encode()


# diameter's runs of nearby points: DIAMETER_RUN consecutive points in the order of a Z curve through
# a grid of 2^DIAMETER_BITS cells per axis
DIAMETER_BITS = 10
DIAMETER_RUN = 64


def _z_order(points: np.ndarray) -> np.ndarray:
    """The order of the points along a Z (Morton) curve through a grid over their box: runs of
    consecutive points lie close together."""
    low, high = points.min(axis=0), points.max(axis=0)
    cells = ((points - low) / np.where(high > low, high - low, 1.0) * ((1 << DIAMETER_BITS) - 1)).astype(np.int64)
    code = np.zeros(len(points), np.int64)
    for bit in range(DIAMETER_BITS):
        for axis in range(3):
            code |= ((cells[:, axis] >> bit) & 1) << (3 * bit + axis)
    return np.argsort(code, kind="stable")


def diameter(points: np.ndarray) -> float:
    """The largest distance between two of the points, exactly (no sampling): the best pair found
    from the extremes bounds it from below; only the points far enough from the box's centre to
    reach beyond it can be the pair; in runs of nearby points (_z_order), the pairs of runs whose
    boxes are farther apart than the best so far have the squared distances of all their pairs
    computed from matrix products (|a|^2 + |b|^2 - 2 a.b), and the pairs within their rounding of
    the largest are measured again directly."""
    points = np.asarray(points, np.float64)
    if len(points) < 2:
        return 0.0
    centre = (points.min(axis=0) + points.max(axis=0)) / 2
    points = points - centre
    reach = np.linalg.norm(points, axis=1)
    extremes = np.unique(np.concatenate([points.argmin(axis=0), points.argmax(axis=0), [reach.argmax()]]))
    best = float(np.max(np.linalg.norm(points[extremes][:, None] - points[None], axis=2)))
    points = points[reach + reach.max() >= best]
    points = points[_z_order(points)]
    squares = (points**2).sum(axis=1)
    slack = 16 * np.finfo(np.float64).eps * 4 * float(squares.max())  # the products' rounding, generously
    starts = np.arange(0, len(points), DIAMETER_RUN)
    run_low, run_high = np.minimum.reduceat(points, starts), np.maximum.reduceat(points, starts)
    largest, pairs = best**2, []
    for i, start in enumerate(starts):
        # the largest squared distance between this run's box and each later one's (per axis the
        # farther of the two face pairs), a little over its rounding
        span = np.maximum(run_high[i] - run_low[i:], run_high[i:] - run_low[i])
        others = np.flatnonzero((span**2).sum(axis=1) * (1 + 1e-9) >= largest - slack) + i
        if not len(others):
            continue
        columns = (starts[others][:, None] + np.arange(DIAMETER_RUN)).ravel()
        columns = columns[columns < len(points)]
        block = points[start:start + DIAMETER_RUN]
        d2 = squares[start:start + DIAMETER_RUN, None] + squares[None, columns] - 2.0 * (block @ points[columns].T)
        top = float(d2.max())
        if top >= largest - slack:
            largest = max(largest, top)
            rows, at = np.nonzero(d2 >= largest - slack)
            pairs.append((rows + start, columns[at]))
    for rows, columns in pairs:
        exact = np.sqrt(((points[rows] - points[columns]) ** 2).sum(axis=1))
        best = max(best, float(exact.max()) if len(exact) else best)
    return best


def model_info(model: ObjectModel) -> dict:
    """BOP's models_info entry: diameter, min_x, min_y, min_z, size_x, size_y, size_z (mm)."""
    low, high = model.vertices.min(axis=0), model.vertices.max(axis=0)
    info = {"diameter": diameter(model.vertices)}
    for axis, lo, size in zip("xyz", low, high - low):
        info[f"min_{axis}"] = float(lo)
        info[f"size_{axis}"] = float(size)
    return info
