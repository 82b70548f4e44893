"""The parity grid of closed meshes: occupancy's (and signed distance's sign's) shortcut for a
scene of closed meshes alone (engine/queries/closest.py), made at its first large batch and kept
with the meshes' handle.

Two levels. A coarse grid of cells around the meshes' box (GRID_CELLS along its largest side, one
more beyond it on each side); each coarse surface cell (below) is refined into a block of BLOCK^3
fine cells (up to MAX_FINE_CELLS fine cells in all, in the coarse cells' order). At each level a
cell is a surface cell where some triangle may come within margin of it (margin: SURFACE_MARGIN
of the largest coordinate, and at least CLEARANCE of a coarse cell, at both levels): where the
triangle's box widened by margin meets the cell, and its plane widened too (_meets) meets it;
else it is empty.

A point's fine cell is floor((x - lo) / (size / BLOCK)) per axis in float64, its coarse cell that
floor divided by BLOCK (rounded down): the fine coordinate is a function of each coordinate that
never decreases as the coordinate grows (each operation rounds correctly), so the points of one
fine cell form a box, and those of one coarse cell too (BLOCK^3 fine cells' boxes side by side).
As BLOCK is a power of two, fl((x - lo) / (size / BLOCK)) == BLOCK * fl((x - lo) / size) exactly
(scaling by a power of two commutes with rounding, barring overflow and subnormals, where both are
beyond the grid or in its first cell): the coarse cell is the one-level grid's floor((x - lo) /
size) (tests/test_occupancy_grid.py checks).

Why an empty cell holds no point within margin of a triangle: a point p of the cell within margin
of a point q of the triangle lies in the widened box, whose cells (by the same monotone formula)
include p's; and along the computed unit normal n, |n.(q - a)| is within REACH of the triangle's
extent (n within 2^-31 of the exact normal: the triangle is no sliver, SLIVER) and |n.(p - q)|
within margin, while p lies within half a side (plus slack: the rounding of the cell's index and
of its computed centre, SLACK of the grid's coordinates) of the cell's centre c per axis: so
|n.(c - a)| <= sum |n_k| (side / 2 + slack) + reach, which _meets tests with room for its own
roundings. A sliver's cells are those of its box.

The empty cells, coarse ones and the fine ones of the refined blocks, are joined into connected
regions by their face neighbours (two fine cells side by side, in one block or two; a fine cell on
a block's side and the empty coarse cell beyond it): the points of a cell and of a face
neighbour's form a box, or two boxes whose common face holds the smaller one's (a fine cell and a
coarse one), so a path between any two points of a region stays within its cells. So:

- a point of an empty cell is on no triangle, and all the points of a connected region of empty
  cells have one inside: a path between two of them stays within cells that no triangle meets,
  and for a closed mesh (every edge shared by two faces) the parity of a path's crossings depends
  on its ends alone, as does its signed count (the winding number), mesh by mesh. One point of
  each region (near the centre of its first cell, by the fine coordinate's formula: checked) is
  decided by its exact rays (count_hits' tie rule: each mesh's parity, or the signed crossings
  for sign="winding"), and every point of an empty cell takes its region's answer without a ray;
- a point beyond the grid is beyond the meshes' box: outside, on no surface;
- a point of a fine surface cell, or of a coarse surface cell not refined, is left to its own ray
  (and surface test), as without the grid.

A point of an empty cell lies farther than margin, at least CLEARANCE of a coarse cell, from every
triangle (the same margin at both levels), far beyond the float32 rounding of a triangle tested
from it: its own parity ray counts as the grid answers (the same bits as without the grid:
tests/test_occupancy_grid.py); and a point that the closest-point query finds at distance 0 (its
computed nearest point a few ulps off the triangle) is in a surface cell. On uniform points in a
mesh's box most points are in empty coarse cells; of the points near the surface many are in
empty fine cells.

The fine level's cost is bounded: at most MAX_FINE_CELLS fine cells (the coarse surface cells
beyond them, in the cells' order, are left coarse), and no fine level where the fine marks would
test more than FINE_WORK fine cells in all (per triangle those of its widened box within refined
blocks: many large triangles), the coarse answers then alone. A block whose fine cells are all
surface cells (near a large triangle) is left coarse too: it would decide nothing. The fine level
is made where asked for (of: refine): closest.py asks at the first batch with many points in
coarse surface cells.
"""
from __future__ import annotations

import numba
import numpy as np

# cells along the largest side of the mesh's box (the others in proportion)
GRID_CELLS = 64
# fine cells along each side of a refined coarse cell (a power of two, see the module's text; at
# least 4: a block's cells are whole words of 64 bits in the lookup)
BLOCK = 8
# the most fine cells (BLOCK^3 per refined coarse cell): kept, a byte each (their regions) and 2
# bits per sign rule (the states); during the build about 10 bytes each
MAX_FINE_CELLS = 1 << 24
# the most fine cells that the fine marks may test in all (_fine_work)
FINE_WORK = 1 << 27

# where in its cell a region's decided point lies (a fraction of the cell per axis): near its
# centre, away from the cell's sides and from the surfaces beyond them
REFERENCE_AT = np.array([0.5123, 0.4769, 0.5351])

# a triangle's box and plane are widened by this much of the mesh's largest coordinate (thousands of
# float64 ulps) and by TINY: a point that the closest-point query finds at distance 0 from a
# triangle (its computed nearest point, a few ulps off the exact triangle at most, or at a distance
# whose square underflows) lies in one of the triangle's surface cells too
SURFACE_MARGIN = 2.0**-40
TINY = 1e-150
# ... and by at least this much of a coarse cell (at both levels): a point of an empty cell is that
# far from every triangle
CLEARANCE = 2.0**-10

# a triangle's plane is widened too (the cells that its widened box meets are marked where the
# widened plane meets them as well): by REACH of the triangle's extent (the computed unit normal's
# error, a few float64 roundings over the sine of its angle at a, at least SLIVER: a triangle
# thinner than that is marked by its box alone), by the margin, by SLACK of the magnitudes of the
# cell's centre's terms (the rounding of the cell's place and of the dot product)
SLIVER = 2.0**-19
REACH = 2.0**-28
SLACK = 2.0**-40

# the cell states
SURFACE, OUTSIDE, INSIDE = -1, 0, 1


@numba.njit(cache=True, nogil=True)
def _cell(x, lo, fine_size):
    """The fine cell coordinate of x along an axis (its floor is the fine cell's index, that
    divided by BLOCK the coarse cell's): the one formula of the marks and the lookups."""
    return (x - lo) / fine_size


@numba.njit(cache=True, nogil=True)
def _meets(t, x, y, z, side, lo, normals, corners, reach, slack):
    """Whether triangle t's plane, widened, may meet the cell of index (x, y, z) and side side
    (coarse or fine): the distance along the unit normal from the cell's computed centre to the
    triangle's corner within the cell's half-width along it (each half side widened by slack, the
    cell's rounding) plus reach[t], plus SLACK of the dot product's terms' magnitudes (its
    rounding), the whole bound widened by SLACK (its own rounding); always where the normal is 0
    (a sliver). See the module's text."""
    d0 = lo[0] + (x + 0.5) * side - corners[t, 0]
    d1 = lo[1] + (y + 0.5) * side - corners[t, 1]
    d2 = lo[2] + (z + 0.5) * side - corners[t, 2]
    n0, n1, n2 = normals[t, 0], normals[t, 1], normals[t, 2]
    along = n0 * d0 + n1 * d1 + n2 * d2
    weight = abs(n0) + abs(n1) + abs(n2)
    rounding = SLACK * (abs(n0 * d0) + abs(n1 * d1) + abs(n2 * d2))
    return abs(along) <= (weight * (0.5 * side + slack) + reach[t] + rounding) * (1.0 + SLACK)


@numba.njit(cache=True, nogil=True)
def _mark(low, high, lo, fine_size, dims, block, normals, corners, reach, slack):
    """(fits, surface): uint8 per coarse cell (x fastest), 1 where some triangle's widened box and
    widened plane (_meets) both meet it; fits is False (and the marks unfinished) where a box
    reaches beyond the grid."""
    surface = np.zeros(dims[0] * dims[1] * dims[2], np.uint8)
    first = np.empty(3, np.int64)
    last = np.empty(3, np.int64)
    size = fine_size * block
    for t in range(low.shape[0]):
        for axis in range(3):
            a = _cell(low[t, axis], lo[axis], fine_size)
            b = _cell(high[t, axis], lo[axis], fine_size)
            if not (a >= 0.0 and b < dims[axis] * block):
                return False, surface
            first[axis], last[axis] = np.int64(a) // block, np.int64(b) // block
        for z in range(first[2], last[2] + 1):
            for y in range(first[1], last[1] + 1):
                row = (z * dims[1] + y) * dims[0]
                for x in range(first[0], last[0] + 1):
                    if not surface[row + x] and _meets(t, x, y, z, size, lo, normals, corners, reach, slack):
                        surface[row + x] = 1
    return True, surface


@numba.njit(cache=True, nogil=True)
def _mark_fine(low, high, lo, fine_size, dims, block, blocks, count, normals, corners, reach, slack):
    """uint8 per fine cell of the count refined blocks (blocks: per coarse cell its block's index or
    -1; in a block x fastest), 1 where some triangle's widened box and widened plane (_meets) both
    meet it (the boxes fit the grid: _mark)."""
    cube = block * block * block
    surface = np.zeros(count * cube, np.uint8)
    first = np.empty(3, np.int64)
    last = np.empty(3, np.int64)
    for t in range(low.shape[0]):
        for axis in range(3):
            first[axis] = np.int64(_cell(low[t, axis], lo[axis], fine_size))
            last[axis] = np.int64(_cell(high[t, axis], lo[axis], fine_size))
        for cz in range(first[2] // block, last[2] // block + 1):
            for cy in range(first[1] // block, last[1] // block + 1):
                for cx in range(first[0] // block, last[0] // block + 1):
                    b = blocks[(cz * dims[1] + cy) * dims[0] + cx]
                    if b < 0:
                        continue
                    base = b * cube
                    for z in range(max(first[2], cz * block), min(last[2], cz * block + block - 1) + 1):
                        for y in range(max(first[1], cy * block), min(last[1], cy * block + block - 1) + 1):
                            row = base + ((z - cz * block) * block + (y - cy * block)) * block - cx * block
                            for x in range(max(first[0], cx * block), min(last[0], cx * block + block - 1) + 1):
                                if not surface[row + x] and _meets(t, x, y, z, fine_size, lo, normals, corners,
                                                                   reach, slack):
                                    surface[row + x] = 1
    return surface


def _fine_work(low, high, lo, fine_size, dims, refined) -> float:
    """The fine marks' work (_mark_fine: the fine cells tested): per triangle the fine cells of its
    box, at most BLOCK^3 per refined coarse cell in it (refined: bool per coarse cell; counted by a
    summed-volume table of them), summed; or the whole boxes' sum where that is within FINE_WORK."""
    first = np.floor((low - lo) / fine_size).astype(np.int64)
    last = np.floor((high - lo) / fine_size).astype(np.int64)
    box = np.prod((last - first + 1).astype(np.float64), axis=1)
    if float(box.sum()) <= FINE_WORK:  # within the cap counted in the whole boxes: no table needed
        return float(box.sum())
    table = np.zeros((dims[2] + 1, dims[1] + 1, dims[0] + 1), np.int64)
    table[1:, 1:, 1:] = refined.reshape(dims[2], dims[1], dims[0]).cumsum(0).cumsum(1).cumsum(2)
    x0, y0, z0 = (first // BLOCK).T
    x1, y1, z1 = (last // BLOCK + 1).T
    count = (table[z1, y1, x1] - table[z0, y1, x1] - table[z1, y0, x1] - table[z1, y1, x0]
             + table[z0, y0, x1] + table[z0, y1, x0] + table[z1, y0, x0] - table[z0, y0, x0])
    return float(np.minimum(box, count * float(BLOCK**3)).sum())


def _planes(a, b, c, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """(normals, reach): per triangle (corners a, b, c) its computed unit normal (0 for a sliver,
    whose angle at a has a sine below SLIVER, or a normal not finite) and how far along it from the
    plane through a a point within margin of the triangle may lie: REACH of the triangle's extent
    (the triangle's own points: the normal's direction is within about 8 float64 roundings over
    that sine, 2^-31, of the exact one) plus margin (times 1 + SLACK: the normal's length within
    roundings of 1)."""
    ab, ac = b - a, c - a  # each within half an ulp of the exact difference (of its own magnitude)
    cross = np.cross(ab, ac)
    with np.errstate(over="ignore", invalid="ignore"):
        area2 = np.einsum("ij,ij->i", cross, cross)
        length = np.sqrt(area2)
        fat = (area2 > SLIVER**2 * np.einsum("ij,ij->i", ab, ab) * np.einsum("ij,ij->i", ac, ac)) & (length > 0)
        normals = cross / np.where(fat, length, 1.0)[:, None]
        extent = np.abs(ab).sum(axis=1) + np.abs(ac).sum(axis=1)
        good = fat & np.isfinite(normals).all(axis=1) & np.isfinite(extent)
    normals[~good] = 0.0
    return np.ascontiguousarray(normals), np.where(good, REACH * extent, 0.0) + margin * (1.0 + SLACK)


@numba.njit(cache=True, nogil=True)
def _regions(surface, dims, blocks, cells, fine_surface, block):
    """(region per node, each region's first node): the connected regions of empty cells, by a
    breadth-first search over face neighbours from each empty cell not yet reached. The nodes: the
    coarse cells (x fastest; -1 for a surface cell), then the refined blocks' fine cells (block by
    block, x fastest in each; -1 for a fine surface cell). cells: per block its coarse cell."""
    coarse = surface.shape[0]
    cube = block * block * block
    count = coarse + fine_surface.shape[0]
    region = np.full(count, -1, np.int32)
    firsts = np.empty(1024, np.int32)  # grown as regions are found (most meshes have few)
    queue = np.empty(count, np.int32)
    layer = dims[0] * dims[1]
    coarse_strides = np.array([1, dims[0], layer])
    fine_strides = np.array([1, block, block * block])
    at = np.empty(3, np.int64)
    shift = 0  # block = 2^shift: the fine cells' divisions by shifts and masks
    while (1 << shift) < block:
        shift += 1
    regions = 0
    for seed in range(count):
        if region[seed] >= 0 or (surface[seed] if seed < coarse else fine_surface[seed - coarse]):
            continue
        region[seed] = regions
        if regions == len(firsts):
            grown = np.empty(2 * len(firsts), np.int32)
            grown[:regions] = firsts
            firsts = grown
        firsts[regions] = seed
        head, tail = 0, 1
        queue[0] = seed
        while head < tail:
            node = np.int64(queue[head])
            head += 1
            if node < coarse:  # a coarse cell: its empty coarse neighbours, the facing fine cells of refined ones
                at[0], at[1], at[2] = node % dims[0], (node // dims[0]) % dims[1], node // layer
                for k in range(6):
                    axis, step = k >> 1, 1 - 2 * (k & 1)
                    if not (0 <= at[axis] + step < dims[axis]):
                        continue
                    other = node + step * coarse_strides[axis]
                    if not surface[other]:
                        if region[other] < 0:
                            region[other] = regions
                            queue[tail] = other
                            tail += 1
                    elif blocks[other] >= 0:  # the refined block's side facing this cell
                        base = blocks[other] * cube + (0 if step > 0 else (block - 1) * fine_strides[axis])
                        along_i, along_j = fine_strides[(axis + 1) % 3], fine_strides[(axis + 2) % 3]
                        for i in range(block):
                            for j in range(block):
                                fine = base + i * along_i + j * along_j
                                if not fine_surface[fine] and region[coarse + fine] < 0:
                                    region[coarse + fine] = regions
                                    queue[tail] = coarse + fine
                                    tail += 1
            else:  # a fine cell: its fine neighbours, in its block or the next, or an empty coarse cell
                b = (node - coarse) >> (3 * shift)
                local = (node - coarse) & (cube - 1)
                at[0], at[1], at[2] = local & (block - 1), (local >> shift) & (block - 1), local >> (2 * shift)
                for k in range(6):
                    axis, step = k >> 1, 1 - 2 * (k & 1)
                    if 0 <= at[axis] + step < block:  # in its block
                        other = node + step * fine_strides[axis]
                        if fine_surface[other - coarse]:
                            continue
                    else:  # beyond its block's side: the next coarse cell's
                        cell = cells[b]
                        place = (cell % dims[0], (cell // dims[0]) % dims[1], cell // layer)[axis] + step
                        if not (0 <= place < dims[axis]):
                            continue
                        other_cell = cell + step * coarse_strides[axis]
                        if not surface[other_cell]:
                            other = other_cell
                        elif blocks[other_cell] >= 0:
                            other = coarse + blocks[other_cell] * cube + local - step * (block - 1) * fine_strides[axis]
                            if fine_surface[other - coarse]:
                                continue
                        else:
                            continue
                    if region[other] < 0:
                        region[other] = regions
                        queue[tail] = other
                        tail += 1
        regions += 1
    return region, firsts[:regions].copy()


@numba.njit(cache=True, nogil=True)
def _lookup(points, lo, fine_size, dims, block, state, blocks, fine_bits):
    """Per point: decided (1 where its cell decides it: an empty coarse or fine cell, or beyond the
    grid) and, for those, inside (1 in an inside region's cell). fine_bits: per refined block its
    fine cells' surface bits, then their inside bits (words of 64 cells each, in the block's order)."""
    count = points.shape[0]
    decided = np.zeros(count, np.uint8)
    inside = np.zeros(count, np.uint8)
    fine = np.empty(3, np.int64)
    shift = 0  # block = 2^shift: the fine indices' divisions by shifts and masks (they are >= 0)
    while (1 << shift) < block:
        shift += 1
    mask = block - 1
    words = block * block * block // 64
    for i in range(count):
        cell = 0
        for axis in (2, 1, 0):
            c = _cell(points[i, axis], lo[axis], fine_size)
            if not (c >= 0.0 and c < dims[axis] * block):
                cell = -1
                break
            fine[axis] = np.int64(c)
            cell = cell * dims[axis] + (fine[axis] >> shift)
        if cell < 0:  # beyond the grid: beyond the mesh's box
            decided[i] = 1
        elif state[cell] != SURFACE:  # an empty coarse cell: its region's inside
            decided[i] = 1
            inside[i] = state[cell]
        elif blocks[cell] >= 0:  # a refined surface cell: its fine cell's bits
            local = ((((fine[2] & mask) << shift) + (fine[1] & mask)) << shift) + (fine[0] & mask)
            at = blocks[cell] * 2 * words + (local >> 6)
            bit = np.uint64(local & 63)
            if not (fine_bits[at] >> bit) & np.uint64(1):
                decided[i] = 1
                inside[i] = (fine_bits[at + words] >> bit) & np.uint64(1)
    return decided, inside


def fine_bits(fine_state: np.ndarray, block: int) -> np.ndarray:
    """The fine cells' states (int8, block by block) as _lookup's bits: per block its words of
    surface bits, then its words of inside bits (bit k of word w: the block's cell 64 w + k)."""
    count = len(fine_state) // block**3
    cells = fine_state.reshape(count, 1, block**3 // 64, 64)
    flags = np.concatenate([cells == SURFACE, cells == INSIDE], axis=1)  # (blocks, 2, words, 64)
    packed = np.packbits(flags, axis=3, bitorder="little")  # byte j's bit i: cell 8 j + i
    out = np.ascontiguousarray(packed).view("<u8").reshape(-1).astype(np.uint64)
    return out if len(out) else np.zeros(1, np.uint64)


class ParityGrid:
    """The grid of closed meshes (see the module's text): its first cell's corner lo, coarse cells
    of side size (fine ones of size / block), dims coarse cells per axis; per coarse cell its empty
    region (region, int32, x fastest; -1 for a surface cell) and its refined block (blocks, int32;
    -1 for none); per fine cell of the blocks (block by block, x fastest in each) its region
    (fine_region, of the narrowest signed type; -1 for a fine surface cell); each region's decided
    point (seeds); per sign rule ("parity", "winding": a closed mesh's winding number is constant on
    a region too) the coarse cells' states (SURFACE, OUTSIDE, INSIDE: int8) and the fine cells'
    (fine_bits), made when first asked for (decide)."""

    def __init__(self, lo, size, dims, block, region, blocks, fine_region, seeds, refined=True):
        self.lo, self.size, self.dims, self.block = lo, size, dims, block
        self.fine_size = size / block
        self.region, self.blocks, self.fine_region, self.seeds = region, blocks, fine_region, seeds
        self.refined = refined  # whether the fine level was asked for (of: refine)
        self.states: dict = {}
        self.device_states: dict = {}  # per sign the states on a device (cast_device.py: grid_lookup_device)

    @property
    def nbytes(self) -> int:
        """The host memory of the grid's arrays (its states included)."""
        arrays = [self.region, self.blocks, self.fine_region, self.seeds]
        arrays += [s for pair in self.states.values() for s in pair]
        return sum(a.nbytes for a in arrays)

    @classmethod
    def of(cls, corners, refine: bool = True) -> "ParityGrid | None":
        """The grid of closed meshes' triangles (corners: a, b, c, (F, 3) float64 each, in world
        space), with its fine level where refine (within the caps) or its coarse level alone, or
        None where it cannot be made (no triangle, no extent, a mesh too large for the grid's
        float64 cells)."""
        a, b, c = corners
        if not len(a):
            return None
        low = np.minimum(np.minimum(a, b), c)
        high = np.maximum(np.maximum(a, b), c)
        box_lo, box_hi = low.min(axis=0), high.max(axis=0)
        size = float((box_hi - box_lo).max()) / GRID_CELLS
        fine_size = size / BLOCK  # exact: a power of two
        if not (fine_size > 0 and np.isfinite(size)):
            return None
        margin = max(SURFACE_MARGIN * float(np.abs(np.stack([box_lo, box_hi])).max()) + TINY, CLEARANCE * size)
        low, high = low - margin, high + margin
        lo = box_lo - margin - size  # a cell beyond the widened boxes on each side (_mark makes sure)
        dims = (np.floor((box_hi + margin - lo) / size) + 2).astype(np.int64)
        if not np.all(dims <= 4 * GRID_CELLS):
            return None
        # the cells' own reach beyond their sides (a point's computed cell index against its exact
        # place: a few roundings of the grid's coordinates)
        slack = SLACK * float(np.abs(np.stack([lo, lo + dims * size])).max())
        normals, reach = _planes(a, b, c, margin)
        plane = (normals, np.ascontiguousarray(a), reach, slack)
        fits, surface = _mark(low, high, lo, fine_size, dims, BLOCK, *plane)
        if not fits:
            return None
        # the refined blocks: the first coarse surface cells, within the caps
        blocks = np.full(len(surface), -1, np.int32)
        cells = np.flatnonzero(surface)[:MAX_FINE_CELLS // BLOCK**3]
        blocks[cells] = np.arange(len(cells), dtype=np.int32)
        if not refine or _fine_work(low, high, lo, fine_size, dims, blocks >= 0) > FINE_WORK:
            blocks[cells] = -1
            cells = cells[:0]
        fine_surface = _mark_fine(low, high, lo, fine_size, dims, BLOCK, blocks, len(cells), *plane)
        # a block whose fine cells are all surface cells decides nothing: left coarse
        full = fine_surface.reshape(len(cells), BLOCK**3).all(axis=1)
        if full.any():
            fine_surface = fine_surface.reshape(len(cells), BLOCK**3)[~full].reshape(-1)
            blocks[cells[full]] = -1
            cells = cells[~full]
            blocks[cells] = np.arange(len(cells), dtype=np.int32)
        nodes, firsts = _regions(surface, dims, blocks, cells.astype(np.int64), fine_surface, BLOCK)
        # each region's decided point, in its first cell (which must hold it, by the lookup's formula:
        # checked), the fine coordinates of that cell's corner
        coarse = firsts < len(surface)
        block_of = cells[np.maximum(firsts - len(surface), 0) // BLOCK**3] if len(cells) else 0
        first_cell = np.where(coarse, firsts, block_of)
        local = np.where(coarse, 0, (firsts - len(surface)) % BLOCK**3)
        layer = dims[0] * dims[1]
        at = (np.stack([first_cell % dims[0], (first_cell // dims[0]) % dims[1], first_cell // layer], axis=1) * BLOCK
              + np.stack([local % BLOCK, (local // BLOCK) % BLOCK, local // BLOCK**2], axis=1))
        span = np.where(coarse, BLOCK, 1)[:, None]  # a coarse cell spans BLOCK fine ones per axis
        seeds = lo + (at + REFERENCE_AT * span) * fine_size
        held = np.floor((seeds - lo) / fine_size)
        if not np.array_equal(held // span * span, at):
            return None
        fine_region = nodes[len(surface):]  # kept in the narrowest type that holds the regions' indices
        fine_region = fine_region.astype(np.min_scalar_type(-max(len(seeds), 1)))
        return cls(lo, size, dims, BLOCK, nodes[:len(surface)], blocks, fine_region, seeds, refine)

    def decide(self, sign: str, rule) -> None:
        """The cells' states by a sign rule, where not made yet: rule(points (N, 3)) -> bool, the
        exact inside of points on no surface, asked of the regions' seeds."""
        if sign not in self.states:
            region_inside = np.asarray(rule(self.seeds), bool) if len(self.seeds) else np.zeros(0, bool)

            def states(region):
                state = np.full(len(region), SURFACE, np.int8)
                empty = region >= 0
                state[empty] = region_inside[region[empty]].astype(np.int8)
                return state

            self.states[sign] = (states(self.region), fine_bits(states(self.fine_region), self.block))

    def lookup(self, points: np.ndarray, sign: str) -> tuple[np.ndarray, np.ndarray]:
        """(decided, inside) per point (N, 3), bool each, by the sign rule's states (decide): see
        _lookup."""
        state, bits = self.states[sign]
        decided, inside = _lookup(np.ascontiguousarray(points, np.float64), self.lo, self.fine_size, self.dims,
                                  self.block, state, self.blocks, bits)
        return decided.view(bool), inside.view(bool)
