"""pyclray.engine.queries.ray_order: the coherent order of large cast batches (numba). The order changes no
result (tests/test_cast.py holds cast's bits to those of small, unordered batches); these tests hold
its parts to their definitions: the codes to a plain Morton interleave of the cells, the counting
sort to numpy's stable argsort, the scan to numpy's checks, and a large batch's bad row to the same
message as a small batch's."""
from __future__ import annotations

import numpy as np
import pytest

import pyclray
from pyclray.engine.queries import cast as cast_module
from pyclray.engine.queries import ray_order as cast_order


def reference_codes(origins, directions, lo, extent, with_origins):
    """Each ray's code from its cells, interleaved bit by bit: at each level (most significant
    first) the dimensions that still have a bit, in order (origin x, y, z, then direction x, y, z)."""
    cells = []
    if with_origins:
        cells += [(np.clip(np.floor((origins[:, a] - lo[a]) * (8.0 / extent)), 0, 7).astype(int), 3) for a in range(3)]
    count = 4 if with_origins else 32
    scale = 0.5 * count / np.abs(directions).sum(axis=1)
    cells += [(np.clip(np.floor(directions[:, a] * scale + 0.5 * count), 0, count - 1).astype(int), 2 if with_origins else 5)
              for a in range(3)]
    codes = np.zeros(len(directions), np.int64)
    for level in range(max(bits for _, bits in cells)):
        for cell, bits in cells:
            if level < bits:
                codes = (codes << 1) | ((cell >> (bits - 1 - level)) & 1)
    return codes


@pytest.mark.parametrize("with_origins", [True, False])
def test_codes_interleave_the_cells(with_origins):
    """The 15-bit codes are the Morton interleave of 8 origin cells and 4 direction cells per axis
    (or 32 direction cells alone): any misplaced bit or clipped cell differs here."""
    rng = np.random.default_rng(5)
    origins = rng.uniform(-3, 5, (20_000, 3))
    directions = rng.normal(size=(20_000, 3))
    lo, extent = origins.min(axis=0), float(np.ptp(origins, axis=0).max())
    tables = cast_order.WITH_ORIGINS if with_origins else cast_order.DIRECTIONS_ONLY
    codes = cast_order._codes(origins, directions, lo, 8.0 / extent, tables, with_origins)
    expected = reference_codes(origins, directions, lo, extent, with_origins)
    assert expected.max() < cast_order.CODES
    np.testing.assert_array_equal(codes, expected)
    if not with_origins:  # the scan's own codes (written as arithmetic, not the tables): the same
        np.testing.assert_array_equal(cast_order.scan_codes(origins, directions)[3], expected)


def test_counting_sort_is_numpys_stable_argsort():
    """Rays of equal codes keep their batch order (a stable sort), so the order is a function of the
    batch alone: the same as numpy's stable argsort, element for element."""
    codes = np.random.default_rng(6).integers(0, 300, 50_000).astype(np.uint16) * np.uint16(97)
    np.testing.assert_array_equal(cast_order._counting_sort(codes), np.argsort(codes, kind="stable"))


def test_scan_finds_what_numpys_checks_find():
    """The scan's box is numpy's min and max; any inf, -inf or NaN coordinate, or a zero direction,
    makes the batch not fine (the host then finds the row with numpy)."""
    rng = np.random.default_rng(7)
    origins, directions = rng.normal(size=(5000, 3)), rng.normal(size=(5000, 3))
    fine, lo, hi, _ = cast_order.scan_codes(origins, directions)
    assert fine
    np.testing.assert_array_equal(lo, origins.min(axis=0))
    np.testing.assert_array_equal(hi, origins.max(axis=0))
    for bad in (np.inf, -np.inf, np.nan):
        for array in (origins, directions):
            spoilt = array.copy()
            spoilt[4321, 2] = bad
            pair = (spoilt, directions) if array is origins else (origins, spoilt)
            assert not cast_order.scan_codes(*pair)[0]
    zero = directions.copy()
    zero[17] = 0.0
    assert not cast_order.scan_codes(origins, zero)[0]


@pytest.mark.parametrize("name, row, value, message", [
    ("origins", 5000, np.nan, "origins: row 5000 is not finite"),
    ("origins", 5100, 1e30, r"origins: row 5100 \(.*\) is too far from the scene's shapes for fp32"),
    ("directions", 4100, np.inf, "directions: row 4100 is not finite"),
    ("directions", 4200, 0.0, "directions: row 4200 has zero length"),
])
def test_a_large_batch_names_its_bad_row(name, row, value, message):
    """A batch large enough for the compiled scan fails as a small one does: one message naming
    the first bad row (an origin too far for the precision too: its reach is checked from the scan's box)."""
    count = cast_module.COHERENT_FROM + 2000
    rng = np.random.default_rng(8)
    rays = {"origins": rng.uniform(-1, 1, (count, 3)), "directions": rng.normal(size=(count, 3))}
    rays[name][row] = value
    scene = pyclray.Scene(pyclray.Camera((0, 0, 5), (0, 0, 0)), pyclray.Image(4, 4), (pyclray.Sphere((0, 0, 0), 1.0),))
    with pytest.raises(pyclray.PyclrayError, match=message):
        pyclray.cast(scene, rays["origins"], rays["directions"])
