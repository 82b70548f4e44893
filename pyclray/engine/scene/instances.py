"""The lower level of two (DESIGN.md item 12): one BVH per shared mesh, in the mesh's own (object)
space, over one copy of its triangles, shared by all its instances (pyclray/model/shapes/instance.py).

The prepared scene's top-level BVH holds each instance as one entry (its world box, beside the other
bounded shapes); the instance's entry says where its mesh's tree and triangles start in the shared
arrays (``root``, ``first``), each tree's indices relative to those starts (kernels/instance.cl
traverses it with kernels/bvh_packet.h's packet traversal from nodes + root)."""
from __future__ import annotations

import numpy as np

from ..bvh.tree import build, pack_nodes, widened
from .indexed import indexed_bounds

# leaves of the mesh's own tree: as a mesh's in the scene's tree (Mesh.leaf_size: about a packet's lanes)
LEAF_SIZE = 7


def pack_shared(cls, meshes, world) -> list[np.ndarray]:
    """The shared arrays of these instances (cls.shared's order: the meshes' object-space vertices,
    their faces in each tree's leaf order (vertex indices into those vertices, and each triangle's
    index in its mesh, ~index where it has zero area: Mesh.pack_indexed's), the trees' binary nodes
    around each mesh's anchor, and the vertices' unit object-space normals where an instance of
    their mesh is smooth, else 0: only where some instance is smooth), each distinct mesh once;
    writes each instance's root and first into world. Per triangle of a closed mesh: a face (16
    bytes), half a vertex (32 bytes each) and the tree's share, about 48 bytes (the world triangles
    and their indices took 100)."""
    from ...model.shapes.mesh_sharing import shared_key
    from ...model.shapes.mesh import Mesh

    vertices, faces, nodes, normals = [], [], [], []
    smooth = {shared_key(mesh) for mesh in meshes if mesh.smooth}
    starts: dict = {}
    root = first = base = 0
    for k, mesh in enumerate(meshes):
        key = shared_key(mesh)
        if key not in starts:
            own = mesh.placed()  # the same arrays in object space (no placement)
            points, own_faces = Mesh.pack_indexed([own])
            # the bounds of the world triangles' (the same bits), without packing them
            tree = build(widened(indexed_bounds(points, own_faces)), LEAF_SIZE, "sah" if len(own_faces) > 1 else None)
            starts[key] = (root, first)
            own_faces = own_faces[tree.order]
            own_faces[:, :3] += base
            vertices.append(points)
            faces.append(own_faces)
            nodes.append(pack_nodes(tree, world["anchor"][k, :3]))
            unit = np.zeros_like(points)
            if key in smooth:  # the placement's are these through its normal matrix (a mesh's vertex_normals)
                unit[:, :3] = own.vertex_normals()
            normals.append(unit)
            root += tree.nodes
            first += len(own_faces)
            base += len(points)
        world["root"][k], world["first"][k] = starts[key]
    # the vertex normals only where some instance is smooth (else one entry: the kernel reads none)
    normals = np.concatenate(normals) if smooth else normals[0][:1]
    return [np.concatenate(vertices), np.concatenate(faces).astype(np.int32), np.concatenate(nodes), normals]


def instance_bytes(prepared) -> dict:
    """What the instances of a prepared scene cost: bytes per instance of their own (world entry,
    per-view entry, their share of the top-level tree's nodes and refs) and of the shared arrays."""
    kind = prepared.kinds.get("instance")
    if kind is None:
        return {}
    count = kind.count
    entries = len(prepared.bvh.leaf_type) or 1
    own = kind.world.itemsize + kind.in_view_host.itemsize
    tlas = (prepared._wide_host.nbytes + entries * 4) / entries  # the (wide) tree and refs per entry
    return {"instances": count, "own_bytes_per_instance": own, "tlas_bytes_per_instance": tlas,
            "bytes_per_instance": own + tlas, "shared_bytes": sum(a.nbytes for a in kind.shared_host)}
