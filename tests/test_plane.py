"""The plane, through the batch-ray kernel: seeded property tests against the float64 oracle.

With an arbitrary origin the kernel forms h + n.origin per ray in float32, whose error is a few
ulps of |n.origin|, so the tolerance is 8 float32 ulps of max(t, |origin|) over |cos incidence|.
"""
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import pyclray
from pyclray import oracle
from pyclray.shapes import Plane

ULP = 2.0**-24


def scene_of(*shapes):
    return pyclray.Scene(pyclray.Camera((0, 0, 0), (0, 0, -1)), pyclray.Image(1, 1), shapes)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_hits_lie_on_the_plane_and_match_the_oracle(seed):
    rng = np.random.default_rng(seed)
    plane = Plane(tuple(rng.normal(size=3) * 10 ** rng.uniform(-2, 2)), float(rng.normal() * 5))
    origins = rng.normal(size=(400, 3)) * 10
    directions = rng.normal(size=(400, 3))
    frame = pyclray.cast(scene_of(plane), origins, directions)
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    ref = oracle.trace(scene_of(plane), origins, unit)
    n, h = plane.unit()
    cos = np.abs(unit @ n)
    judged = cos > 0.02
    assert np.array_equal(frame["id"][judged], ref["id"][judged])
    hit = judged & (ref["id"] == 0)
    scale = np.maximum(ref["depth"], np.linalg.norm(origins, axis=1))[hit]
    t = frame["depth"][hit].astype(np.float64)
    assert np.all(np.abs(t - ref["depth"][hit]) * cos[hit] <= 8 * ULP * scale)
    points = origins[hit] + t[:, None] * unit[hit]
    assert np.all(np.abs(points @ n + h) <= 8 * ULP * (scale + np.abs(h)))
    # the normal is the plane's own, normalized, on every hit: never flipped toward the ray
    assert np.allclose(frame["normal"][hit], n, atol=2 * ULP)
    assert np.all(frame["normal"][ref["id"] < 0] == 0)


def test_parallel_rays_and_rays_from_the_plane_miss():
    plane = Plane((0, 1, 0), 0.0)
    frame = pyclray.cast(scene_of(plane), [[0, 1, 0], [0, 0, 0], [0, 0, 0], [0, -1, 0]],
                         [[1, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 0]])
    assert np.isinf(frame["depth"][:3]).all() and (frame["id"][:3] == -1).all()
    assert frame["depth"][3] == 1.0 and np.array_equal(frame["normal"][3], [0, 1, 0])  # from below
