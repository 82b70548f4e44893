"""The wide BVH the kernels traverse: the binary tree (pyclray.engine.bvh.tree) collapsed three levels at
a time, up to 8 children a node, their boxes tested at once in one float8 test per visit."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model.layout import Struct, layout
from .tree import _FLOAT_MAX, BVH, SAH_FROM, outward32

WIDTH = 8  # children per wide node: one float8 box test of all of them per visit
STACK = 256  # kernels/bvh.h: BVH_STACK

WIDE_NODE = Struct(
    "WideNode",
    (
        ("lo_x", "float8"),  # the children's boxes, one lane per child (empty slots: lo > hi)
        ("lo_y", "float8"),
        ("lo_z", "float8"),
        ("hi_x", "float8"),
        ("hi_y", "float8"),
        ("hi_z", "float8"),
        ("child", "int8"),  # >= 0: a wide node; < 0: ~(first * 8 + count), a leaf of refs[first .. first + count - 1]
    ),
    "A node of the wide BVH (kernels/bvh.h): up to 8 children's boxes, tested at once.",
)


@dataclass(frozen=True)
class WideBVH:
    """The binary tree collapsed three levels at a time: each wide node holds the (up to 8) nodes
    three binary levels below a binary internal node, stopping early at leaves. Boxes are the
    binary tree's, unchanged, so its traversal tests exactly the boxes the binary one would."""

    binary: np.ndarray  # (W, 8) the binary node of each child slot, -1 for an empty slot
    child: np.ndarray  # (W, 8) int32 child codes (see WIDE_NODE)
    depth: int  # levels of wide nodes


def collapse(tree: BVH) -> WideBVH:
    """The wide BVH of a binary one (root: wide node 0). Each wide node starts from a binary
    internal node's two children and opens, up to 8 slots, the internal child of largest surface
    area into its two children (the greedy of Wald et al.'s wide BVHs), all wide nodes of a level
    at once."""
    extent = np.maximum(tree.hi - tree.lo, 0.0)
    area = extent[:, 0] * extent[:, 1] + extent[:, 1] * extent[:, 2] + extent[:, 2] * extent[:, 0]
    inner_node = tree.count == 0
    if not inner_node[0]:  # a single leaf: one wide node with one child
        slots = np.full((1, WIDTH), -1, np.int64)
        slots[0, 0] = 0
        levels = [slots]
    else:
        levels, frontier = [], np.array([0])
        while frontier.size:
            slots = np.full((len(frontier), WIDTH), -1, np.int64)
            slots[:, 0] = tree.first[frontier]
            slots[:, 1] = tree.first[frontier] + 1
            rows = np.arange(len(frontier))
            for used in range(2, WIDTH):
                safe = np.maximum(slots, 0)
                opening = (slots >= 0) & inner_node[safe]
                if not opening.any():
                    break
                pick = np.argmax(np.where(opening, area[safe], -1.0), axis=1)
                can = opening[rows, pick]
                chosen = slots[rows, pick]
                slots[rows[can], pick[can]] = tree.first[chosen[can]]
                slots[rows[can], used] = tree.first[chosen[can]] + 1
            levels.append(slots)
            frontier = slots[(slots >= 0) & inner_node[np.maximum(slots, 0)]]
    binary = np.concatenate(levels)
    # wide node numbers in the order made: the internal slots of level L, in order, are the wide
    # nodes of level L + 1
    internal = (binary >= 0) & inner_node[np.maximum(binary, 0)]
    wide_index = np.full(binary.shape, -1, np.int64)
    wide_index[internal] = 1 + np.arange(int(internal.sum()))
    leaf = (binary >= 0) & ~internal
    b = np.maximum(binary, 0)
    code = np.where(internal, wide_index, np.where(leaf, ~(tree.first[b].astype(np.int64) * 8 + tree.count[b]), 0))
    return WideBVH(binary, code.astype(np.int32), len(levels))


def pack_wide(tree: BVH, wide: WideBVH, origin, rows=None) -> np.ndarray:
    """The wide nodes as the kernel reads them (WIDE_NODE), boxes relative to origin (float64,
    before rounding outward): the scene's anchor (render and cast); rows: only these wide nodes (an
    animation's refitted ones), default all."""
    binary, child = (wide.binary, wide.child) if rows is None else (wide.binary[rows], wide.child[rows])
    out = np.zeros(len(binary), dtype=layout(WIDE_NODE, "fp32").dtype)
    origin = np.asarray(origin, np.float64)
    out["child"] = child
    if tree.nodes >= SAH_FROM:  # one compiled pass (bvh_fast: the same bits), numba being imported by then
        from .passes import pack_wide_boxes

        pack_wide_boxes(np.ascontiguousarray(tree.lo), np.ascontiguousarray(tree.hi),
                        np.ascontiguousarray(binary, dtype=np.int64), origin,
                        out.view(np.float32).reshape(len(binary), 56))
        return out
    b = np.maximum(binary, 0)
    lo, hi = outward32(tree.lo[b] - origin, tree.hi[b] - origin)
    empty = binary < 0
    lo[empty], hi[empty] = _FLOAT_MAX, -_FLOAT_MAX
    for axis, name in enumerate("xyz"):
        out[f"lo_{name}"] = lo[..., axis]
        out[f"hi_{name}"] = hi[..., axis]
    return out


def row_of(wide: WideBVH, count: int) -> np.ndarray:
    """Per node of the binary tree (of count nodes), the wide node whose slot holds it (-1 for the
    root, which none holds): the rows an animation's refit of some binary nodes rewrites."""
    held = wide.binary >= 0
    rows = np.full(count, -1, np.int64)
    rows[wide.binary[held]] = np.nonzero(held)[0]  # (the row of each held slot, in the same order)
    return rows
