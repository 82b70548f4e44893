"""Which meshes share their triangles (the same arrays: the same file in a scene file, the same loaded
Mesh placed many times), and so are packed as instances (pyclray/model/shapes/instance.py)."""
from __future__ import annotations

import numpy as np

# The most an instance's placement may magnify the rounding of its object-space coordinates in
# world space (rounding_gains). An instance rounds its triangles and rays in object space, each
# coordinate to its own float32 precision; a placement that scales across its object axes (a
# matrix: a scale after a rotation, a shear) turns that rounding into a world error of up to its
# condition number times eps t, where a copy's is eps t: a sphere squashed 1:3000 let a ray through
# its face near the rim (tests/test_instance_exact.py). Up to this gain the error stays within the
# error model's position error, K eps (t + L) (pyclray/reference/error_model.py); above it the mesh
# is packed as its own world triangles, as a copy.
INSTANCE_ROUNDING_GAIN = 4.0


def shared_key(mesh) -> tuple[int, int]:
    """The identity of a mesh's triangles: meshes of the same arrays share one copy."""
    return id(mesh.vertices), id(mesh.faces)


def rounding_gains(meshes) -> np.ndarray:
    """Per mesh: how much its placement M magnifies a rounding of object-space coordinates (each
    coordinate's error relative to itself) in world space, max over the object axes i of
    |M e_i| |row i of M^-1|: 1 for scale, axis and angle (a rotation after per-axis scales), up to
    M's condition number for a matrix that scales across its object axes."""
    gains = np.ones(len(meshes))
    placed = [k for k, mesh in enumerate(meshes) if mesh.matrix is not None]
    if placed:
        linear = np.array([meshes[k].transform()[:3, :3] for k in placed])
        with np.errstate(all="ignore"):
            inverse = np.linalg.inv(linear)
            gain = (np.linalg.norm(linear, axis=1) * np.linalg.norm(inverse, axis=2)).max(axis=1)
        gains[placed] = np.where(np.isfinite(gain), gain, np.inf)
    return gains


def split_meshes(meshes, ids) -> dict:
    """{'mesh': (meshes, ids), 'instance': (meshes, ids)}: the meshes whose vertices and faces
    arrays another mesh of the scene shares become instances; the others stay triangles of the
    world (one mesh alone costs less without a second level), as do meshes whose placement would
    magnify an instance's rounding beyond INSTANCE_ROUNDING_GAIN (rounded as copies instead)."""
    shareable = rounding_gains(meshes) <= INSTANCE_ROUNDING_GAIN
    count: dict = {}
    for mesh, ok in zip(meshes, shareable):
        if ok:
            key = shared_key(mesh)
            count[key] = count.get(key, 0) + 1
    out: dict = {}
    for mesh, i, ok in zip(meshes, ids, shareable):
        kind = "instance" if ok and count[shared_key(mesh)] > 1 else "mesh"
        out.setdefault(kind, ([], []))
        out[kind][0].append(mesh)
        out[kind][1].append(i)
    return out
