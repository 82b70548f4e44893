"""cast and occluded count hits with tmin < t < tmax, open at both ends (scene-format.md, "Queries"):
a hit exactly at tmax or at tmin is not one. The cases put a surface at a distance every precision
holds exactly (planes 2 and 4 along axes from the origin: a plane's test from the ray's origin makes
that t without rounding, where a bounded shape's moved origin adds the rounding of its move), so the
bound itself decides."""
import numpy as np
import pytest

import pyclray

from test_lenses import needs_fp64


def scene_at_two():
    """A plane 2 below the origin, another 4 ahead of it (along -z), a ball far off to the side (a
    bounded shape: the BVH's path runs too)."""
    camera = pyclray.Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0))
    shapes = (pyclray.Plane((0.0, 1.0, 0.0), 2.0), pyclray.Plane((0.0, 0.0, 1.0), 4.0),
              pyclray.Sphere((30.0, 0.0, 0.0), 1.0))
    return pyclray.Scene(camera, pyclray.Image(8, 8), shapes)


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_a_hit_exactly_at_tmax_or_tmin_is_a_miss(precision):
    if precision == "fp64":
        needs_fp64()
    scene = scene_at_two()
    origins = np.zeros((2, 3))
    directions = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # a plane at t = 2, the other at t = 4
    with pyclray.prepare(scene, precision=precision) as tracer:
        free = tracer.cast(origins, directions, aovs=("depth", "id"))
        assert free["depth"].tolist() == [2.0, 4.0] and free["id"].tolist() == [0, 1]  # exactly there
        at = np.array([2.0, 4.0])
        above = np.nextafter(at, np.inf)
        below = np.nextafter(at, 0.0)
        exact = tracer.cast(origins, directions, aovs=("depth", "id", "normal"), tmax=at)
        assert np.all(exact["id"] == -1) and np.all(np.isinf(exact["depth"])) and not exact["normal"].any()
        assert tracer.cast(origins, directions, aovs=("id",), tmax=above)["id"].tolist() == [0, 1]
        assert not tracer.occluded(origins, directions, tmax=at).any()
        assert tracer.occluded(origins, directions, tmax=above).all()
        # the other end: a hit exactly at tmin is not one either
        assert tracer.cast(origins, directions, aovs=("id",), tmin=at)["id"].tolist() == [-1, -1]
        near = tracer.cast(origins, directions, aovs=("depth", "id"), tmin=below)
        assert near["depth"].tolist() == [2.0, 4.0]
        assert tracer.occluded(origins, directions, tmin=at, tmax=np.array([100.0, 5.0])).tolist() == [False, False]
        assert tracer.occluded(origins, directions, tmin=below, tmax=above).all()
