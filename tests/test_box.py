"""The box's own cases (the properties every shape has are in tests/test_shapes.py): its keys,
exact face normals, rays parallel to a face (the slab test's infinities), rays from inside and
from a face, both sides of its edges and corners."""
import numpy as np
import pytest

import pyclray
from pyclray import Box

from shape_cases import assert_bad_table, both_sides, precisions, scene_of

GOOD = 'type = "box"\ncenter = [0.0, 0.5, 0.0]\nsize = [1.0, 1.0, 1.0]\n'


@pytest.mark.parametrize("change, key", [
    ("size = [1.0, 0.0, 1.0]", "size"),
    ("size = [1.0, -1.0, 1.0]", "size"),
    ("size = [1.0, 1.0]", "size"),
    ("size = 1.0", "size"),
    ('axis = [0.0, 0.0, 0.0]\nangle = 30.0', "axis"),
    ('angle = 30.0', "angle"),  # no axis to rotate about
    ('axis = [0.0, 1.0, 0.0]\nangle = "thirty"', "angle"),
    ("radius = 1.0", "radius"),  # unknown key
])
def test_bad_keys_are_one_line_errors(tmp_path, change, key):
    lines = [line for line in GOOD.splitlines() if not line.startswith(change.split(" ")[0] + " ")]
    assert_bad_table(tmp_path, "\n".join(lines + [change]) + "\n", 1, "box", key)


def test_rotation_is_right_handed():
    """30 degrees about +y turns +x toward -z (counter-clockwise looking down -y)."""
    axes = Box((0, 0, 0), (1, 1, 1), (0, 2, 0), 30.0).axes()
    np.testing.assert_allclose(axes[:, 0], [np.cos(np.pi / 6), 0, -np.sin(np.pi / 6)], atol=1e-15)
    assert np.array_equal(Box((0, 0, 0), (1, 1, 1)).axes(), np.eye(3))


@pytest.mark.parametrize("precision", precisions())
def test_faces_parallel_rays_and_inside(precision):
    """An axis-aligned box: exact unit normals; a ray parallel to a face inside its slab hits the
    far face, outside it misses (the slab test's +-inf); from inside, the far side with the
    outward normal; from a face looking in, the opposite face."""
    box = Box((0, 0, 0), (2, 4, 6))  # half sizes 1, 2, 3
    origins = [[5, 0, 0], [5, 1.5, 0], [5, 2.5, 0], [0, 0, 0], [-1, 0, 0], [0, 0, 10]]
    directions = [[-1, 0, 0], [-1, 0, 0], [-1, 0, 0], [0, 1, 0], [1, 0, 0], [0, 0, -1]]
    r = pyclray.cast(scene_of(box), origins, directions, precision=precision)
    np.testing.assert_array_equal(r["id"], [0, 0, -1, 0, 0, 0])
    # within a few ulps: cast's frame is the rays' mean origin, which these small numbers round into
    np.testing.assert_allclose(r["depth"][[0, 1, 3, 4, 5]], [4, 4, 2, 2, 7], rtol=4 * 2.0**-24 if precision == "fp32" else 1e-14)
    np.testing.assert_array_equal(r["normal"][[0, 1, 3, 4, 5]], [[1, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [0, 0, 1]])


@pytest.mark.parametrize("precision", precisions())
def test_both_sides_of_edges_and_corners(precision):
    """Rays perpendicular to a face, at points 1e-4 inside and outside each of its edges (across
    the edge, along the neighbouring face's normal) and corners, hit and miss exactly."""
    box = Box((0.2, 0.5, -0.1), (1.0, 0.6, 1.4), (1, 2, 0.5), 35.0)
    R, h, c = box.axes(), box.half(), np.array(box.center)
    origins, points, outward = [], [], []
    for i in range(3):  # looking at face (i, si) along -si e_i
        for si in (-1, 1):
            face = c + si * h[i] * R[:, i]
            for j in range(3):
                if j == i:
                    continue
                k = 3 - i - j
                for sj in (-1, 1):
                    for along in (-0.5, 0.0, 0.5):
                        point = face + sj * h[j] * R[:, j] + along * h[k] * R[:, k]
                        points.append(point)
                        outward.append(sj * R[:, j])
                        origins.append(point + 3 * si * R[:, i])
            for sj in (-1, 1):  # the face's corners, across their diagonal
                for sk in (-1, 1):
                    j, k = [a for a in range(3) if a != i]
                    point = face + sj * h[j] * R[:, j] + sk * h[k] * R[:, k]
                    points.append(point)
                    outward.append((sj * R[:, j] + sk * R[:, k]) / np.sqrt(2))
                    origins.append(point + 3 * si * R[:, i])
    origins, points, outward = np.array(origins), np.array(points), np.array(outward)
    both_sides(scene_of(box), origins, points, outward, 1e-4, precision, 0, -1)
