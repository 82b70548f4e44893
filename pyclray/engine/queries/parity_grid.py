"""The parity grid of closed meshes: occupancy's shortcut for a scene of closed meshes alone
(engine/queries/closest.py), made at its first large batch and kept with the meshes' handle.

A grid of cells around the meshes' box (GRID_CELLS along its largest side, one more beyond it on
each side); a cell is a surface cell where the box of some triangle, widened (SURFACE_MARGIN,
CLEARANCE), meets it, else empty. A point's cell is floor((x - lo) / size) per axis in float64: a
function of each coordinate that never decreases as the coordinate grows (each operation rounds
correctly), so that the points of one cell form a box, and the points of two face-neighbouring
cells a box too. So:

- a point of an empty cell is on no triangle (that triangle's box would meet the cell), and all
  the points of a connected region of empty cells have one inside: a path between two of them
  stays within boxes that no triangle meets, and for a closed mesh (every edge shared by two faces)
  the parity of a path's crossings depends on its ends alone, as does its signed count (the
  winding number), mesh by mesh. One point of each region (near the centre of its first cell) is
  decided by its exact rays (count_hits' tie rule: each mesh's parity, or the signed crossings for
  sign="winding"), and every point of an empty cell takes its region's answer without a ray;
- a point beyond the grid is beyond the meshes' box: outside, on no surface;
- a point of a surface cell is left to its own ray (and surface test), as without the grid.

A point of an empty cell lies at least CLEARANCE of a cell from every triangle, far beyond the
float32 rounding of a triangle tested from it: its own parity ray counts as the grid answers (the
same bits as without the grid: tests/test_occupancy_grid.py). On uniform points in a mesh's box
most points are in empty cells; near the surface few are.
"""
from __future__ import annotations

import numba
import numpy as np

# cells along the largest side of the mesh's box (the others in proportion)
GRID_CELLS = 64

# where in its cell a region's decided point lies (a fraction of the cell per axis): near its
# centre, away from the cell's sides and from the surfaces beyond them
REFERENCE_AT = np.array([0.5123, 0.4769, 0.5351])

# a triangle's box is widened by this much of the mesh's largest coordinate (thousands of float64
# ulps) and by TINY: a point that the closest-point query finds at distance 0 from a triangle (its
# computed nearest point, a few ulps off the exact triangle at most, or at a distance whose square
# underflows) lies in one of the triangle's surface cells too
SURFACE_MARGIN = 2.0**-40
TINY = 1e-150
# ... and by at least this much of a cell: a point of an empty cell is that far from every triangle
CLEARANCE = 2.0**-10

# the cell states
SURFACE, OUTSIDE, INSIDE = -1, 0, 1


@numba.njit(cache=True, nogil=True)
def _cell(x, lo, size):
    """The cell coordinate of x along an axis (its floor is the cell's index): the one formula of
    the marks and the lookups."""
    return (x - lo) / size


@numba.njit(cache=True, nogil=True)
def _mark(low, high, lo, size, dims):
    """(fits, surface): uint8 per cell (x fastest), 1 where the box [low, high] of some triangle
    meets it; fits is False (and the marks unfinished) where a box reaches beyond the grid."""
    surface = np.zeros(dims[0] * dims[1] * dims[2], np.uint8)
    first = np.empty(3, np.int64)
    last = np.empty(3, np.int64)
    for t in range(low.shape[0]):
        for axis in range(3):
            a = _cell(low[t, axis], lo[axis], size)
            b = _cell(high[t, axis], lo[axis], size)
            if not (a >= 0.0 and b < dims[axis]):
                return False, surface
            first[axis], last[axis] = np.int64(a), np.int64(b)
        for z in range(first[2], last[2] + 1):
            for y in range(first[1], last[1] + 1):
                row = (z * dims[1] + y) * dims[0]
                for x in range(first[0], last[0] + 1):
                    surface[row + x] = 1
    return True, surface


@numba.njit(cache=True, nogil=True)
def _regions(surface, dims):
    """(region per cell: the index of its connected region of empty cells, -1 for a surface cell;
    each region's first cell), by a breadth-first search over face neighbours from each cell not
    yet reached."""
    count = surface.shape[0]
    region = np.full(count, -1, np.int32)
    firsts = np.empty(count, np.int64)
    queue = np.empty(count, np.int64)
    layer = dims[0] * dims[1]
    regions = 0
    for seed in range(count):
        if surface[seed] or region[seed] >= 0:
            continue
        region[seed] = regions
        firsts[regions] = seed
        head, tail = 0, 1
        queue[0] = seed
        while head < tail:
            cell = queue[head]
            head += 1
            x, y, z = cell % dims[0], (cell // dims[0]) % dims[1], cell // layer
            for k in range(6):
                if k == 0 and x + 1 < dims[0]:
                    other = cell + 1
                elif k == 1 and x > 0:
                    other = cell - 1
                elif k == 2 and y + 1 < dims[1]:
                    other = cell + dims[0]
                elif k == 3 and y > 0:
                    other = cell - dims[0]
                elif k == 4 and z + 1 < dims[2]:
                    other = cell + layer
                elif k == 5 and z > 0:
                    other = cell - layer
                else:
                    continue
                if not surface[other] and region[other] < 0:
                    region[other] = regions
                    queue[tail] = other
                    tail += 1
        regions += 1
    return region, firsts[:regions].copy()


@numba.njit(cache=True, nogil=True)
def _lookup(points, lo, size, dims, state):
    """Per point: decided (1 where its cell decides it: an empty cell or beyond the grid) and, for
    those, inside (1 in an inside region's cell)."""
    count = points.shape[0]
    decided = np.zeros(count, np.uint8)
    inside = np.zeros(count, np.uint8)
    for i in range(count):
        cell = 0
        for axis in (2, 1, 0):
            c = _cell(points[i, axis], lo[axis], size)
            if not (c >= 0.0 and c < dims[axis]):
                cell = -1
                break
            cell = cell * dims[axis] + np.int64(c)
        if cell < 0:  # beyond the grid: beyond the mesh's box
            decided[i] = 1
        elif state[cell] != SURFACE:  # an empty cell: its region's inside
            decided[i] = 1
            inside[i] = state[cell]
    return decided, inside


class ParityGrid:
    """The grid of closed meshes (see the module's text): per cell its empty region (int32, x
    fastest; -1 for a surface cell), each region's decided point (seeds), its first cell's corner
    lo and cells of side size, dims per axis; per sign rule ("parity", "winding": a closed mesh's
    winding number is constant on a region too) the cells' states (SURFACE, OUTSIDE, INSIDE), made
    when first asked for (decide)."""

    def __init__(self, lo: np.ndarray, size: float, dims: np.ndarray, region: np.ndarray, seeds: np.ndarray):
        self.lo, self.size, self.dims, self.region, self.seeds = lo, size, dims, region, seeds
        self.states: dict = {}
        self.device_states: dict = {}  # per sign the states on a device (cast_device.py: grid_lookup_device)

    @classmethod
    def of(cls, corners) -> "ParityGrid | None":
        """The grid of closed meshes' triangles (corners: a, b, c, (F, 3) float64 each, in world
        space), or None where it cannot be made (no triangle, no extent, a mesh too large for the
        grid's float64 cells)."""
        a, b, c = corners
        if not len(a):
            return None
        low = np.minimum(np.minimum(a, b), c)
        high = np.maximum(np.maximum(a, b), c)
        box_lo, box_hi = low.min(axis=0), high.max(axis=0)
        size = float((box_hi - box_lo).max()) / GRID_CELLS
        if not (size > 0 and np.isfinite(size)):
            return None
        margin = max(SURFACE_MARGIN * float(np.abs(np.stack([box_lo, box_hi])).max()) + TINY, CLEARANCE * size)
        low, high = low - margin, high + margin
        lo = box_lo - margin - size  # a cell beyond the widened boxes on each side (_mark makes sure)
        dims = (np.floor((box_hi + margin - lo) / size) + 2).astype(np.int64)
        if not np.all(dims <= 4 * GRID_CELLS):
            return None
        fits, surface = _mark(low, high, lo, size, dims)
        if not fits:
            return None
        region, firsts = _regions(surface, dims)
        # each region's decided point, in its first cell (which must hold it: checked)
        at = np.stack([firsts % dims[0], (firsts // dims[0]) % dims[1], firsts // (dims[0] * dims[1])], axis=1)
        seeds = lo + (at + REFERENCE_AT) * size
        if not np.array_equal(np.floor((seeds - lo) / size), at):
            return None
        return cls(lo, size, dims, region, seeds)

    def decide(self, sign: str, rule) -> None:
        """The cells' states by a sign rule, where not made yet: rule(points (N, 3)) -> bool, the
        exact inside of points on no surface, asked of the regions' seeds."""
        if sign not in self.states:
            region_inside = np.asarray(rule(self.seeds), bool) if len(self.seeds) else np.zeros(0, bool)
            state = np.full(len(self.region), SURFACE, np.int8)
            empty = self.region >= 0
            state[empty] = region_inside[self.region[empty]].astype(np.int8)
            self.states[sign] = state

    def lookup(self, points: np.ndarray, sign: str) -> tuple[np.ndarray, np.ndarray]:
        """(decided, inside) per point (N, 3), bool each, by the sign rule's states (decide): see
        _lookup."""
        decided, inside = _lookup(np.ascontiguousarray(points, np.float64), self.lo, self.size, self.dims,
                                  self.states[sign])
        return decided.view(bool), inside.view(bool)
