"""The checks of a mesh's array keys (vertices, faces, normals) and of its matrix: each bad value a
SceneError naming the key (scene-format.md, "Triangle meshes")."""
from __future__ import annotations

import numpy as np

from ..errors import SceneError, _shown


def vertices_of(value, key="vertices") -> np.ndarray:
    try:
        array = value if _ready(value, np.float64) else np.array(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise SceneError(f"expected an array of shape (V, 3) of numbers, got {_shown(value)}", key=key) from None
    if array.ndim != 2 or array.shape[1] != 3:
        raise SceneError(f"expected an array of shape (V, 3), got shape {array.shape}", key=key)
    bad = ~np.isfinite(array).all(axis=1)
    if bad.any():
        index = int(np.argmax(bad))
        raise SceneError(f"expected finite numbers, got {array[index].tolist()!r} at index {index}", key=key)
    if array.flags.writeable:
        array.setflags(write=False)
    return array


def faces_of(value, count: int) -> np.ndarray:
    try:
        array = value if _ready(value, np.int64) else np.array(value)
    except (TypeError, ValueError):
        raise SceneError(f"expected an array of shape (F, 3) of vertex indices, got {_shown(value)}", key="faces") from None
    if array.size == 0:
        raise SceneError("expected at least one triangle, got none", key="faces")
    if array.ndim != 2 or array.shape[1] != 3:
        raise SceneError(f"expected an array of shape (F, 3) of vertex indices (triangles), got shape {array.shape}",
                         key="faces")
    if array.dtype.kind not in "iu":
        if array.dtype.kind != "f" or not np.all(np.isfinite(array) & (array == np.round(array))):
            raise SceneError("expected whole-number vertex indices", key="faces")
    array = array.astype(np.int64, copy=False)
    bad = ((array < 0) | (array >= count)).any(axis=1)
    if bad.any():
        index = int(np.argmax(bad))
        raise SceneError(f"face {index} is {array[index].tolist()}: expected indices 0 .. {count - 1} "
                         f"(the mesh has {count} vertices)", key="faces")
    array.setflags(write=False)
    return array


def matrix_of(value) -> tuple:
    try:
        m = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"expected a 4x4 matrix of numbers, got {_shown(value)}", key="matrix") from None
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise SceneError(f"expected a 4x4 matrix of finite numbers, got shape {m.shape}", key="matrix")
    if not np.array_equal(m[3], [0, 0, 0, 1]):
        raise SceneError(f"expected an affine matrix (last row 0 0 0 1), got last row {m[3].tolist()}", key="matrix")
    if not abs(np.linalg.det(m[:3, :3])) > 0:
        raise SceneError("expected an invertible matrix, got a singular one", key="matrix")
    return tuple(map(tuple, m.tolist()))


def _ready(array, dtype) -> bool:
    """A read-only array of this type (a file's, or another Mesh's): checked and shared, not copied."""
    return isinstance(array, np.ndarray) and array.dtype == dtype and not array.flags.writeable
