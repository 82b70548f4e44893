"""The rectangle's own cases (the properties every shape has are in tests/test_shapes.py): its
keys (sides non-zero, not parallel, orthogonal within 1e-6), its normal normalize(u x v), both
sides of its border."""
import numpy as np
import pytest

import pyclray
from pyclray import Rectangle

from shape_cases import assert_bad_table, both_sides, precisions, scene_of

GOOD = 'type = "rectangle"\ncenter = [0.0, 0.0, 0.0]\nu = [1.0, 0.0, 0.0]\nv = [0.0, 0.0, 2.0]\n'


@pytest.mark.parametrize("change, key", [
    ("u = [0.0, 0.0, 0.0]", "u"),
    ("v = [0.0, 0.0, 0.0]", "v"),
    ("v = [3.0, 0.0, 0.0]", "v"),  # parallel to u
    ("v = [0.01, 0.0, 2.0]", "v"),  # not orthogonal: |u.v| = 5e-3 |u| |v|
    ("v = [0.0, 2.0]", "v"),
    ("normal = [0.0, 1.0, 0.0]", "normal"),  # unknown key
])
def test_bad_keys_are_one_line_errors(tmp_path, change, key):
    lines = [line for line in GOOD.splitlines() if not line.startswith(change.split(" ")[0] + " ")]
    assert_bad_table(tmp_path, "\n".join(lines + [change]) + "\n", 2, "rectangle", key)


def test_orthogonal_within_a_millionth_is_accepted():
    Rectangle((0, 0, 0), (1, 0, 0), (1e-7, 0, 2))
    with pytest.raises(pyclray.SceneError, match="orthogonal"):
        Rectangle((0, 0, 0), (1, 0, 0), (3e-6, 0, 2))


@pytest.mark.parametrize("precision", precisions())
def test_normal_is_u_cross_v_from_either_side(precision):
    panel = Rectangle((0, 1, 0), (2, 0, 0), (0, 1, 0))  # u x v = +z
    r = pyclray.cast(scene_of(panel), [[0.5, 1.2, 3], [0.5, 1.2, -3], [2.5, 1, 3]], [[0, 0, -1], [0, 0, 1], [0, 0, -1]],
                     precision=precision)
    np.testing.assert_array_equal(r["id"], [0, 0, -1])
    np.testing.assert_array_equal(r["normal"][:2], [[0, 0, 1], [0, 0, 1]])
    np.testing.assert_array_equal(r["depth"][:2], [3, 3])


@pytest.mark.parametrize("precision", precisions())
def test_both_sides_of_the_border_and_corners(precision):
    u, v = np.array([1.5, 0.0, 0.5]), np.array([-0.1, 0.8, 0.3])
    v = v - (v @ u) / (u @ u) * u
    panel = Rectangle((0.2, 0.1, -0.4), tuple(u), tuple(v))
    n = panel.unit_normal()
    c = np.array(panel.center)
    a = np.linspace(-0.95, 0.95, 9)
    points, outward = [], []
    for side, across in ((u, v), (-u, v), (v, u), (-v, u)):
        points += [c + side + k * across for k in a]
        outward += [side / np.linalg.norm(side)] * len(a)
    for su in (-1, 1):  # corners, across their diagonal
        for sv in (-1, 1):
            points.append(c + su * u + sv * v)
            d = su * u / np.linalg.norm(u) + sv * v / np.linalg.norm(v)
            outward.append(d / np.linalg.norm(d))
    points, outward = np.array(points), np.array(outward)
    both_sides(scene_of(panel), points + 3 * n, points, outward, 1e-4, precision, 0, -1)
