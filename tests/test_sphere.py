"""The sphere's own cases through the batch-ray kernel (the properties every shape has are in
tests/test_shapes.py): only t > 0 counts, a ray from the surface, the nearest of many. Distances
here are small exact numbers, so a few float32 ulps of them is the tolerance."""
import numpy as np

import pyclray
from pyclray.reference import error_model
from pyclray.reference import oracle
from pyclray.model.shapes import Sphere



def scene_of(*shapes):
    return pyclray.Scene(pyclray.Camera((0, 0, 0), (0, 0, -1)), pyclray.Image(1, 1), shapes)


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
    truth = oracle.trace(scene, origins, unit, aovs=("depth", "normal", "id", "second"))
    cos = oracle.incidence_cosine(scene, unit, truth["id"], truth["normal"])
    truth["cos"] = cos
    near_tie = error_model.near_ties(truth, lambda t, ids, c: error_model.pyclray_tolerances(
        scene, {"depth": t, "id": ids}, c, origins, "fp32", directions=unit)[0])
    clear = ~near_tie & ~error_model.silhouettes(truth["id"], cos)
    assert clear.mean() > 0.9
    assert np.array_equal(frame["id"][clear], np.where(np.isinf(all_t.min(axis=0)), -1, np.argmin(all_t, axis=0))[clear])
