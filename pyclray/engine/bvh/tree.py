"""A bounding volume hierarchy over shapes' world bounds: a binned SAH tree for large scenes
(pyclray.engine.bvh.sah, compiled by numba), a linear BVH in vectorized numpy for small ones.

The binned SAH (from SAH_FROM shapes on): top-down, 32 bins on each axis at every node, leaves of
at most LEAF_SIZE where the surface area heuristic says so; see sah.py. Its tree's quality and
render times against the LBVH's: docs/benchmarks.md, "The BVH builder".

The linear BVH (Karras, "Maximizing parallelism in the construction of BVHs, octrees and k-d
trees", HPG 2012), below SAH_FROM: the shapes are sorted along a Morton curve of their bounds'
centres; the binary radix tree of the sorted codes is found for every internal node at once (each
node's range and split by binary searches over the codes, vectorized over all nodes); subtrees of
at most LEAF_SIZE shapes become leaves; nodes are then numbered breadth-first, and bounded bottom-up.

Why two: numba's import and the load of the compiled builder cost a new process's first large
build; a small scene's first render (tp02's cold start) never pays it (numba is not even imported).
From SAH_FROM on the better tree pays for it over a few views (docs/benchmarks.md, "Why the engine
does what it does": SAH_FROM).

Flat layout, ready for a kernel: node k has bounds lo[k], hi[k] (float64 here; the packer rounds
them outward to the kernel's precision) and two integers: ``first`` and ``count``. count > 0: a
leaf holding the shapes order[first : first + count]; count == 0: an internal node whose children
are nodes first and first + 1, numbered after it. Node 0 is the root. Both builders give their
nodes exactly the union of their shapes' boxes (float64 min and max); the refit of an animation
(pyclray.engine.scene.refit) and the wide tree (bvh_wide) read only this layout.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model.layout import Struct, layout
from ..opencl.buffers import aligned_empty

LEAF_SIZE = 4  # shapes per leaf at most: the kernel tests a leaf's shapes one after the other
# How much a shape's box is widened, relative to its size, and the ray's cone in the kernel,
# relative to distance (kernels/bvh.h: BVH_WIDEN): shape tests round, and a box test must never
# drop a shape that the shape's own test would hit.
WIDEN = 2.0**-12

NODE = Struct(
    "BvhNode",
    (
        ("lo", "float4"),  # xyz: the box's low corner; w: the bits of the int first
        ("hi", "float4"),  # xyz: the box's high corner; w: the bits of the int count
    ),
    "A binary BVH node (kernels/bvh.h): count > 0: a leaf of refs[first .. first + count - 1]; else children first, first + 1.",
)
_FLOAT_MAX = float(np.finfo(np.float32).max)
BINARY_STACK = 64  # kernels/bvh.h: BVH_BINARY_STACK: the deepest binary tree the kernels traverse
# The SAH tree's levels at most: a wide level takes at least one binary level, and the wide
# traversal's stack holds 7 entries a level (bvh_wide.STACK = 256 >= 7 * 36 + 1)
MAX_SAH_DEPTH = 36
SAH_FROM = 16_384  # shapes from which build() takes the binned SAH (bvh_sah): see the docstring
# The scene's SAH tree is built for render's packets (kernels/bvh.h; measured when they traversed the
# binary tree): a packet's visit of a node (two box tests of all its lanes, their reductions, a branch
# the predictor often misses) costs about as much as four of its shape tests, and a leaf is tested
# shape after shape against the whole packet, so leaves up to 7 (the most the wide tree's leaf code
# holds) with a node's cost of 4 shape tests (docs/benchmarks.md, "Why the engine does what it
# does": SCENE_LEAF_SIZE).
SCENE_LEAF_SIZE = 7
SCENE_TRAVERSAL = 4.0


@dataclass(frozen=True)
class BVH:
    """A flat BVH over N shapes (see the module docstring)."""

    lo: np.ndarray  # (M, 3) float64 node bounds
    hi: np.ndarray  # (M, 3)
    first: np.ndarray  # (M,) int32: first child (internal) or first position in order (leaf)
    count: np.ndarray  # (M,) int32: shapes in a leaf, 0 for an internal node
    order: np.ndarray  # (N,) int64: the shapes in leaf order (positions in the input bounds)

    @property
    def nodes(self) -> int:
        return len(self.first)

    def depth(self) -> int:
        """Levels from the root to the deepest leaf."""
        if not self.order.size:
            return 1
        level, frontier = 0, np.array([0])
        while frontier.size:
            level += 1
            inner = frontier[self.count[frontier] == 0]
            frontier = np.concatenate([self.first[inner], self.first[inner] + 1])
        return level

    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.lo, self.hi, self.first, self.count, self.order))


def empty() -> BVH:
    """The BVH of no shapes: one empty leaf with bounds that no ray meets."""
    return BVH(
        np.full((1, 3), np.inf), np.full((1, 3), -np.inf),
        np.zeros(1, np.int32), np.zeros(1, np.int32), np.zeros(0, np.int64),
    )


def _bit_length(x: np.ndarray) -> np.ndarray:
    """Bit length of each uint64 (0 for 0), exactly: float64's frexp is exact on 32-bit halves."""
    high = (x >> np.uint64(32)).astype(np.float64)
    low = (x & np.uint64(0xFFFFFFFF)).astype(np.float64)
    return np.where(high > 0, 32 + np.frexp(high)[1], np.frexp(low)[1])


def _spread(v: np.ndarray, bits: int) -> np.ndarray:
    """Interleave: bit b of v goes to bit 3 b (v < 2**bits, bits <= 21), by the usual five
    shift-and-mask steps."""
    v = v.astype(np.uint64) & np.uint64((1 << bits) - 1)
    for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                        (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def morton_order(centres: np.ndarray):
    """(order, keys): the shapes sorted along a Morton curve of their centres, and unique 63-bit
    keys (Morton code, then the rank among equal codes in the low bits) increasing in that order."""
    n = len(centres)
    index_bits = max(int(n - 1).bit_length(), 1)
    axis_bits = min((63 - index_bits) // 3, 21)
    lo, hi = centres.min(axis=0), centres.max(axis=0)
    extent = np.where(hi > lo, hi - lo, 1.0)
    cells = (1 << axis_bits) - 1
    q = np.clip(((centres - lo) / extent * cells).astype(np.int64), 0, cells)
    code = _spread(q[:, 0], axis_bits) << np.uint64(2)
    code |= _spread(q[:, 1], axis_bits) << np.uint64(1)
    code |= _spread(q[:, 2], axis_bits)
    order = np.argsort(code)  # ties get distinct keys below, whatever their order
    keys = (code[order] << np.uint64(index_bits)) | np.arange(n, dtype=np.uint64)
    return order, keys


def _radix_tree(keys: np.ndarray):
    """Karras' binary radix tree over n > 1 unique sorted keys: for each of the n - 1 internal
    nodes i, its range [first, last] of sorted positions and its split g (left child covers
    [first, g], right child [g + 1, last]). Node 0 is the root.

    Prefix lengths are compared through the keys' xor: key j shares a longer prefix with key i
    than b bits of difference allow exactly when keys[i] ^ keys[j] < 2**(b - 1). The binary
    searches go on only for the nodes still searching (most ranges are short), so the work is
    about n log(range) in all, not n log n."""
    n = len(keys)
    i = np.arange(n - 1, dtype=np.int64)
    key_i = keys[:-1]

    def closer(nodes, j, bits):
        """Whether key j (a position, possibly out of range: never) differs from key i only below
        bit bits - 1 (bits = 64: any in-range key, as the 63-bit keys all do), for these nodes i."""
        inside = (j >= 0) & (j < n)
        x = key_i[nodes] ^ keys[np.clip(j, 0, n - 1)]
        return inside & (x < np.left_shift(np.uint64(1), (bits - 1).astype(np.uint64)))

    # direction of the node's range: towards the neighbour sharing the longer prefix
    x_next = key_i ^ keys[1:]
    x_prev = np.empty_like(x_next)
    x_prev[0] = np.iinfo(np.uint64).max
    x_prev[1:] = key_i[1:] ^ keys[:-2]
    d = np.where(x_next < x_prev, 1, -1)
    # the range must share more than the prefix with the neighbour on the other side
    bits_min = np.where(d > 0, _bit_length(x_prev), _bit_length(x_next)).astype(np.int64)
    bits_min[0] = 64  # the root: no neighbour on the other side
    # the range's length: an upper bound by doubling, then binary search
    length_max = np.full(n - 1, 2, np.int64)
    active = i[closer(i, i + 2 * d, bits_min)]
    while active.size:
        length_max[active] *= 2
        active = active[closer(active, active + length_max[active] * d[active], bits_min[active])]
    length = np.zeros(n - 1, np.int64)
    step = length_max // 2
    active = i[step > 0]
    while active.size:
        s = step[active]
        grow = closer(active, active + (length[active] + s) * d[active], bits_min[active])
        length[active[grow]] += s[grow]
        step[active] //= 2
        active = active[step[active] > 0]
    j = i + length * d
    # the split: the farthest position from i that shares more than the node's prefix with key i
    bits_node = _bit_length(key_i ^ keys[j]).astype(np.int64)
    split = np.zeros(n - 1, np.int64)
    step = length.copy()
    active = i
    while active.size:
        step[active] = (step[active] + 1) // 2
        s = step[active]
        grow = closer(active, active + (split[active] + s) * d[active], bits_node[active])
        split[active[grow]] += s[grow]
        active = active[s > 1]
    gamma = i + split * d + np.minimum(d, 0)
    return np.minimum(i, j), np.maximum(i, j), gamma


def build(bounds: np.ndarray, leaf_size: int | None = None, method: str | None = None,
          traversal: float | None = None) -> BVH:
    """The BVH of shapes with these world bounds ((N, 2, 3) float64: lo, hi per shape), leaves of
    at most leaf_size (default LEAF_SIZE) shapes. method: "sah" (the binned SAH of bvh_sah),
    "lbvh" (the Morton LBVH below), or None: the SAH from SAH_FROM shapes on, else the LBVH.
    traversal: the SAH's cost of a node's visit, in shape tests (default bvh_sah.TRAVERSAL)."""
    leaf_size = LEAF_SIZE if leaf_size is None else leaf_size
    bounds = np.asarray(bounds, np.float64)
    n = len(bounds)
    if n == 0:
        return empty()
    if method is None:
        method = "sah" if n >= SAH_FROM else "lbvh"
    if method == "sah" and n > 1:
        from . import sah  # numba: imported for large scenes only (see sah

        return BVH(*sah.build(bounds, leaf_size, MAX_SAH_DEPTH,
                              traversal=sah.TRAVERSAL if traversal is None else traversal))
    if method not in ("sah", "lbvh"):
        raise ValueError(f"BVH build method: expected 'sah' or 'lbvh', got {method!r}")
    order, keys = morton_order(0.5 * (bounds[:, 0] + bounds[:, 1]))
    lo_sorted, hi_sorted = bounds[order, 0], bounds[order, 1]
    if n <= leaf_size:
        return BVH(
            lo_sorted.min(axis=0)[None], hi_sorted.max(axis=0)[None],
            np.zeros(1, np.int32), np.array([n], np.int32), order,
        )
    first, last, gamma = _radix_tree(keys)
    # children of internal node k: (left, right) as (index, is_internal); a child is a leaf of
    # the collapsed tree when its range holds at most leaf_size shapes
    child_first = np.stack([first, gamma + 1])  # [0]: left range start, [1]: right range start
    child_last = np.stack([gamma, last])
    child_internal = (child_last - child_first + 1) > leaf_size
    child_node = np.stack([gamma, gamma + 1])  # internal node index when internal
    # breadth-first numbering: the root, then the two children of each node in turn
    level_nodes = np.array([0])  # Karras indices of this level's internal nodes
    level_ranges = np.array([[0, n - 1]])
    level_internal = np.array([True])
    next_index = 1
    levels = []
    while level_nodes.size:
        m = len(level_nodes)
        # the children of this level's internal nodes, numbered next_index, next_index + 1, ...
        inner = level_internal
        k = level_nodes[inner]
        count_inner = int(inner.sum())
        firsts = np.zeros(m, np.int64)
        firsts[inner] = next_index + 2 * np.arange(count_inner)
        counts = np.where(inner, 0, level_ranges[:, 1] - level_ranges[:, 0] + 1)
        firsts = np.where(inner, firsts, level_ranges[:, 0])
        levels.append((firsts, counts, level_ranges))
        next_index += 2 * count_inner
        # next level, left and right child of each inner node interleaved
        nxt_nodes = np.stack([child_node[0][k], child_node[1][k]], axis=1).ravel()
        nxt_ranges = np.stack(
            [np.stack([child_first[0][k], child_last[0][k]], axis=1), np.stack([child_first[1][k], child_last[1][k]], axis=1)],
            axis=1,
        ).reshape(-1, 2)
        nxt_internal = np.stack([child_internal[0][k], child_internal[1][k]], axis=1).ravel()
        level_nodes, level_ranges, level_internal = nxt_nodes, nxt_ranges, nxt_internal
    node_first = np.concatenate([f for f, _, _ in levels]).astype(np.int32)
    node_count = np.concatenate([c for _, c, _ in levels]).astype(np.int32)
    ranges = np.concatenate([r for _, _, r in levels])
    total = len(node_first)
    lo = np.empty((total, 3))
    hi = np.empty((total, 3))
    # leaves: their ranges partition the sorted shapes in order, so one reduceat bounds them all
    leaf = node_count > 0
    leaf_index = np.flatnonzero(leaf)
    at_start = np.full(n, -1, np.int64)  # the leaf starting at each sorted position, if any
    at_start[ranges[leaf_index, 0]] = leaf_index
    by_start = at_start[at_start >= 0]
    starts = ranges[by_start, 0]
    lo[by_start] = np.minimum.reduceat(lo_sorted, starts, axis=0)
    hi[by_start] = np.maximum.reduceat(hi_sorted, starts, axis=0)
    # internal nodes bottom-up, a level at a time: the union of their two children
    offset = total
    for firsts, counts, _ in reversed(levels):
        offset -= len(firsts)
        rows = offset + np.flatnonzero(counts == 0)
        c = node_first[rows]
        lo[rows] = np.minimum(lo[c], lo[c + 1])
        hi[rows] = np.maximum(hi[c], hi[c + 1])
    return BVH(lo, hi, node_first, node_count, order)


def sah_cost(tree: BVH, traversal: float = 1.0, intersection: float = 1.0) -> float:
    """The surface area heuristic's expected cost of a ray through the tree (relative to the root's
    area): traversal for each internal node visited, intersection per shape of each leaf visited."""
    extent = np.maximum(tree.hi - tree.lo, 0.0)
    area = extent[:, 0] * extent[:, 1] + extent[:, 1] * extent[:, 2] + extent[:, 2] * extent[:, 0]
    root = area[0] if area[0] > 0 else 1.0
    weight = np.where(tree.count > 0, intersection * tree.count, traversal)
    return float((area * weight).sum() / root)


def widened(bounds: np.ndarray) -> np.ndarray:
    """Shapes' world bounds widened by WIDEN times their size (see WIDEN)."""
    bounds = np.asarray(bounds, np.float64)
    out = np.empty_like(bounds)
    if len(bounds) >= SAH_FROM:  # one compiled pass (numba is imported for the SAH build anyway; docs/benchmarks.md)
        from .passes import widen

        widen(np.ascontiguousarray(bounds), WIDEN, out)
        return out
    extent = bounds[:, 1] - bounds[:, 0]
    size = extent.max(axis=1, initial=0.0)[:, None]
    size *= WIDEN
    np.subtract(bounds[:, 0], size, out=out[:, 0])  # written in place: no temporaries
    np.add(bounds[:, 1], size, out=out[:, 1])
    return out


def outward32(lo: np.ndarray, hi: np.ndarray):
    """float64 corners rounded outward to float32 and kept within float32's finite range (a box
    test then never meets inf - inf or 0 * inf)."""
    with np.errstate(over="ignore", invalid="ignore"):
        lo32 = np.clip(lo, -_FLOAT_MAX, _FLOAT_MAX).astype(np.float32)
        hi32 = np.clip(hi, -_FLOAT_MAX, _FLOAT_MAX).astype(np.float32)
    with np.errstate(over="ignore"):
        lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
        hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    return np.maximum(lo32, -_FLOAT_MAX).astype(np.float32), np.minimum(hi32, _FLOAT_MAX).astype(np.float32)


def pack_nodes(tree: BVH, origin) -> np.ndarray:
    """The binary nodes as the kernel reads them (NODE), boxes relative to origin (float64, taken
    before rounding outward): shadow rays' packets traverse them around the scene's anchor."""
    out = aligned_empty(tree.nodes, layout(NODE, "fp32").dtype)  # every word written below; no copy to align it
    assert out.itemsize == 32  # two float4 (pack_binary writes its words)
    origin = np.asarray(origin, np.float64)
    if tree.nodes >= SAH_FROM:  # one compiled pass (bvh_fast: the same bits), numba being imported by then
        from .passes import pack_binary

        words = out.view(np.float32).reshape(tree.nodes, 8)
        pack_binary(np.ascontiguousarray(tree.lo), np.ascontiguousarray(tree.hi), tree.first.astype(np.int32),
                    tree.count.astype(np.int32), origin, words, words.view(np.int32))
        return out
    lo, hi = outward32(tree.lo - origin, tree.hi - origin)
    out["lo"][:, :3], out["hi"][:, :3] = lo, hi
    out["lo"][:, 3] = tree.first.astype(np.int32).view(np.float32)
    out["hi"][:, 3] = tree.count.astype(np.int32).view(np.float32)
    return out
