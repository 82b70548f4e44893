"""The lower level of two (DESIGN.md item 12): one BVH per shared mesh, in the mesh's own (object)
space, over one copy of its triangles, shared by all its instances (pyclray/model/shapes/instance.py).

The prepared scene's top-level BVH holds each instance as one entry (its world box, beside the other
bounded shapes); the instance's entry says where its mesh's tree and triangles start in the shared
arrays (``root``, ``first``), each tree's indices relative to those starts (kernels/instance.cl
traverses it with kernels/bvh_packet.h's packet traversal from nodes + root). Each tree takes an even
number of binary nodes (its 2L - 1 and a spare one, L its leaves), so that at one ray per work-item
(a GPU's lane width) its pair nodes, L slots a tree (engine/bvh/pairs.py: L - 1 nodes, or one for a
tree that is a leaf), start at root / 2 in the trees' pair nodes (pair_nodes, made when a program
traversing them first asks), found from the entry's root alone (kernels/instance.cl: INSTANCE_ROOT)."""
from __future__ import annotations

import numpy as np

from ...model.layout import layout
from ..bvh.pairs import PAIR_NODE, leaf_codes, pack_pairs
from ..bvh.tree import BVH, NODE, build, pack_nodes, widened
from .indexed import indexed_bounds

# leaves of the mesh's own tree: as a mesh's in the scene's tree (Mesh.leaf_size: about a packet's lanes)
LEAF_SIZE = 7
# the node after each tree's binary nodes (an even count: pair_nodes): never read
_SPARE_NODE = np.zeros(1, layout(NODE, "fp32").dtype)


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
            nodes.append(_SPARE_NODE)  # an even count: its pair nodes start at root / 2 (pair_nodes)
            unit = np.zeros_like(points)
            if key in smooth:  # the placement's are these through its normal matrix (a mesh's vertex_normals)
                unit[:, :3] = own.vertex_normals()
            normals.append(unit)
            root += tree.nodes + 1
            first += len(own_faces)
            base += len(points)
        world["root"][k], world["first"][k] = starts[key]
    # the vertex normals only where some instance is smooth (else one entry: the kernel reads none)
    normals = np.concatenate(normals) if smooth else normals[0][:1]
    return [np.concatenate(vertices), np.concatenate(faces).astype(np.int32), np.concatenate(nodes), normals]


def pair_nodes(binary: np.ndarray, roots) -> np.ndarray:
    """The pair nodes (PAIR_NODE) of the trees packed in binary (pack_shared's nodes; roots: each
    tree's first node), each tree's L slots from root / 2 on: its pair nodes (pack_pairs, with the
    same boxes and each leaf's code ~(first * 8 + count), first from the tree's first triangle, as
    its binary leaf's), then an unused one where a tree's L - 1 leave one."""
    out = np.zeros(len(binary) // 2, layout(PAIR_NODE, "fp32").dtype)
    starts = np.unique(np.asarray(roots, np.int64))
    for root, end in zip(starts, [*starts[1:], len(binary)]):
        own = binary[root:end - 1]  # the tree's nodes, its spare one left out
        first, count = own["lo"][:, 3].view(np.int32), own["hi"][:, 3].view(np.int32)
        tree = BVH(own["lo"][:, :3], own["hi"][:, :3], first, count, np.zeros(0, np.int64))
        pairs = pack_pairs(tree, own, leaf_codes(tree))
        out[root // 2: root // 2 + len(pairs)] = pairs
    return out


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
