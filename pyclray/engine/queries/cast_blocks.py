"""cast's leaves in blocks: a leaf's entries of one shape of a type that tests them at once
(the capability "cast_blocks": a mesh's triangles, kernels/mesh.cl) become one ref, one anchor and one block.

For 100,000 incoherent rays through a mesh, cast read per triangle it tested a ref, its mesh's
anchor (32 bytes) and its float64 world entry (96 bytes), each a scattered read, and ran the
triangle's test alone; a block holds a leaf's triangles of one mesh in whole cache lines (72 bytes a
triangle, rows of coordinates) and one 8-wide test runs them all, to the same bits per triangle.
The wide tree's leaf codes are renumbered to the new refs; the other types' entries keep theirs.
"""
from __future__ import annotations

import numpy as np

from ...model.errors import RequestError
from ...model.shapes.capabilities import capability

# a ref holds its index shifted by 4 bits in an int: a block's place (64-byte units) below 2^27
MAX_PLACE = 2**27
LANES = 8  # a block's entries at most: kernels/mesh.cl tests them in 8 lanes


def leaves(tree) -> tuple[np.ndarray, np.ndarray]:
    """(first, count) of the binary tree's leaves, by first position: they partition the positions."""
    leaf = tree.count > 0
    first, count = tree.first[leaf].astype(np.int64), tree.count[leaf].astype(np.int64)
    by_first = np.argsort(first, kind="stable")
    return first[by_first], count[by_first]


def regroup(bvh, shape_types, kinds, worlds, nodes: np.ndarray):
    """(refs, anchors, per type): cast's refs and anchors (engine/launch/signatures.py: the cast kernel's refs and anchors)
    with each leaf's entries of one shape of a cast_blocks type grouped into one ref; per bounded
    type (by name) its blocks array, number of refs and lanes' entries (places, first, kept: the
    entries of block i at place places[i] are kept[first[i]:first[i + 1]]) where it is a cast_blocks type, else its
    entries' anchors (in its leaf order); the wide nodes' leaf codes (nodes["child"]) are
    renumbered in place. bvh: the scene's SceneBVH; kinds, worlds: the prepared kinds and their
    world entries (in leaf order) by name."""
    n = len(bvh.leaf_type)
    refs = bvh.refs(shape_types).astype(np.int64)
    first, count = leaves(bvh.tree)
    leaf_of = np.repeat(np.arange(len(first)), count)
    # a key per position: its shape's (type, id) where the type is tested in blocks, else one of its own
    # (negative, increasing with the position: the others keep their order within the leaf)
    key = np.arange(n, dtype=np.int64) - n
    own_anchors = {}
    for t, name in enumerate(bvh.types):
        kind = kinds[name]
        if not capability(kind.cls, "cast_blocks"):
            continue
        mine = bvh.leaf_type == t
        ids = np.asarray(kind.ids, np.int64)
        key[mine] = ((t + 1) << 33) + ids[bvh.leaf_index[mine]]
        own_anchors[name] = kind.cls.cast_anchors(worlds[name], kind.ids)
    # positions sorted by leaf, then key (stably): each run of one (leaf, key) is one new ref
    perm = np.lexsort((key, leaf_of))
    leaf_sorted, key_sorted = leaf_of[perm], key[perm]
    change = np.ones(n, bool)
    change[1:] = (leaf_sorted[1:] != leaf_sorted[:-1]) | (key_sorted[1:] != key_sorted[:-1])
    # a block holds at most LANES entries (a leaf holds at most 7 today: the wide tree's leaf code)
    group_start = np.flatnonzero(change)
    rank = np.arange(n) - np.repeat(group_start, np.diff(np.append(group_start, n)))
    change |= (rank > 0) & (rank % LANES == 0)
    run_start = np.flatnonzero(change)
    run_end = np.append(run_start[1:], n)
    head = perm[run_start]  # each run's first position
    run_type = bvh.leaf_type[head]
    new_refs = refs[head].copy()
    anchors = np.empty((max(len(head), 1), 4))
    single = key_sorted[run_start] < 0
    anchors[: len(head)][single] = bvh.anchors(head[single])
    # the other types' entries, each its own ref in position order (their types' leaf order): their anchors
    blocks = {name: anchors[: len(head)][single & (run_type == t)] for t, name in enumerate(bvh.types)
              if name not in own_anchors}
    for name, cast_anchors in own_anchors.items():
        t = bvh.types.index(name)
        runs = np.flatnonzero(~single & (run_type == t))
        lengths = run_end[runs] - run_start[runs]
        # the runs' positions, run after run, in the leaf's order
        within = np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)
        positions = perm[np.repeat(run_start[runs], lengths) + within]
        entries = bvh.leaf_index[positions]
        starts = np.concatenate([[0], np.cumsum(lengths)])
        kind = kinds[name]
        vertices, corners = _corners(kind, worlds[name])
        data, places = kind.cls.pack_cast_blocks(vertices, corners, np.asarray(kind.ids), entries, starts)
        if len(places) and places[-1] >= MAX_PLACE:
            raise RequestError(f"the scene's {name}es are too many for cast's blocks ({len(entries):,} entries)")
        new_refs[runs] = places * 16 + 1 + list(shape_types).index(name)
        anchors[runs] = cast_anchors[bvh.leaf_index[head[runs]]]
        # which entry each block's lane is (the hit queries' primitives and ids, engine/queries/hits.py):
        # block i at 64-byte place places[i], its lanes the entries kept[first[i]:first[i + 1]] (the
        # zero-area ones left out, as pack_cast_blocks leaves them)
        valid = corners[entries, 0] >= 0
        block_of = np.repeat(np.arange(len(runs)), lengths)
        kept_count = np.bincount(block_of[valid], minlength=len(runs))
        lanes = (np.asarray(places, np.int64), np.concatenate([[0], np.cumsum(kept_count)]), entries[valid])
        blocks[name] = (data, len(runs), lanes)
    # the wide tree's leaves: (first, count) of positions -> of the new refs
    run_leaf = leaf_sorted[run_start]
    new_first = np.searchsorted(run_leaf, np.arange(len(first)))
    new_count = np.bincount(run_leaf, minlength=len(first))
    leaf_at = np.zeros(n + 1, np.int64)
    leaf_at[first] = np.arange(len(first))
    child = nodes["child"]
    leaf_code = child < 0
    j = leaf_at[(~child[leaf_code].astype(np.int64)) >> 3]
    child[leaf_code] = ~(new_first[j] * 8 + new_count[j])
    return (new_refs if len(new_refs) else np.zeros(1, np.int64)).astype(np.int32), anchors, blocks


def _corners(kind, world) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3+) float64, corners (F, 3)): the type's entries (in leaf order) as vertex
    indices, -1 where never hit: an indexed type's shared vertices and faces (engine/scene/indexed.py), else
    each entry's own three corners from its world entry (a zero world normal: never hit)."""
    if kind.indexed is not None:
        faces = kind.indexed.faces
        return kind.indexed.world_vertices, np.where(faces[:, 3:] >= 0, faces[:, :3], -1)
    vertices = np.stack([world[name][:, :3] for name in ("a", "b", "c")], 1).reshape(-1, 3)
    corners = np.arange(len(vertices)).reshape(-1, 3)
    flat = (world["a"][:, 3] == 0) & (world["b"][:, 3] == 0) & (world["c"][:, 3] == 0)
    return vertices, np.where(flat[:, None], -1, corners)
