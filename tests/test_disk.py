"""The disk's own cases (the properties every shape has are in tests/test_shapes.py): its keys,
its normal (never flipped), parallel rays, a radius of 1e6 as a ground, both sides of its rim."""
import numpy as np
import pytest

import pyclray
from pyclray import Disk

from shape_cases import assert_bad_table, both_sides, precisions, scene_of

GOOD = 'type = "disk"\ncenter = [0.0, 0.0, 0.0]\nnormal = [0.0, 1.0, 0.0]\nradius = 1.0\n'


@pytest.mark.parametrize("change, key", [
    ("normal = [0.0, 0.0, 0.0]", "normal"),
    ("radius = 0.0", "radius"),
    ("radius = -1.0", "radius"),
    ("center = [0.0, 0.0]", "center"),
    ("caps = true", "caps"),  # unknown key
])
def test_bad_keys_are_one_line_errors(tmp_path, change, key):
    lines = [line for line in GOOD.splitlines() if not line.startswith(change.split(" ")[0] + " ")]
    assert_bad_table(tmp_path, "\n".join(lines + [change]) + "\n", 0, "disk", key)


@pytest.mark.parametrize("precision", precisions())
def test_normal_never_flipped_and_parallel_rays_miss(precision):
    disk = Disk((0, 1, 0), (0, 3, 0), 2.0)
    r = pyclray.cast(scene_of(disk), [[0, 5, 0], [0, -1, 0], [0, 1, -5], [0, 1, 0]],
                     [[0, -1, 0], [0.5, 1, 0], [0, 0, 1], [0, -1, 0]], precision=precision)
    np.testing.assert_array_equal(r["id"], [0, 0, -1, -1])  # in its plane, or from it: no hit
    np.testing.assert_array_equal(r["normal"][:2], [[0, 1, 0], [0, 1, 0]])  # exact: packed as is
    assert r["depth"][0] == 4


@pytest.mark.parametrize("precision", precisions())
def test_both_sides_of_the_rim(precision):
    disk = Disk((0.4, 0.2, -0.3), (0.3, 1.0, 0.2), 1.3)
    n = disk.unit_normal()
    t1, t2, _ = pyclray.model.shapes.base.space_columns(n)
    angle = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    radial = np.cos(angle)[:, None] * t1 + np.sin(angle)[:, None] * t2
    rim = np.array(disk.center) + 1.3 * radial
    both_sides(scene_of(disk), np.array(disk.center) + 4 * n + 0.5 * radial, rim, radial, 1e-4, precision, 0, -1)


def test_huge_disk_ground_keeps_the_eye_height():
    """A disk of radius 1e6 as the ground, the eye 3 above it: depths to the ground within a
    few ulps straight down and at 30 degrees (the plane's offset comes exact from the host)."""
    disk = Disk((1e5, 0.0, -2e5), (0, 1, 0), 1e6)
    scene = pyclray.Scene(pyclray.Camera((0, 3, 0), (0, 0, -1)), pyclray.Image(1, 1), (disk,))
    down = [[0, -1, 0], [0, -np.cos(np.pi / 6), np.sin(np.pi / 6)]]
    r = pyclray.cast(scene, (0, 3, 0), down)
    expected = np.array([3.0, 3.0 / np.cos(np.pi / 6)])
    assert np.all(np.abs(r["depth"] - expected) <= 2 * np.spacing(expected.astype(np.float32)))
