"""A top-down binned SAH build (Wald, "On fast construction of SAH-based bounding volume
hierarchies", 2007), compiled by numba: pyclray.engine.bvh.tree.build's builder for large N.

Imported only by bvh.build, and only for scenes of at least bvh.SAH_FROM primitives: numba's
import and its compiled code's load from numba's disk cache (cache=True) would otherwise cost every
small render's cold start.

Each node in turn (depth first, from an explicit stack): one pass over its primitives bins their
boxes by centroid into up to BINS bins along each of the three axes at once (as many bins as
primitives below BINS: a small node's bins cost more than its primitives; a large node bins about
SAMPLE of them, evenly spaced); a sweep of each axis'
bins from both ends gives the SAH cost of every split between bins; the node becomes a leaf where it
holds at most leaf_size primitives and testing them costs no more than the best split (a node's
visit costing TRAVERSAL primitive tests); else a second pass partitions its primitives in place by
the best split, and finds each side's centroid box on the way (a child's box is the union of its
side's bins). Two passes over a node's rows then, and the rows are float32 boxes relative to the
root's centre (24 bytes a primitive, contiguous for a node: passes stream memory instead of
gathering). They only steer the splits: the final boxes are recomputed from the float64 bounds,
bottom up, as exact unions.

Threads: a node of at least N / (8 threads) primitives is split on its own and its two children
handed on to a pool of threads (numba's nogil: they run at once); a smaller one is built whole by
the thread that takes it. Every node's number follows from the splits above it (see _grow), so the
tree is the same whatever the number of threads; the numbers left unused (a leaf of several
primitives leaves a gap) are squeezed out after.

Depth: the kernels' stacks bound the tree's depth (bvh.MAX_SAH_DEPTH). A node at level d with m
primitives keeps d + ceil(log2 m) <= max_depth; a split whose larger side would break that for a
child becomes an object median split (sorted by centroid on the node's longest centroid axis),
which always keeps it: pathological inputs end in balanced subtrees instead of a stack overflow.
"""
from __future__ import annotations

import os
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

import numba
import numpy as np

from .passes import inner_boxes, leaf_boxes, leaf_cut

BINS = 32
# The SAH's cost of visiting a node, relative to a primitive's test. 1 (bvh.sah_cost's) makes leaves of
# 1.4 primitives on average, 1.1 to 1.4 nodes a primitive: twice the LBVH's memory (nodes are 32 bytes
# on the device, 64 more as float64 world corners). 2 makes 0.7 to 0.8 nodes a primitive, as the LBVH,
# for a slightly higher SAH cost (counted with 1) and no slower renders (docs/benchmarks.md, "The BVH
# builder").
TRAVERSAL = 2.0
SPLIT_ALONE_MIN = 4096
# A node of at least 2 SAMPLE primitives chooses its split from the bins of every k-th row only
# (k = m // SAMPLE: about SAMPLE rows, evenly spaced), and partitions all of them by it. A binning
# pass is half a level's work; this saves it on the top levels (of 1,000,000 triangles, the 8 levels
# above 8,192 primitives a node) for a nearly unchanged SAH cost (docs/benchmarks.md, "Why the engine does what it
# does"). A sampled node's child box (the union of its sampled bins) is only an estimate, read only by a
# child of at most leaf_size primitives deciding whether to be a leaf; the final boxes are recomputed
# exactly (_boxes).
SAMPLE = 4096
_STACK = 256  # pending nodes: one per level of the tree (right siblings) at most, with margin
_BIG = np.float32(3.4e38)
# a pending node: range start, end, node number, level, the first number of its descendants' range;
# and its box and centroid box (float32)
_INTS, _GEOMETRY = 5, 12


@numba.njit(cache=True, inline="always")
def _half_area(x0, y0, z0, x1, y1, z1):
    dx, dy, dz = max(x1 - x0, 0.0), max(y1 - y0, 0.0), max(z1 - z0, 0.0)
    return dx * dy + dy * dz + dz * dx


@numba.njit(cache=True, inline="always")
def _bin(value, low, scale, bins):
    """The bin of a (doubled) centroid coordinate: the same arithmetic in binning and partition, so
    that both put a primitive in the same bin."""
    return min(max(int((value - low) * scale), 0), bins - 1)


@numba.njit(cache=True, inline="always")
def _ceil_log2(m):
    levels = 0
    while (1 << levels) < m:
        levels += 1
    return levels


@numba.njit(cache=True, inline="always")
def _empty_box(geometry):
    for a in range(3):
        geometry[a], geometry[a + 3], geometry[a + 6], geometry[a + 9] = _BIG, -_BIG, _BIG, -_BIG


@numba.njit(cache=True, nogil=True)
def _extent(bounds):
    """The (2, 3) box of all the bounds (numpy's min and max over the strided (N, 2, 3) array
    cost ten times as much)."""
    box = np.empty((2, 3))
    box[0], box[1] = np.inf, -np.inf
    for i in range(bounds.shape[0]):
        for a in range(3):
            box[0, a] = min(box[0, a], bounds[i, 0, a])
            box[1, a] = max(box[1, a], bounds[i, 1, a])
    return box


@numba.njit(cache=True, nogil=True)
def _rows(bounds, centre, unit, rows):
    """rows[i] = (bounds[i] - centre) * unit in float32, kept within +-1e30 (no inf in a sum)."""
    for i in range(bounds.shape[0]):
        for side in range(2):
            for a in range(3):
                rows[i, 3 * side + a] = min(max((bounds[i, side, a] - centre[a]) * unit, -1e30), 1e30)


@numba.njit(cache=True, nogil=True)
def _add_row(geometry, rows, i):
    """geometry[0:12] (a box and a (doubled) centroid box) grown by row i."""
    for a in range(3):
        c = rows[i, a] + rows[i, a + 3]
        geometry[a] = min(geometry[a], rows[i, a])
        geometry[a + 3] = max(geometry[a + 3], rows[i, a + 3])
        geometry[a + 6] = min(geometry[a + 6], c)
        geometry[a + 9] = max(geometry[a + 9], c)


@numba.njit(cache=True, nogil=True)
def _root(rows, geometry):
    """The box and the (doubled) centroid box of all rows, into geometry[0:12]."""
    _empty_box(geometry)
    for i in range(rows.shape[0]):
        _add_row(geometry, rows, i)


@numba.njit(cache=True, nogil=True)
def _grow(rows, index, first, count, start, geometry, leaf_size, bins, max_depth, traversal, task_from, tasks,
          task_geometry):
    """Build the subtree of the node start = (s, e, node, level, r) with geometry (its box, its
    centroid box); a child of fewer than task_from primitives (0: none) is not built but appended to
    tasks (its start and geometry). Returns the number of tasks.

    Numbers: a node over m primitives has at most 2 m - 2 descendants, numbered from its r: its
    children r and r + 1, the left one's descendants from r + 2 (2 m_left - 2 of them at most),
    the right one's from r + 2 m_left. The numbers depend on the splits only, not on which thread
    builds which subtree: any number of threads builds the same tree."""
    stack = np.empty((_STACK, _INTS), np.int64)
    stack_geometry = np.empty((_STACK, _GEOMETRY), np.float32)
    bin_n = np.empty((3, bins), np.int64)
    bin_box = np.empty((3, bins, 6), np.float32)
    right_area = np.empty(bins, np.float64)
    right_n = np.empty(bins, np.int64)
    scale = np.empty(3, np.float64)
    g = np.empty(_GEOMETRY, np.float32)  # the node's (its stack slot is the first child's)
    left = np.empty(_GEOMETRY, np.float32)
    right = np.empty(_GEOMETRY, np.float32)
    stack[0] = start
    stack_geometry[0] = geometry
    top, found = 1, 0
    while top > 0:
        top -= 1
        s, e, node, level, r = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3], stack[top, 4]
        for c in range(_GEOMETRY):
            g[c] = stack_geometry[top, c]
        m = e - s
        if m == 1 or (m <= leaf_size and m <= traversal):
            # a leaf without binning: a split costs traversal plus its children's tests (> 0), which
            # is more than m tests here (the same leaf as the cost test below makes)
            first[node], count[node] = s, m
            continue
        area = _half_area(g[0], g[1], g[2], g[3], g[4], g[5])
        nb = min(bins, m)
        # a large node bins about SAMPLE of its rows, evenly spaced (see SAMPLE)
        step = 1 if m < 2 * SAMPLE else m // SAMPLE
        # bin along each axis with a centroid extent (an axis without one: scale 0, all in bin 0)
        for a in range(3):
            extent = g[a + 9] - g[a + 6]
            scale[a] = nb * (1.0 - 1e-6) / extent if extent > 0 else 0.0
        for a in range(3):  # (loops: numba's slice assignments cost a small node more than its rows)
            for k in range(nb):
                bin_n[a, k] = 0
                for c in range(3):
                    bin_box[a, k, c] = _BIG
                    bin_box[a, k, c + 3] = -_BIG
        for i in range(s, e, step):
            x0, y0, z0, x1, y1, z1 = rows[i, 0], rows[i, 1], rows[i, 2], rows[i, 3], rows[i, 4], rows[i, 5]
            for a in range(3):
                k = _bin(rows[i, a] + rows[i, a + 3], g[a + 6], scale[a], nb)
                bin_n[a, k] += 1
                bin_box[a, k, 0] = min(bin_box[a, k, 0], x0)
                bin_box[a, k, 1] = min(bin_box[a, k, 1], y0)
                bin_box[a, k, 2] = min(bin_box[a, k, 2], z0)
                bin_box[a, k, 3] = max(bin_box[a, k, 3], x1)
                bin_box[a, k, 4] = max(bin_box[a, k, 4], y1)
                bin_box[a, k, 5] = max(bin_box[a, k, 5], z1)
        # sweep: the cost of splitting after bin k is area(0..k) n(0..k) + area(k+1..) n(k+1..)
        best_cost, best_axis, best_k, best_left = np.inf, -1, -1, 0
        for a in range(3):
            if scale[a] == 0:
                continue
            x0 = y0 = z0 = _BIG
            x1 = y1 = z1 = -_BIG
            total = 0
            for k in range(nb - 1, 0, -1):
                x0, y0, z0 = min(x0, bin_box[a, k, 0]), min(y0, bin_box[a, k, 1]), min(z0, bin_box[a, k, 2])
                x1, y1, z1 = max(x1, bin_box[a, k, 3]), max(y1, bin_box[a, k, 4]), max(z1, bin_box[a, k, 5])
                total += bin_n[a, k]
                right_area[k] = _half_area(x0, y0, z0, x1, y1, z1)
                right_n[k] = total
            x0 = y0 = z0 = _BIG
            x1 = y1 = z1 = -_BIG
            total = 0
            for k in range(nb - 1):
                x0, y0, z0 = min(x0, bin_box[a, k, 0]), min(y0, bin_box[a, k, 1]), min(z0, bin_box[a, k, 2])
                x1, y1, z1 = max(x1, bin_box[a, k, 3]), max(y1, bin_box[a, k, 4]), max(z1, bin_box[a, k, 5])
                total += bin_n[a, k]
                if total == 0 or right_n[k + 1] == 0:
                    continue
                cost = _half_area(x0, y0, z0, x1, y1, z1) * total + right_area[k + 1] * right_n[k + 1]
                if cost < best_cost:
                    best_cost, best_axis, best_k, best_left = cost, a, k, total
        # a leaf where it is small enough and testing its primitives costs no more than a split
        # (SAH: a primitive test costs 1, a node's traversal costs traversal)
        split_cost = traversal + best_cost / area if area > 0 else np.inf
        if m <= leaf_size and (best_axis < 0 or m <= split_cost):
            first[node], count[node] = s, m
            continue
        _empty_box(left)
        _empty_box(right)
        # the object median where there is no split, or where the split would break the depth bound
        # (a sampled node's split checked on its real sides, after its partition)
        median = best_axis < 0 or (step == 1 and _ceil_log2(max(best_left, m - best_left)) > max_depth - level - 1)
        if not median:
            # partition in place (bins 0..best_k to the left), each side's centroid box on the way:
            # every row is swapped to the end of the left side and that end moves by one where the
            # row belongs there (no branch on the side: it is a coin toss per row, and mispredicted
            # branches cost more than the swaps; docs/benchmarks.md, "Why the engine does what it does")
            a = best_axis
            l0 = l1 = l2 = r0 = r1 = r2 = _BIG  # each side's centroid box, in registers
            l3 = l4 = l5 = r3 = r4 = r5 = -_BIG
            mid = s
            for i in range(s, e):
                c0, c1, c2 = rows[i, 0] + rows[i, 3], rows[i, 1] + rows[i, 4], rows[i, 2] + rows[i, 5]
                is_left = _bin(rows[i, a] + rows[i, a + 3], g[a + 6], scale[a], nb) <= best_k
                # both sides' boxes grown, by the centroid or by nothing (selects, no branch)
                l0, l1, l2 = min(l0, c0 if is_left else _BIG), min(l1, c1 if is_left else _BIG), min(l2, c2 if is_left else _BIG)
                l3, l4, l5 = max(l3, c0 if is_left else -_BIG), max(l4, c1 if is_left else -_BIG), max(l5, c2 if is_left else -_BIG)
                r0, r1, r2 = min(r0, _BIG if is_left else c0), min(r1, _BIG if is_left else c1), min(r2, _BIG if is_left else c2)
                r3, r4, r5 = max(r3, -_BIG if is_left else c0), max(r4, -_BIG if is_left else c1), max(r5, -_BIG if is_left else c2)
                for c in range(6):
                    rows[i, c], rows[mid, c] = rows[mid, c], rows[i, c]
                index[i], index[mid] = index[mid], index[i]
                mid += 1 if is_left else 0
            left[6], left[7], left[8], left[9], left[10], left[11] = l0, l1, l2, l3, l4, l5
            right[6], right[7], right[8], right[9], right[10], right[11] = r0, r1, r2, r3, r4, r5
            # each side's box: the union of its bins
            for k in range(nb):
                side = left if k <= best_k else right
                for c in range(3):
                    side[c] = min(side[c], bin_box[a, k, c])
                    side[c + 3] = max(side[c + 3], bin_box[a, k, c + 3])
            if step > 1 and _ceil_log2(max(mid - s, e - mid)) > max_depth - level - 1:
                median = True
                _empty_box(left)
                _empty_box(right)
        if median:
            # the object median (where every centroid coincides: the halves as they are)
            axis = 0
            for a in range(1, 3):
                if g[a + 9] - g[a + 6] > g[axis + 9] - g[axis + 6]:
                    axis = a
            if g[axis + 9] > g[axis + 6]:
                keys = rows[s:e, axis] + rows[s:e, axis + 3]
                order = np.argsort(keys, kind="mergesort")
                rows[s:e] = rows[s:e][order]
                index[s:e] = index[s:e][order]
            mid = s + m // 2
            for i in range(s, e):
                _add_row(left if i < mid else right, rows, i)
        first[node], count[node] = r, 0
        for child in range(2):  # the right child first on the stack: the left one is built next
            cs, ce = (mid, e) if child == 0 else (s, mid)
            number, descendants = (r + 1, r + 2 * (mid - s)) if child == 0 else (r, r + 2)
            if ce - cs < task_from:
                tasks[found, 0], tasks[found, 1], tasks[found, 2] = cs, ce, number
                tasks[found, 3], tasks[found, 4] = level + 1, descendants
                for c in range(_GEOMETRY):
                    task_geometry[found, c] = right[c] if child == 0 else left[c]
                found += 1
            else:
                stack[top, 0], stack[top, 1], stack[top, 2] = cs, ce, number
                stack[top, 3], stack[top, 4] = level + 1, descendants
                for c in range(_GEOMETRY):
                    stack_geometry[top, c] = right[c] if child == 0 else left[c]
                top += 1
    return found


@numba.njit(cache=True, nogil=True)
def _squeeze(first, count):
    """Number the used nodes (count >= 0) in order, in place: children stay adjacent and after
    their parent. Returns how many."""
    renumber = np.empty(first.shape[0], np.int32)
    nodes = 0
    for k in range(first.shape[0]):
        renumber[k] = nodes
        if count[k] >= 0:
            nodes += 1
    for k in range(first.shape[0]):
        if count[k] >= 0:
            to = renumber[k]
            first[to] = renumber[first[k]] if count[k] == 0 else first[k]
            count[to] = count[k]
    return nodes


def _boxes(bounds, index, first, count, lo, hi, threads: int) -> None:
    """The nodes' float64 boxes: the leaves' in parts of the leaf positions, a part a thread (each
    leaf wholly in one part), then the internal nodes'."""
    n = index.shape[0]
    cuts = [0] + [int(leaf_cut(first, count, n * t // threads, n)) for t in range(1, threads)] + [n]

    def part(t):
        p0, p1 = cuts[t], cuts[t + 1]
        leaf_boxes(bounds, index, first, count, lo, hi, p0, p1, np.empty((max(p1 - p0, 1), 2, 3)))

    if threads > 1 and n >= SPLIT_ALONE_MIN:
        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(part, range(threads)))
    else:
        cuts = [0, n]
        part(0)
    inner_boxes(first, count, lo, hi)


def _threads() -> int:
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not on Linux
        return max(os.cpu_count() or 1, 1)


def build(bounds: np.ndarray, leaf_size: int, max_depth: int, bins: int = BINS, threads: int | None = None,
          traversal: float = TRAVERSAL):
    """(lo, hi, first, count, order) of the binned SAH tree over these (N, 2, 3) float64 bounds
    (N >= 2), in bvh.BVH's layout."""
    bounds = np.ascontiguousarray(bounds, np.float64)  # one layout: one compiled version, cached once
    n = len(bounds)
    threads = _threads() if threads is None else threads
    # the rows: relative to the root box's centre and scaled by a power of two to about unit size
    # (exact in float64, then one rounding to float32), so that far-away or huge scenes bin as well
    # as small ones at the origin
    box = _extent(bounds)
    centre = 0.5 * box[0] + 0.5 * box[1]
    size = float(np.max(box[1] - box[0]))
    unit = 2.0 ** -np.frexp(size)[1] if 0 < size < np.inf else 1.0
    rows = np.empty((n, 6), np.float32)
    _rows(bounds, centre, unit, rows)
    index = np.arange(n, dtype=np.int64)
    first = np.full(max(2 * n - 1, 1), -1, np.int32)
    count = np.full(max(2 * n - 1, 1), -1, np.int32)
    root = np.array([0, n, 0, 1, 1]), np.empty(_GEOMETRY, np.float32)
    _root(rows, root[1])
    # a node of at least split_alone primitives is split on its own (one pass over its rows) and its
    # children handed on; smaller ones are built whole, on whichever thread is free (a task has a cost
    # of its own: none of fewer than SPLIT_ALONE_MIN primitives is handed on; docs/benchmarks.md, "Why
    # the engine does what it does")
    split_alone = max(n // (8 * threads), SPLIT_ALONE_MIN) if threads > 1 else n + 1

    def work(task):
        """Split or build the node task = (start, geometry); returns the children to hand on."""
        start, geometry = task
        m = start[1] - start[0]
        children = np.empty((2, _INTS), np.int64), np.empty((2, _GEOMETRY), np.float32)
        found = _grow(rows, index, first, count, start, geometry, leaf_size, bins, max_depth, traversal,
                      m if m >= split_alone else 0, *children)
        return [(children[0][k], children[1][k]) for k in range(found)]

    if threads > 1:
        with ThreadPoolExecutor(threads) as pool:
            running = {pool.submit(work, root)}
            while running:
                done, running = wait(running, return_when=FIRST_COMPLETED)
                for future in done:
                    running |= {pool.submit(work, child) for child in future.result()}
    else:
        work(root)
    nodes = _squeeze(first, count)
    first, count = first[:nodes].copy(), count[:nodes].copy()
    lo = np.empty((nodes, 3))
    hi = np.empty((nodes, 3))
    _boxes(bounds, index, first, count, lo, hi, threads)
    return lo, hi, first, count, index
