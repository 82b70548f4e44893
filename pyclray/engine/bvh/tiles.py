"""Screen-space culling for the render kernel: for each tile of TILE x TILE pixels, the shapes of
each type whose conservative screen bounds meet it. The kernel visits only those and tests each
exactly as before, so the images do not change: a shape is left out of a tile only when no ray of
the tile can hit it, with a wide margin over every float rounding of the kernel.

Each entry is bounded by its type's bounding spheres (``Shape.spheres_of``); a type that is
not ``bounded`` (the plane) is visited in every tile.
"""
from __future__ import annotations

import warnings

import numpy as np

TILE = 16  # pixels per tile side, a power of two (and the render kernel's work-group size)
ENABLED = True  # False: every tile visits every shape (tests compare the two)

# The kernel's float32 test accepts a ray whose true squared distance to the centre exceeds r^2
# by at most a few dozen ulps of |F|^2 (F: centre in the camera space); 256 float32 ulps bound
# that with room to spare, so the radius is widened by sqrt(256 eps) |F| = 3.9e-3 |F| (an angle
# of 3.9e-3 radians, a couple of pixels at usual fields of view), plus rounding of the centre.
_WIDEN = 16.0 * np.sqrt(np.finfo(np.float32).eps)


def sphere_bounds(center, radius, origin, rotation):
    """(N, 4) bounds (sx_lo, sx_hi, sy_lo, sy_hi) of the image-plane coordinates (x/z, y/z in the
    camera space) of the rays that can meet each sphere (centres (N, 3), radii (N,)); NaN rows:
    anywhere (the sphere reaches the eye's plane); +inf lo rows: nowhere (wholly behind the eye)."""
    F = (np.asarray(center, np.float64) - origin) @ np.asarray(rotation, np.float64).T  # camera space: x left, y up, z forward
    r = np.asarray(radius, np.float64)
    distance = np.linalg.norm(F, axis=1)
    r = r * (1 + 1e-6) + _WIDEN * distance
    x, y, z = F[:, 0], F[:, 1], F[:, 2]
    out = np.full((len(r), 4), np.nan)
    ahead = z - r > 1e-6 * r  # wholly in front of the eye's plane, with a margin
    behind = z + r < 0
    out[behind] = (np.inf, -np.inf, np.inf, -np.inf)
    with np.errstate(invalid="ignore", divide="ignore"):
        denominator = z * z - r * r
        for axis, (a, col) in enumerate(((x, 0), (y, 2))):
            # planes a = t z through the eye tangent to the sphere: t = (a z -+ r sqrt(a^2 + z^2 - r^2)) / (z^2 - r^2)
            root = r * np.sqrt(a * a + z * z - r * r)
            lo = (a * z - root) / denominator
            hi = (a * z + root) / denominator
            out[ahead, col] = lo[ahead]
            out[ahead, col + 1] = hi[ahead]
    return out


def _pixel_range(lo, hi, tangent, centre, size):
    """First and last pixel index whose centre coordinate tangent (2 centre - 2 i - 1) / size
    (model.camera.ImagePlane; centre: the principal point in pixels) lies in [lo, hi] (the
    coordinate decreases with i), widened by one pixel and clamped."""
    with np.errstate(over="ignore", invalid="ignore"):
        first = np.floor((2 * centre - 1 - size * (hi / tangent)) / 2) - 1
        last = np.ceil((2 * centre - 1 - size * (lo / tangent)) / 2) + 1
    return np.clip(first, 0, size - 1), np.clip(last, -1, size - 1), (last >= 0) & (first <= size - 1)


def tile_lists(bounded, spheres, n, origin, rotation, plane, width, height, tile=TILE):
    """(start, index) int32 arrays: the n entries of one shape type (positions in its packed array;
    bounded: held by the spheres (centres, radii), else visited everywhere) that tile t visits are
    index[start[t]:start[t+1]], in increasing order; tiles are numbered row by row. plane: the
    camera's model.camera.ImagePlane at this image size (each axis's tangent and principal point on
    its own: off-centre and unequal focal lengths alike)."""
    tiles_x, tiles_y = -(-width // tile), -(-height // tile)
    if ENABLED and bounded and n:
        bounds = sphere_bounds(*spheres, np.asarray(origin, np.float64), rotation)
        everywhere = np.isnan(bounds).any(axis=1)
        c0, c1, ok_x = _pixel_range(bounds[:, 0], bounds[:, 1], plane.tan_x, plane.cx, width)
        r0, r1, ok_y = _pixel_range(bounds[:, 2], bounds[:, 3], plane.tan_y, plane.cy, height)
        ok = ok_x & ok_y & (c0 <= c1) & (r0 <= r1)
        tx0, tx1 = np.where(ok, c0 // tile, 0), np.where(ok, c1 // tile, -1)
        ty0, ty1 = np.where(ok, r0 // tile, 0), np.where(ok, r1 // tile, -1)
        tx0[everywhere], tx1[everywhere] = 0, tiles_x - 1
        ty0[everywhere], ty1[everywhere] = 0, tiles_y - 1
    else:
        tx0, tx1 = np.zeros(n), np.full(n, tiles_x - 1)
        ty0, ty1 = np.zeros(n), np.full(n, tiles_y - 1)
    nx = np.maximum(tx1 - tx0 + 1, 0).astype(np.int64)
    ny = np.maximum(ty1 - ty0 + 1, 0).astype(np.int64)
    counts = nx * ny
    shape = np.repeat(np.arange(n), counts)
    # position of each pair within its shape's rectangle of tiles
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    nx_r = np.repeat(nx, counts)
    tx = np.repeat(tx0.astype(np.int64), counts) + local % np.maximum(nx_r, 1)
    ty = np.repeat(ty0.astype(np.int64), counts) + local // np.maximum(nx_r, 1)
    tiles = ty * tiles_x + tx
    order = np.argsort(tiles, kind="stable")  # stable: shapes stay in increasing order in a tile
    start = np.zeros(tiles_x * tiles_y + 1, np.int32)
    start[1:] = np.cumsum(np.bincount(tiles, minlength=tiles_x * tiles_y))
    index = shape[order].astype(np.int32)
    if index.size == 0:
        index = np.zeros(1, np.int32)  # no zero-size buffers
    return start, index


def table_rects(directions, valid, tile=TILE) -> np.ndarray:
    """(tiles_y * tiles_x, 4) rectangles (sx_lo, sx_hi, sy_lo, sy_hi) of the image-plane coordinates
    (x / z, y / z in the camera space) of each tile's rays, for a camera whose rays are a table (a
    lens, a panorama: CameraModel.space_directions; directions (height, width, 3), valid (height,
    width)): a ray that meets a sphere has its coordinates in the sphere's sphere_bounds, and in its
    tile's rectangle, so a tile visits the spheres whose bounds meet its rectangle. A tile with a
    ray at or behind the eye's plane (a fisheye's rim, a panorama) is NaN: it visits every shape;
    a tile without a ray in the field is empty (+inf lo): it visits none."""
    height, width = valid.shape
    tiles_x, tiles_y = -(-width // tile), -(-height // tile)
    padded = np.full((tiles_y * tile, tiles_x * tile, 3), np.nan)
    padded[:height, :width] = np.where(valid[..., None], directions, np.nan)
    cells = padded.reshape(tiles_y, tile, tiles_x, tile, 3).transpose(0, 2, 1, 3, 4).reshape(tiles_y * tiles_x, tile * tile, 3)
    z = cells[..., 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        sx, sy = cells[..., 0] / z, cells[..., 1] / z
        behind = np.any(z <= 1e-6 * np.linalg.norm(cells, axis=-1), axis=1)  # NaN compares False: padding is ignored
    with warnings.catch_warnings():  # an all-NaN tile (out of the field) gives NaN min and max
        warnings.simplefilter("ignore", RuntimeWarning)
        rects = np.stack([np.nanmin(sx, axis=1), np.nanmax(sx, axis=1), np.nanmin(sy, axis=1), np.nanmax(sy, axis=1)], axis=1)
    empty = np.isnan(rects).any(axis=1) & ~behind
    rects[empty] = (np.inf, -np.inf, np.inf, -np.inf)
    rects[behind] = np.nan
    return rects


# entries x tiles compared at once (tile_lists_in_rects): bounds the temporary boolean matrix's size
RECT_CHUNK = 1 << 22


def tile_lists_in_rects(bounded, spheres, n, origin, rotation, rects, tiles_x, tiles_y):
    """tile_lists for a camera whose tiles' rays are given as rectangles (table_rects): entry e is in
    tile t's list where its sphere bounds meet t's rectangle (or either is everywhere); the same
    (start, index) arrays, entries in increasing order within a tile."""
    n_tiles = tiles_x * tiles_y
    if not (ENABLED and bounded and n):
        start = np.arange(n_tiles + 1, dtype=np.int64) * n
        index = np.tile(np.arange(n, dtype=np.int32), n_tiles)
        return start.astype(np.int32), (index if index.size else np.zeros(1, np.int32))
    bounds = sphere_bounds(*spheres, np.asarray(origin, np.float64), rotation)
    everywhere = np.isnan(bounds).any(axis=1)
    anywhere_tile = np.isnan(rects).any(axis=1)
    pairs_tile, pairs_entry = [], []
    step = max(1, RECT_CHUNK // max(n_tiles, 1))
    for first in range(0, n, step):
        b = bounds[first:first + step]
        meets = ((b[:, None, 0] <= rects[None, :, 1]) & (rects[None, :, 0] <= b[:, None, 1])
                 & (b[:, None, 2] <= rects[None, :, 3]) & (rects[None, :, 2] <= b[:, None, 3]))
        meets |= everywhere[first:first + step, None] | anywhere_tile[None, :]
        entry, tile = np.nonzero(meets)
        pairs_tile.append(tile)
        pairs_entry.append(entry + first)
    tiles = np.concatenate(pairs_tile)
    entries = np.concatenate(pairs_entry)
    order = np.lexsort((entries, tiles))
    start = np.zeros(n_tiles + 1, np.int32)
    start[1:] = np.cumsum(np.bincount(tiles, minlength=n_tiles))
    index = entries[order].astype(np.int32)
    return start, (index if index.size else np.zeros(1, np.int32))
