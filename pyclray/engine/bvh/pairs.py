"""The BVH for one ray per work-item (GPUs: a lane width of 1): the binary tree's internal nodes, each
holding both its children's boxes (Aila and Laine, "Understanding the efficiency of ray traversal
on GPUs", HPG 2009), 64 bytes a node.

A ray reads a node in one 64-byte load (four float4: one cache line, the loads of a warp's rays
coalesced where they walk the same nodes), tests both children's boxes, goes on to the nearer one
entered and pushes the other: one node read per binary level, where the binary layout
(pyclray.engine.bvh.tree: a box per node) reads both children's nodes to choose. The boxes are the
binary tree's (tree.pack_nodes: rounded outward to float around the same origin) and a leaf's code
is the wide tree's (~(first * 8 + count), after cast's regroup where it rewrote them): the leaves
a ray's box tests keep are those the wide tree's would, and every shape test, tie rule and result
is the same (kernels/bvh_pairs.h). Why this layout and not a compressed 8-wide one:
docs/benchmarks.md, "On a GPU"."""
from __future__ import annotations

import numpy as np

from ...model.layout import Struct, layout
from .tree import _FLOAT_MAX, BVH
from .wide import WideBVH

PAIR_NODE = Struct(
    "PairNode",
    (
        ("left_lo", "float4"),  # xyz: the first child's box's low corner; w: the bits of its int code
        ("left_hi", "float4"),  # xyz: its high corner (w unused)
        ("right_lo", "float4"),  # the second child's, the same (code 0: no second child, a root leaf's node)
        ("right_hi", "float4"),
    ),
    "A node of the binary BVH for one ray per work-item (kernels/bvh_pairs.h): both children's boxes and "
    "codes (>= 0: a node; < 0: ~(first * 8 + count), a leaf of refs[first .. first + count - 1]).",
)


def leaf_codes(tree: BVH, wide: WideBVH | None = None, wide_child: np.ndarray | None = None) -> np.ndarray:
    """(M,) int64: per binary node the code a leaf has in the wide nodes (wide_child: their packed
    "child" column, cast's leaves rewritten by its regroup), else its own ~(first * 8 + count);
    meaningless for internal nodes."""
    codes = ~(tree.first.astype(np.int64) * 8 + tree.count.astype(np.int64))
    if wide is not None and wide_child is not None:
        held = wide.binary >= 0
        leaf = held & (tree.count[np.maximum(wide.binary, 0)] > 0)
        codes[wide.binary[leaf]] = wide_child[leaf]
    return codes


def pack_pairs(tree: BVH, binary: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """The pair nodes (PAIR_NODE) of a binary tree: binary, its nodes as tree.pack_nodes packs them
    (their boxes around the kernels' origin), codes: per binary node its leaf code (leaf_codes).
    Node 0 is the root's; a node's children are numbered after it. A tree that is one leaf has one
    node, that leaf its first child and no second (code 0, an empty box)."""
    inner = np.flatnonzero(tree.count == 0)
    words = layout(PAIR_NODE, "fp32").dtype
    if not inner.size:  # the root is a leaf
        out = np.zeros(1, words)
        out["left_lo"][0, :3], out["left_hi"][0, :3] = binary["lo"][0, :3], binary["hi"][0, :3]
        out["left_lo"][0, 3] = np.int32(codes[0]).view(np.float32)
        out["right_lo"][0, :3], out["right_hi"][0, :3] = _FLOAT_MAX, -_FLOAT_MAX
        return out
    index = np.zeros(tree.nodes, np.int64)
    index[inner] = np.arange(len(inner))  # the root (node 0) is inner[0]: children follow their parents
    out = np.empty(len(inner), words)
    for side, name in ((0, "left"), (1, "right")):
        child = tree.first[inner].astype(np.int64) + side
        out[f"{name}_lo"][:, :3] = binary["lo"][child, :3]
        out[f"{name}_hi"][:, :3] = binary["hi"][child, :3]
        code = np.where(tree.count[child] == 0, index[child], codes[child]).astype(np.int32)
        out[f"{name}_lo"][:, 3] = code.view(np.float32)
        out[f"{name}_hi"][:, 3] = 0.0
    return out
