"""The sphere, through the batch-ray kernel: seeded property tests (each hypothesis example is a
seed) against the float64 oracle.

Rays here have arbitrary origins, so the kernel computes |F|^2 - r^2 per ray in float32: its
error bound is a few ulps of max(t, |F|) rather than of t (the camera kernel gets that term exact
from the host). Tolerance: 16 float32 ulps of max(t, |origin - centre| + r), over |cos incidence|.
"""
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import pyclray
from pyclray import oracle
from pyclray.accuracy import SILHOUETTE_COS
from pyclray.shapes import Sphere

ULP = 2.0**-24


def scene_of(*shapes):
    return pyclray.Scene(pyclray.Camera((0, 0, 0), (0, 0, -1)), pyclray.Image(1, 1), shapes)


def random_rays(rng, n, centre, spread):
    origins = centre + rng.normal(size=(n, 3)) * spread
    targets = centre + rng.normal(size=(n, 3)) * spread * 0.3
    return origins, targets - origins


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_hits_lie_on_the_sphere_and_match_the_oracle(seed):
    rng = np.random.default_rng(seed)
    centre = rng.uniform(-10, 10, 3)
    radius = float(10 ** rng.uniform(-2, 2))
    sphere = Sphere(tuple(centre), radius)
    origins, directions = random_rays(rng, 500, centre, 3 * radius)
    frame = pyclray.cast(scene_of(sphere), origins, directions)
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    ref = oracle.trace(scene_of(sphere), origins, unit)
    cos = np.abs(np.einsum("ij,ij->i", unit, ref["normal"]))
    judged = (ref["id"] < 0) | (cos > SILHOUETTE_COS)
    assert np.array_equal(frame["id"][judged], ref["id"][judged])
    hit = judged & (ref["id"] == 0)
    assert hit.sum() > 20
    scale = np.maximum(ref["depth"], np.linalg.norm(origins - centre, axis=1) + radius)[hit]
    t = frame["depth"][hit].astype(np.float64)
    assert np.all(np.abs(t - ref["depth"][hit]) * cos[hit] <= 16 * ULP * scale)
    # the hit point lies on the sphere, to the same precision
    points = origins[hit] + t[:, None] * unit[hit]
    assert np.all(np.abs(np.linalg.norm(points - centre, axis=1) - radius) * cos[hit] <= 16 * ULP * scale)
    # normals: unit, outward (along the hit point), within the error model
    normal = frame["normal"][hit].astype(np.float64)
    assert np.allclose(np.linalg.norm(normal, axis=1), 1, atol=4 * ULP)
    assert np.all(np.linalg.norm(normal - ref["normal"][hit], axis=1) * cos[hit] <= 16 * ULP * scale / radius + 1e-6)


def test_only_positive_t_counts():
    sphere = Sphere((0, 0, 0), 1.0)
    frame = pyclray.cast(scene_of(sphere), [[0, 0, 5], [0, 0, 0.5], [0, 0, -5]], [[0, 0, 1], [0, 0, 1], [0, 0, 1]])
    assert np.isinf(frame["depth"][0]) and frame["id"][0] == -1  # sphere behind the ray
    assert abs(frame["depth"][1] - 0.5) < 1e-6 and frame["normal"][1][2] > 0.999  # from inside: far side
    assert abs(frame["depth"][2] - 4.0) < 4e-6 and frame["normal"][2][2] < -0.999


def test_a_ray_from_the_surface_sees_the_far_side_not_itself():
    sphere = Sphere((0, 0, 0), 1.0)
    frame = pyclray.cast(scene_of(sphere), [[0, 0, 1], [0, 0, 1]], [[0, 0, -1], [0, 0, 1]])
    assert abs(frame["depth"][0] - 2.0) < 1e-6
    assert np.isinf(frame["depth"][1])


def test_nearest_of_many_is_the_nearest():
    rng = np.random.default_rng(7)
    spheres = tuple(Sphere(tuple(rng.uniform(-5, 5, 3)), float(rng.uniform(0.2, 1.5))) for _ in range(40))
    origins = rng.uniform(-8, 8, (2000, 3))
    directions = rng.normal(size=(2000, 3))
    scene = scene_of(*spheres)
    frame = pyclray.cast(scene, origins, directions)
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    all_t = np.stack([s.oracle_distance(origins, unit) for s in spheres])
    order = np.sort(all_t, axis=0)
    with np.errstate(invalid="ignore"):  # inf - inf where a ray misses everything
        clear = (order[1] - order[0] > 1e-4 * order[0]) | np.isinf(order[0])  # not a near-tie
    assert np.array_equal(frame["id"][clear], np.where(np.isinf(order[0]), -1, np.argmin(all_t, axis=0))[clear])
