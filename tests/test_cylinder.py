"""The cylinder's own cases (the properties every shape has are in tests/test_shapes.py): its
keys, caps or an open tube, rays along and across the axis, from inside, and both sides of its
rims. Distances here are small exact numbers: a few ulps of them is the tolerance, from the error
model's K_ORACLE eps (t + L) / cos with t, L of order 10."""
import numpy as np
import pytest

import pyclray
from pyclray import Cylinder

from shape_cases import assert_bad_table, both_sides, precisions, scene_of

GOOD = 'type = "cylinder"\np0 = [0.0, 0.0, 0.0]\np1 = [0.0, 1.0, 0.0]\nradius = 0.5\n'


@pytest.mark.parametrize("change, key", [
    ("p1 = [0.0, 0.0, 0.0]", "p1"),  # p0 == p1
    ("radius = 0.0", "radius"),
    ("radius = -1.0", "radius"),
    ("caps = 1", "caps"),
    ('caps = "yes"', "caps"),
    ("p0 = [0.0, 0.0]", "p0"),
    ("height = 2.0", "height"),  # unknown key
])
def test_bad_keys_are_one_line_errors(tmp_path, change, key):
    lines = [line for line in GOOD.splitlines() if not line.startswith(change.split(" ")[0] + " ")]
    assert_bad_table(tmp_path, "\n".join(lines + [change]) + "\n", 1, "cylinder", key)


def test_caps_default_to_true_and_false_makes_a_tube(tmp_path):
    path = tmp_path / "ok.toml"
    from shape_cases import CAMERA

    path.write_text(CAMERA + "[[shapes]]\n" + GOOD + "[[shapes]]\n" + GOOD + "caps = false\n")
    capped, tube = pyclray.load_scene(path).shapes
    assert capped.caps is True and capped.solid and tube.caps is False and not tube.solid


@pytest.mark.parametrize("precision", precisions())
def test_along_and_across_the_axis(precision):
    """Down the axis: the cap (normal out of the solid) or, for a tube, nothing; across: the side;
    from inside: the far side with the outward normal; from the axis inside a tube: the side."""
    capped = Cylinder((0, 0, 0), (0, 4, 0), 1.0)
    tube = Cylinder((0, 0, 0), (0, 4, 0), 1.0, caps=False)
    origins = [[0, 10, 0], [0, -3, 0], [5, 2, 0], [0, 2, 0], [0, 1, 0]]
    directions = [[0, -1, 0], [0, 1, 0], [-1, 0, 0], [0, 0, 1], [0, 1, 0]]
    eps = 4 * 2.0**-24 if precision == "fp32" else 1e-14
    r = pyclray.cast(scene_of(capped), origins, directions, precision=precision)
    np.testing.assert_array_equal(r["id"], [0, 0, 0, 0, 0])
    np.testing.assert_allclose(r["depth"], [6, 3, 4, 1, 3], rtol=eps)
    np.testing.assert_allclose(r["normal"], [[0, 1, 0], [0, -1, 0], [1, 0, 0], [0, 0, 1], [0, 1, 0]], atol=eps)
    r = pyclray.cast(scene_of(tube), origins, directions, precision=precision)
    np.testing.assert_array_equal(r["id"], [-1, -1, 0, 0, -1])  # along the axis a tube is open
    np.testing.assert_allclose(r["normal"][2:4], [[1, 0, 0], [0, 0, 1]], atol=eps)  # the inner side: outward


@pytest.mark.parametrize("precision", precisions())
def test_both_sides_of_the_rims(precision):
    """Rays 1e-4 inside and outside the rim (of the cap, seen from above; of the side, seen from
    the side) hit and miss exactly; at the rim itself either, never NaN."""
    cylinder = Cylinder((0.3, -1.0, 0.2), (0.3, 2.0, 0.2), 0.7)
    scene = scene_of(cylinder)
    angle = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    radial = np.stack([np.cos(angle), np.zeros(24), np.sin(angle)], axis=1)
    rim = np.array([0.3, 2.0, 0.2]) + 0.7 * radial
    above = np.array([0.3, 6.0, 0.2]) + 0.2 * radial  # looking down at the top cap
    both_sides(scene, above, rim, radial, 1e-4, precision, 0, -1)
    side = rim + 3.0 * radial + np.array([0, -1.0, 0])  # looking up at the side's top edge
    both_sides(scene, side, rim, np.array([0, 1.0, 0]), 1e-4, precision, 0, -1)


def test_tall_thin_cylinder_meets_the_targets():
    """Height 100, radius 0.5: the fp32 render meets the stability targets (tests/test_stability.py
    runs the full case; here the axis is tilted and the eye near its foot)."""
    from pyclray.reference import error_model

    scene = pyclray.Scene(pyclray.Camera((2.0, 0.5, 3.0), (0.5, 50.0, 0.0), (0, 1, 0), 80.0), pyclray.Image(48, 48),
                          (Cylinder((0, 0, 0), (1.0, 100.0, 0.5), 0.5),))
    result = error_model.compare(pyclray.render(scene), error_model.reference(scene))
    assert result["pixels"] > 300 and error_model.meets_targets(result, "fp32"), result
