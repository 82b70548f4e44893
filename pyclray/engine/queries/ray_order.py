"""The coherent order of a large batch of cast rays, compiled by numba: each ray's 15-bit Morton code of
its origin and direction, and a counting sort of the codes, in one pass each over the rays (numpy took
seven passes, a radix argsort and gathered the rays in that order; docs/benchmarks.md, "Why the engine
does what it does").

Imported by pyclray.engine.queries.cast only for batches of at least its COHERENT_FROM rays (numba's import
and its compiled code's load from numba's disk cache are a process's first large cast's to pay, and
the first on a machine compiles). Each ray
is traced on its own, so the order changes no bit of any result; only which rays run side by side.
"""
from __future__ import annotations

import numba
import numpy as np

CODES = 1 << 15  # the codes' range: 15 bits


def morton_tables(bits: tuple[int, ...]) -> np.ndarray:
    """(dimensions, 32) uint16: per dimension, table[v] holds the bits of v (bits[dimension] of them)
    at their places in a Morton code, the most significant level first; at each level the
    dimensions that still have a bit, in order, take the next places down."""
    place, places = sum(bits), [[] for _ in bits]
    for level in range(max(bits)):
        for dimension, count in enumerate(bits):
            if level < count:
                place -= 1
                places[dimension].append(place)  # bit count - 1 - level of the dimension's cell
    tables = np.zeros((len(bits), 32), np.uint16)
    for dimension, count in enumerate(bits):
        values = np.arange(1 << count, dtype=np.uint32)
        for level, at in enumerate(places[dimension]):
            tables[dimension, : 1 << count] |= (((values >> np.uint32(count - 1 - level)) & np.uint32(1))
                                                << np.uint32(at)).astype(np.uint16)
    return tables


# Origins x, y, z in 8 cells per axis and directions in 4: 15 bits (as good an order as 30 bits on
# both ray sets of bench/secondary.py); rays from within one origin cell (a camera's, a shared
# origin) by their directions alone, in 32 cells per axis.
WITH_ORIGINS = morton_tables((3, 3, 3, 2, 2, 2))
DIRECTIONS_ONLY = morton_tables((5, 5, 5))


# scan_codes' passes index rows through the flat array (3 i + axis): indexed as [i, axis], numba's code
# for a possibly negative index kept LLVM from vectorizing them (docs/benchmarks.md, "Why the engine
# does what it does").


@numba.njit(cache=True, nogil=True, fastmath={"reassoc"})
def _all_finite(flat):
    """Whether every value is finite: v - v is 0 exactly for a finite v, NaN for inf and NaN, so
    their sum is 0 exactly when all are (summed in any order, reassoc: vector lanes)."""
    total = 0.0
    for i in range(flat.shape[0]):
        total += flat[i] - flat[i]
    return total == 0


@numba.njit(cache=True, nogil=True, fastmath={"nnan"})
def _box(flat):
    """(lo, hi) of (N, 3) points given flat; by comparisons that assume no NaN (vector lanes): a
    batch with a NaN is refused by _all_finite before its box is used."""
    x0, y0, z0 = np.inf, np.inf, np.inf
    x1, y1, z1 = -np.inf, -np.inf, -np.inf
    for i in range(flat.shape[0] // 3):
        x, y, z = flat[3 * i], flat[3 * i + 1], flat[3 * i + 2]
        x0, y0, z0 = x if x < x0 else x0, y if y < y0 else y0, z if z < z0 else z0
        x1, y1, z1 = x if x > x1 else x1, y if y > y1 else y1, z if z > z1 else z1
    return np.array([x0, y0, z0]), np.array([x1, y1, z1])


@numba.njit(cache=True, nogil=True)
def _cell(value, cells):
    """The cell of a value, clipped to [0, cells - 1] by comparisons (NaN, from a batch that is not
    fine and whose codes are not used, to 0: never an index outside the tables)."""
    value = value if value > 0.0 else 0.0
    return np.int32(value if value < cells - 1 else cells - 1)


@numba.njit(cache=True, nogil=True)
def _spread5(v):
    """The 5 bits of v at every third place (bit b at 3 b): the Morton interleave of one axis."""
    v = (v | (v << 8)) & 0x100F
    v = (v | (v << 4)) & 0x10C3
    return (v | (v << 2)) & 0x1249


# numpy's error model: a zero direction (a batch that is not fine) divides to inf, not an exception
@numba.njit(cache=True, nogil=True, error_model="numpy")
def _direction_codes(flat):
    """(no zero direction, codes): each ray's code by its direction alone, DIRECTIONS_ONLY's
    interleave of its 32 cells per axis of d / |d|_1 in [-1, 1] written as arithmetic (vector
    lanes, where the tables' lookups are not): (d / |d|_1 + 1) / 2 * 32, by one division per ray."""
    count = flat.shape[0] // 3
    codes = np.empty(count, np.uint16)
    zeros = 0
    for i in range(count):
        x, y, z = flat[3 * i], flat[3 * i + 1], flat[3 * i + 2]
        zeros += (x == 0) & (y == 0) & (z == 0)
        to_cells = 16.0 / (abs(x) + abs(y) + abs(z))
        codes[i] = ((_spread5(_cell(x * to_cells + 16.0, 32.0)) << 2) | (_spread5(_cell(y * to_cells + 16.0, 32.0)) << 1)
                    | _spread5(_cell(z * to_cells + 16.0, 32.0)))
    return zeros == 0, codes


@numba.njit(cache=True, nogil=True)
def _no_zero(flat):
    """Whether no direction of flat (N, 3) is (0, 0, 0): _direction_codes' check without its codes."""
    zeros = 0
    for i in range(flat.shape[0] // 3):
        zeros += (flat[3 * i] == 0) & (flat[3 * i + 1] == 0) & (flat[3 * i + 2] == 0)
    return zeros == 0


def scan_codes(origins: np.ndarray, directions: np.ndarray, codes: bool = True):
    """(fine, lo, hi, codes) of (N, 3) float64 arrays: whether every coordinate is finite and no
    direction is zero, the origins' box, and each ray's code by its direction alone (DIRECTIONS_ONLY:
    the order of a batch whose origins share one cell, such as a camera's; None unless codes), in one
    compiled pass per quantity (numpy's checks took five passes, its extent six more;
    docs/benchmarks.md, "Why the engine does what it does"). The box and the codes of a batch that is
    not fine are not used."""
    origins, directions = np.ascontiguousarray(origins).reshape(-1), np.ascontiguousarray(directions).reshape(-1)
    fine = _all_finite(origins) and _all_finite(directions)
    lo, hi = _box(origins)
    if codes:
        no_zero, direction_codes = _direction_codes(directions)
    else:
        no_zero, direction_codes = _no_zero(directions), None
    return fine and no_zero, lo, hi, direction_codes


@numba.njit(cache=True, nogil=True)
def _codes(origins, directions, lo, scale, tables, with_origins):
    """Per ray its code: origin cell (o - lo) * scale per axis (with_origins), direction cell of
    d / |d|_1 in [-1, 1]; cells clipped to the table's range (as numpy's clip did). Called for
    batches found fine only (no NaN reaches a table's index)."""
    count = directions.shape[0]
    codes = np.empty(count, np.uint16)
    origin_cells = 8.0
    direction_cells = 4.0 if with_origins else 32.0
    for i in range(count):
        code = np.uint16(0)
        row = 0
        if with_origins:
            for axis in range(3):
                value = min(max((origins[i, axis] - lo[axis]) * scale, 0.0), origin_cells - 1)
                code |= tables[row, int(value)]
                row += 1
        # (d / |d|_1 + 1) / 2 * cells, by one division per ray
        to_cells = 0.5 * direction_cells / (abs(directions[i, 0]) + abs(directions[i, 1]) + abs(directions[i, 2]))
        for axis in range(3):
            value = min(max(directions[i, axis] * to_cells + 0.5 * direction_cells, 0.0), direction_cells - 1)
            code |= tables[row, int(value)]
            row += 1
        codes[i] = code
    return codes


@numba.njit(cache=True, nogil=True)
def _counting_sort(codes):
    """order[place]: the ray at each place of the stable sort of the codes (a counting sort over
    the 2^15 codes: one pass to count, one to place)."""
    count = codes.shape[0]
    starts = np.zeros(CODES + 1, np.int64)
    for i in range(count):
        starts[codes[i] + 1] += 1
    for code in range(CODES):
        starts[code + 1] += starts[code]
    order = np.empty(count, np.int32)
    for i in range(count):
        at = starts[codes[i]]
        starts[codes[i]] = at + 1
        order[at] = i
    return order


def coherent_order(origins: np.ndarray, directions: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                   scene_size: float, direction_codes: np.ndarray | None = None) -> np.ndarray:
    """order[i]: the place in the batch of the i-th ray along a Morton curve of (origin, direction).
    Origins in cubic cells of the batch's box (lo, hi), never finer than 1/8 of the scene's size;
    directions by d / |d|_1. The rays are not gathered in that order: the kernel reads each through
    order (a gather on the host wrote 4.8 MB of fresh memory per 100,000 rays, page faults and all:
    more than the whole sort). direction_codes: scan_codes' codes, used where the origins share
    one cell (else computed here)."""
    extent = max(float((hi - lo).max()), scene_size, 1e-300)
    with_origins = len(origins) > 1 and float((hi - lo).max()) > extent / 8
    if direction_codes is not None and not with_origins:
        return _counting_sort(direction_codes)
    tables = WITH_ORIGINS if with_origins else DIRECTIONS_ONLY
    return _counting_sort(_codes(origins, directions, np.ascontiguousarray(lo, np.float64), 8.0 / extent, tables,
                                 with_origins))
