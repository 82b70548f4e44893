"""closest_points and distance: agreement with the float64 oracle on every shape type, near the
origin and 1e6 away from it, in fp32 and fp64; the nearest point's properties; ties, planes,
leading shapes, the lane width, bad arrays.

Error model (pyclray.reference.error_model.closest_tolerances): the kernel and the oracle both
compute in float64 from the point as given and the shapes' float64 geometry, so distances agree
within a few eps64 of the coordinates involved; the position is also rounded to the precision.
Where two surface points are (nearly) equally near, either is right: the tests then hold the
kernel's answer to what makes it right (a point of the named shape's surface, at the distance
reported, the nearest within the tolerance) rather than to the oracle's choice.
"""
import numpy as np
import pytest

import pyclray
from pyclray.model.shapes import REGISTRY
from pyclray.reference import error_model, oracle

CAMERA = pyclray.Camera((0, 0, 10), (0, 0, 0))


def scene_of(shapes) -> pyclray.Scene:
    return pyclray.Scene(CAMERA, pyclray.Image(8, 8), tuple(shapes))


def random_case(type_name: str, seed: int, shift: float):
    """A scene of 1 to 3 random shapes of the type near shift, and points around them: uniform in
    their neighbourhood, and jittered about their surfaces (through the oracle's nearest points)."""
    rng = np.random.default_rng(seed)
    cls = REGISTRY[type_name]
    shapes = [cls.random(rng, shift) for _ in range(int(rng.integers(1, 4)))]
    scene = scene_of(shapes)
    centre = np.full(3, shift, np.float64)
    uniform = centre + rng.uniform(-5, 5, (300, 3))
    on = oracle.closest_points(scene, uniform)["position"]
    near = on + rng.normal(size=on.shape) * 10.0 ** rng.uniform(-9, -1, (len(on), 1))
    return scene, np.concatenate([uniform, near, on])


def assert_closest_right(scene, points, result, precision):
    """The kernel's closest points against the oracle's, within the error model (see the module's
    docstring for what is held where the nearest point is ambiguous)."""
    truth = oracle.closest_points(scene, points)
    tol = error_model.closest_tolerances(points, truth, precision)
    real = np.float64 if precision == "fp64" else np.float32
    assert result["position"].dtype == real and result["normal"].dtype == real and result["barycentric"].dtype == real
    assert result["distance"].dtype == np.float64 and result["id"].dtype == np.int32
    d = result["distance"]
    bad = ~(np.abs(d - truth["distance"]) <= tol["distance"])
    assert not bad.any(), f"distance off at {np.flatnonzero(bad)[:5]}: {d[bad][:5]} vs {truth['distance'][bad][:5]}"
    position = result["position"].astype(np.float64)
    # the position reported is at the distance reported ...
    gap = np.abs(np.linalg.norm(points - position, axis=-1) - d)
    assert (gap <= tol["position"]).all(), np.max(gap - tol["position"])
    for index, item in enumerate(scene.shapes):
        mine = result["id"] == index
        if not mine.any():
            continue
        # ... on the surface of the shape named, which is a nearest shape of the point
        assert (item.surface_distance(position[mine]) <= tol["position"][mine]).all()
        assert (np.abs(item.surface_distance(points[mine]) - truth["distance"][mine]) <= tol["distance"][mine]).all()
        # the normal: unit, and the oracle's at that point wherever the surface has one normal there
        normal = result["normal"][mine].astype(np.float64)
        assert np.allclose(np.linalg.norm(normal, axis=-1), 1.0, atol=1e-6)
        own = item.oracle_closest(points[mine])
        same = np.linalg.norm(own[0] - position[mine], axis=-1) <= tol["position"][mine]
        clear = same & (item.edge_distance(own[0]) > 1e-6 * (1 + np.linalg.norm(points[mine], axis=-1)))
        if type(item).barycentric:  # a mesh: its triangle's normal and the barycentrics of the position
            primitive = result["primitive"][mine]
            assert np.allclose(normal, item.face_normals()[primitive], atol=1e-6)
            a, b, c = (x[primitive] for x in item.corners())
            uv = result["barycentric"][mine].astype(np.float64)
            rebuilt = a + uv[:, :1] * (b - a) + uv[:, 1:] * (c - a)
            scale = 1e-5 if precision == "fp32" else 1e-9
            assert np.allclose(rebuilt, position[mine], atol=scale * (1 + np.abs(points[mine]).max()))
        else:
            assert np.allclose(normal[clear], own[1][clear], atol=1e-6)
            assert (result["barycentric"][mine] == 0).all()


@pytest.mark.parametrize("type_name", sorted(REGISTRY))
@pytest.mark.parametrize("shift", [0.0, 1e6])
def test_every_shape_agrees_with_oracle(type_name, shift):
    precision = "fp32" if shift == 0 else "fp64"
    for seed in range(2):
        scene, points = random_case(type_name, seed, shift)
        result = pyclray.closest_points(scene, points, precision=precision)
        assert_closest_right(scene, points, result, precision)
        assert np.array_equal(pyclray.distance(scene, points, precision=precision), result["distance"])


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_mixed_scene_far_from_origin(precision):
    """Every type in one scene, 1e6 from the origin: the BVH's float boxes around the scene's
    anchor never prune the nearest shape (its lower bounds cover the points' rounding)."""
    rng = np.random.default_rng(7)
    shift = 1e6
    shapes = [REGISTRY[t].random(rng, shift) for t in sorted(REGISTRY) for _ in range(2)]
    scene = scene_of(shapes)
    points = shift + rng.uniform(-6, 6, (3000, 3))
    result = pyclray.closest_points(scene, points, precision=precision)
    assert_closest_right(scene, points, result, precision)


def test_large_batch_in_coherent_order_is_the_same():
    """Above COHERENT_FROM the points run in a Morton order; each is computed on its own, so every
    result is the same bits as in a small batch."""
    from pyclray.engine.queries.closest import COHERENT_FROM

    rng = np.random.default_rng(3)
    scene = scene_of([pyclray.Mesh.random(rng), pyclray.Sphere((1, 2, 0), 0.5)])
    points = rng.uniform(-4, 4, (COHERENT_FROM + 10, 3))
    whole = pyclray.closest_points(scene, points)
    part = pyclray.closest_points(scene, points[:100])
    for key in whole:
        assert np.array_equal(whole[key][:100], part[key]), key


def test_exact_cases_and_ties():
    sphere = pyclray.Sphere((0, 0, 0), 1.0)
    box = pyclray.Box(center=(3.0, 0.0, 0.0), size=(2.0, 2.0, 2.0))
    plane = pyclray.Plane((0, 0, 1), 5.0)  # z = -5; behind: z < -5
    scene = scene_of([sphere, box, plane])
    points = np.array([[0, 0, 3.0], [1.5, 0, 0], [3, 0, 0.5], [0, 0, -7.0], [0, 0, 0]])
    r = pyclray.closest_points(scene, points, precision="fp64")
    # the point midway between the sphere (x = 1) and the box (x = 2): an exact tie, the lower id
    assert r["distance"].tolist() == [2.0, 0.5, 0.5, 2.0, 1.0]
    assert r["id"].tolist() == [0, 0, 1, 2, 0]
    assert np.array_equal(r["position"][2], [3.0, 0.0, 1.0]) and np.array_equal(r["normal"][2], [0, 0, 1])
    assert np.array_equal(r["position"][3], [0.0, 0.0, -5.0]) and np.array_equal(r["normal"][3], [0, 0, 1])
    # the centre of the sphere: every surface point is as near; one of them, at distance 1
    assert np.linalg.norm(r["position"][4]) == 1.0


def test_plane_is_unbounded():
    scene = scene_of([pyclray.Plane((0, 1, 0), 0.0)])
    points = np.array([[1e5, 3.0, -2e5], [0.0, -0.25, 0.0]])
    r = pyclray.closest_points(scene, points, precision="fp64")
    assert r["distance"].tolist() == [3.0, 0.25]
    assert np.array_equal(r["position"], [[1e5, 0.0, -2e5], [0.0, 0.0, 0.0]])


def test_mesh_triangle_regions():
    """One triangle: the face, each edge and each vertex region, with their barycentrics."""
    mesh = pyclray.Mesh(vertices=np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), faces=np.array([[0, 1, 2]]))
    scene = scene_of([mesh])
    points = np.array([[0.25, 0.25, 2.0], [-1, -1, 0.0], [2, -1, 0.0], [-1, 2, 0.0], [0.5, -1, 0.0],
                       [-1, 0.5, 0.0], [1, 1, 0.0]])
    r = pyclray.closest_points(scene, points, precision="fp64")
    expected = np.array([[0.25, 0.25, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0], [0.5, 0, 0], [0, 0.5, 0], [0.5, 0.5, 0]])
    assert np.allclose(r["position"], expected, atol=1e-15)
    assert np.allclose(r["barycentric"], expected[:, :2], atol=1e-15)
    assert r["distance"][0] == 2.0
    assert np.array_equal(r["normal"], np.tile([0.0, 0.0, 1.0], (7, 1)))
    assert (r["primitive"] == 0).all()


def test_degenerate_triangle():
    """A zero-area triangle is its edges: the nearest point of the segment."""
    mesh = pyclray.Mesh(vertices=np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 0, 5], [1, 0, 5], [0, 1, 5]]),
                        faces=np.array([[0, 1, 2], [3, 4, 5]]))
    r = pyclray.closest_points(scene_of([mesh]), np.array([[1.5, 1.0, 0.0]]), precision="fp64")
    assert r["distance"][0] == 1.0 and r["primitive"][0] == 0
    assert np.allclose(r["position"][0], [1.5, 0, 0])


def test_leading_shapes_and_empty():
    scene = scene_of([pyclray.Sphere((0, 0, 0), 1.0)])
    points = np.random.default_rng(0).uniform(-2, 2, (4, 5, 3))
    r = pyclray.closest_points(scene, points)
    assert r["position"].shape == (4, 5, 3) and r["distance"].shape == (4, 5) and r["barycentric"].shape == (4, 5, 2)
    assert np.array_equal(r["distance"].reshape(-1), pyclray.distance(scene, points.reshape(-1, 3)))
    assert pyclray.distance(scene, points[0, 0]).shape == ()
    empty = pyclray.closest_points(scene, np.zeros((0, 3)))
    assert empty["distance"].shape == (0,) and empty["position"].shape == (0, 3)
    assert pyclray.distance(scene, []).shape == (0,)
    # float32 points are taken as given (widened exactly)
    p32 = points.astype(np.float32)
    assert np.array_equal(pyclray.distance(scene, p32), pyclray.distance(scene, p32.astype(np.float64)))


def test_no_shapes():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = scene_of([])
        r = pyclray.closest_points(scene, np.zeros((2, 3)))
    assert np.isinf(r["distance"]).all() and (r["id"] == -1).all() and np.isnan(r["position"]).all()


def test_handle_methods_match_functions():
    rng = np.random.default_rng(5)
    scene = scene_of([pyclray.Mesh.random(rng), pyclray.Cylinder((0, 0, 0), (0, 0, 1), 0.5)])
    points = rng.uniform(-3, 3, (500, 3))
    with pyclray.prepare(scene) as tracer:
        r = tracer.closest_points(points)
        assert np.array_equal(tracer.distance(points), r["distance"])
        assert tracer.nbytes > 0
    with pytest.raises(pyclray.RequestError, match="closed"):
        tracer.distance(points)
    f = pyclray.closest_points(scene, points)
    for key in r:
        assert np.array_equal(r[key], f[key])


def test_instanced_meshes():
    """Meshes sharing their arrays (packed as instances for render and cast) are each a mesh here."""
    rng = np.random.default_rng(2)
    base = pyclray.Mesh.random(rng)
    moved = pyclray.Mesh(base.vertices, base.faces, translate=(4.0, 0.0, 0.0))
    scene = scene_of([base, moved])
    points = rng.uniform(-3, 7, (400, 3))
    assert_closest_right(scene, points, pyclray.closest_points(scene, points, precision="fp64"), "fp64")


def test_lane_width_changes_no_bit(monkeypatch):
    rng = np.random.default_rng(11)
    scene = scene_of([pyclray.Mesh.random(rng), pyclray.Box(center=(2, 0, 0), size=(1, 1, 1))])
    points = rng.uniform(-3, 3, (300, 3))
    before = pyclray.closest_points(scene, points)
    monkeypatch.setenv("PYCLRAY_LANES", "1")
    pyclray.clear_cache()
    after = pyclray.closest_points(scene, points)
    for key in before:
        assert np.array_equal(before[key], after[key], equal_nan=True), key


@pytest.mark.parametrize("points, message", [
    (np.zeros((4, 2)), r"points: expected an array of shape \(\.\.\., 3\), got shape \(4, 2\)"),
    (np.array([[0, 0, 0], [1, np.nan, 0]]), r"points: row 1 is not finite"),
    (np.array([[[0, 0, 0], [0, 0, 0]], [[0, 0, 0], [np.inf, 0, 0]]]), r"points: row \(1, 1\) is not finite"),
    ("abc", r"points: expected an array"),
    (5.0, r"points: expected an array of shape \(\.\.\., 3\)"),
])
def test_bad_points(points, message):
    scene = scene_of([pyclray.Sphere((0, 0, 0), 1.0)])
    for query in (pyclray.closest_points, pyclray.distance, pyclray.signed_distance, pyclray.occupancy):
        with pytest.raises(ValueError, match=message):
            query(scene, points)


def test_check_compares_closest_points_with_the_oracle():
    """pyclray check's closest-point part (reference/validation/closest.py): within the tolerance on a
    scene of every type, and a fault found where the distances are made wrong."""
    from pyclray.reference.validation import closest as check

    rng = np.random.default_rng(9)
    scene = scene_of([REGISTRY[t].random(rng) for t in sorted(REGISTRY)])
    result = check.closest_check(scene, 600, seed=1)
    assert result.points == 600 and not result.failures
    text = check.format_closest_check(result)
    assert "Mitsuba has no closest-point query" in text and "float64 oracle" in text
    import pyclray.engine.api as api  # (closest_check imports the engine's function when it runs)

    original = api.closest_points

    def off(*args, **kwargs):
        out = original(*args, **kwargs)
        out["distance"] = out["distance"] * (1 + 1e-6)
        return out

    api.closest_points = off
    try:
        assert check.closest_check(scene, 200, seed=1).failures
    finally:
        api.closest_points = original
