"""Which meshes share their triangles (the same arrays: the same file in a scene file, the same loaded
Mesh placed many times), and so are packed as instances (pyclray/model/shapes/instance.py)."""
from __future__ import annotations


def shared_key(mesh) -> tuple[int, int]:
    """The identity of a mesh's triangles: meshes of the same arrays share one copy."""
    return id(mesh.vertices), id(mesh.faces)


def split_meshes(meshes, ids) -> dict:
    """{'mesh': (meshes, ids), 'instance': (meshes, ids)}: the meshes whose vertices and faces
    arrays another mesh of the scene shares become instances; the others stay triangles of the
    world (one mesh alone costs less without a second level)."""
    count: dict = {}
    for mesh in meshes:
        key = shared_key(mesh)
        count[key] = count.get(key, 0) + 1
    out: dict = {}
    for mesh, i in zip(meshes, ids):
        kind = "instance" if count[shared_key(mesh)] > 1 else "mesh"
        out.setdefault(kind, ([], []))
        out[kind][0].append(mesh)
        out[kind][1].append(i)
    return out
