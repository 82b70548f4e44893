"""cast's traversal of the wide BVH (kernels/bvh.h's PYCLRAY_TRAVERSE): a leaf's shapes are pre-tested
together in float (kernels/rays.h's cast_leaf_mask: is the ray within the widened bounding radius
R of each shape's anchor, its box's centre?) before each is moved to and tested in float64. The
pre-test may keep a shape it need not, never drop one the ray hits. R is half the box's diagonal (and
a margin): a box's corners lie at R, so rays through a point 1e-4 of a size inside a box's corner,
perpendicular to the diagonal there, pass within a hair of R, the closest a hit comes to it. From
up to 1e5 away, in a scene 1e4 off the world origin (the pre-test's float frame is around the
scene's anchor), the float rounding of that distance is a hundred times the hair: a pre-test that
did not widen R for it drops some of these hits."""
import numpy as np
import pytest

import pyclray

from oracle_checks import assert_agrees_with_oracle


def corner_rays(centres, sizes, count, rng):
    """(origins, directions, distance to the aimed point): each ray through a point 1e-4 of the
    size inside a random corner of a random box, perpendicular to the line from the box's centre to
    that point, from 2 to 1e5 before it."""
    target = rng.integers(0, len(centres), count)
    corner = rng.choice([-1.0, 1.0], (count, 3))
    point = centres[target] + corner * 0.5 * sizes[target] * (1 - 1e-4)
    radial = point - centres[target]
    direction = np.cross(radial, rng.normal(size=(count, 3)))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    along = np.exp(rng.uniform(np.log(2.0), np.log(1e5), count))
    return point - direction * along[:, None], direction, along


@pytest.mark.parametrize("shift", [0.0, 1e4])
def test_the_leaf_pretest_drops_no_hit(shift):
    """Every ray through a point inside a box's corner hits that box or a nearer shape, as the
    oracle says; the oracle agrees on the ids of all (corners are edges it explains), and occluded
    on which rays hit."""
    rng = np.random.default_rng(31)
    count = 3000  # boxes: leaves of several, small enough that a ray enters many leaves' boxes
    centres = rng.uniform(-5.0, 5.0, (count, 3)) + shift
    sizes = rng.uniform(0.04, 0.4, (count, 3))
    scene = pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(4, 4),
                          tuple(pyclray.Box(tuple(c), tuple(s)) for c, s in zip(centres.tolist(), sizes.tolist())))
    origins, directions, along = corner_rays(centres, sizes, 4000, rng)
    result = pyclray.cast(scene, origins, directions)
    assert (result["id"] >= 0).all(), f"{(result['id'] < 0).sum()} rays through a box's inside missed"
    assert (result["depth"] <= along * (1 + 1e-5)).all()
    assert_agrees_with_oracle(scene, origins, directions, result, "fp32", min_judged=0.05)
    assert np.array_equal(pyclray.occluded(scene, origins, directions), result["id"] >= 0)
