"""pyclray.cast, the batch ray API: agreement with the float64 oracle, independence from the batch,
far origins, tmax and occluded, input checks, edge cases.

Error model of cast (pyclray.accuracy: pyclray_tolerances and cast_spaces). Each ray is traced
on its own (kernels/cast.cl, kernels/rays.h): a bounded shape of anchor A (its box's centre) and bounding radius
R is tested from the point O' = O + s0 D of the ray, s0 = max(0, (A - O).D - R), taken in float64
with the shape's coordinates relative to A; a plane from the ray's world origin in float64. What is
rounded to the kernel's precision is then of size L = |O' - A| + R for a bounded shape, 0 for a
plane (its signed distance is rounded once, a relative error). So a hit is the exact hit of a ray
moved by about eps (t - s0 + L): along the ray a depth error over the cosine of incidence, and
seen from a centre of curvature of radius r an angle of that over r; the oracle adds its own
eps64 (t + W), W the size of its world coordinates. K_ORACLE = 4.
Silhouettes, near ties and edges may disagree on the id; any other id disagreement fails.
"""
import numpy as np
import pytest

import pyclray
from pyclray.reference import error_model
from pyclray.reference import oracle
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.reference.validation.images import next_to_id_change

from conftest import SCENES
from oracle_checks import assert_agrees_with_oracle

EPSILON = error_model.EPSILON


def random_scene(seed: int):
    """Random spheres and a tilted plane (in random order), moved off the world origin for odd
    seeds; random origins (some inside spheres) and directions of random lengths."""
    rng = np.random.default_rng(seed)
    shift = rng.normal(size=3) * (50.0 if seed % 2 else 0.0)
    normal = rng.normal(size=3)
    shapes = [pyclray.Plane(tuple(normal), float(-normal @ shift - rng.uniform(-1, 1)))]
    for _ in range(rng.integers(1, 7)):
        shapes.append(pyclray.Sphere(tuple(rng.uniform(-4, 4, 3) + shift), float(rng.uniform(0.1, 3.0))))
    order = rng.permutation(len(shapes))
    scene = pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(8, 8), tuple(shapes[i] for i in order))
    origins = rng.uniform(-6, 6, (2000, 3)) + shift
    directions = rng.normal(size=(2000, 3)) * rng.uniform(0.01, 100.0, (2000, 1))
    return scene, origins, directions


def need_precision(precision):
    if precision == "fp64" and not has_fp64(context_for(None).device):
        pytest.skip("device lacks cl_khr_fp64")


@pytest.mark.parametrize("seed", range(8))
def test_agrees_with_oracle_fp32(seed):
    scene, origins, directions = random_scene(seed)
    result = pyclray.cast(scene, origins, directions)
    assert result["depth"].dtype == np.float32 and result["normal"].dtype == np.float32 and result["id"].dtype == np.int32
    assert_agrees_with_oracle(scene, origins, directions, result, "fp32")


@pytest.mark.parametrize("seed", range(2))
def test_agrees_with_oracle_fp64(seed):
    need_precision("fp64")
    scene, origins, directions = random_scene(100 + seed)
    result = pyclray.cast(scene, origins, directions, precision="fp64")
    assert result["depth"].dtype == np.float64
    assert_agrees_with_oracle(scene, origins, directions, result, "fp64")


def test_the_model_is_tight_enough_to_catch_a_grown_sphere():
    """The same comparison fails against a sphere 2e-5 larger (a few hundred eps at these
    distances): the tolerance is not so loose that a real geometric error would pass."""
    scene, origins, directions = random_scene(3)
    result = pyclray.cast(scene, origins, directions)
    index = next(i for i, s in enumerate(scene.shapes) if s.type == "sphere")
    grown = pyclray.Sphere(scene.shapes[index].center, scene.shapes[index].radius + 2e-5)
    wrong = pyclray.Scene(scene.camera, scene.image, scene.shapes[:index] + (grown,) + scene.shapes[index + 1:])
    with pytest.raises(AssertionError, match="off by"):
        assert_agrees_with_oracle(wrong, origins, directions, result, "fp32")


def test_one_origin_is_broadcast_to_every_ray():
    scene, origins, directions = random_scene(0)
    origin = origins[0]
    one = pyclray.cast(scene, origin, directions)
    every = pyclray.cast(scene, np.tile(origin, (len(directions), 1)), directions)
    for name in pyclray.AOVS:
        np.testing.assert_array_equal(one[name], every[name])
    assert_agrees_with_oracle(scene, np.tile(origin, (len(directions), 1)), directions, one, "fp32")


def test_direction_length_does_not_matter():
    """Directions are normalized after scaling by their largest component: powers of two apart,
    even beyond float64's square root range, give the very same bits."""
    scene, origins, directions = random_scene(2)
    base = pyclray.cast(scene, origins, directions)
    for factor in (2.0**-900, 2.0**900):
        other = pyclray.cast(scene, origins, directions * factor)
        for name in pyclray.AOVS:
            np.testing.assert_array_equal(base[name], other[name])


def test_fewer_images_give_the_same_values():
    scene, origins, directions = random_scene(4)
    full = pyclray.cast(scene, origins, directions)
    for aovs in (("depth",), ("normal",), ("id",), ("id", "depth")):
        part = pyclray.cast(scene, origins, directions, aovs=aovs)
        assert set(part) == set(aovs)
        for name in aovs:
            np.testing.assert_array_equal(part[name], full[name])


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("empty", [np.zeros((0, 3)), [], np.zeros((0, 3), np.float32)])
def test_no_rays(empty, precision):
    need_precision(precision)
    scene = pyclray.load_scene(SCENES / "tp02.toml")
    real = np.float32 if precision == "fp32" else np.float64
    for origins in ((0.0, 1.0, 5.0), np.zeros((0, 3))):
        result = pyclray.cast(scene, origins, empty, precision=precision)
        assert result["depth"].shape == (0,) and result["depth"].dtype == real
        assert result["normal"].shape == (0, 3) and result["normal"].dtype == real
        assert result["id"].shape == (0,) and result["id"].dtype == np.int32


ONE = [[0.0, 0.0, -1.0]]
BAD = [
    # (origins, directions, words the message must hold)
    ((0, 1, 5), [[0.0, -1.0]], ["directions", "(..., 3)", "(1, 2)"]),
    ((0, 1, 5), np.ones((2, 3, 2)), ["directions", "(..., 3)", "(2, 3, 2)"]),
    ((0, 1, 5), 5.0, ["directions", "(..., 3)"]),
    ((0, 1, 5), "down", ["directions", "numbers"]),
    ((0, 1, 5), None, ["directions", "(..., 3)"]),
    ((0, 1), ONE, ["origins", "(..., 3)", "(2,)"]),
    (np.zeros((2, 3)), np.ones((3, 3)), ["origins", "(3, 3)", "(2, 3)"]),
    (np.zeros((1, 3)), np.ones((3, 3)), ["origins", "(3, 3)", "(1, 3)"]),
    (np.zeros((2, 2, 3)), np.ones((2, 2, 3)) * [1, np.nan, 1], ["directions", "row (0, 0)", "not finite"]),
    ((0, 1, 5), [[0, 0, -1], [0, 0, 0]], ["directions", "row 1", "zero length"]),
    ((0, 1, 5), [[0, 0, -1], [0, np.nan, -1]], ["directions", "row 1", "not finite"]),
    ((0, 1, 5), [[0, 0, -1], [np.inf, 0, -1]], ["directions", "row 1", "not finite"]),
    ([[0, 1, 5], [0, 1, np.inf]], np.ones((2, 3)), ["origins", "row 1", "not finite"]),
    ((np.nan, 1, 5), ONE, ["origins", "row 0", "not finite"]),
    ([[1e30, 0, 0], [-1e30, 0, 0]], np.ones((2, 3)), ["origins", "row 0", "too far", "fp32"]),
    ((1e39, 0, 0), ONE, ["shapes", "too far", "fp32"]),
]


@pytest.mark.parametrize("origins, directions, words", BAD)
def test_bad_arrays_are_clear_errors(origins, directions, words):
    scene = pyclray.load_scene(SCENES / "tp02.toml")
    with pytest.raises(pyclray.PyclrayError) as error:
        pyclray.cast(scene, origins, directions)
    message = str(error.value)
    assert "\n" not in message
    for word in words:
        assert word in message, f"{word!r} not in {message!r}"


def test_bad_request_is_a_clear_error():
    scene = pyclray.load_scene(SCENES / "tp02.toml")
    with pytest.raises(pyclray.PyclrayError, match="aovs"):
        pyclray.cast(scene, (0, 1, 5), ONE, aovs=("depth", "colour"))
    with pytest.raises(pyclray.PyclrayError, match="precision"):
        pyclray.cast(scene, (0, 1, 5), ONE, precision="fp16")


def test_hits_only_ahead_and_lowest_id_on_a_tie():
    """t > 0 only: from inside a sphere the far side; behind the origin nothing; a ray parallel to
    the plane misses it; two identical spheres: the lower id."""
    scene = pyclray.Scene(
        pyclray.Camera((0, 0, 10), (0, 0, 0)),
        pyclray.Image(4, 4),
        (pyclray.Plane((0, 1, 0), 1.0), pyclray.Sphere((0, 0, 0), 2.0), pyclray.Sphere((0, 0, 0), 2.0)),
    )
    origins = [[0, 0, 0], [0, 0, 5], [0, 0, 5], [0, 3, 5]]
    directions = [[0, 0, 1], [0, 0, 1], [0, 0, -1], [1, 0, 0]]
    result = pyclray.cast(scene, origins, directions)
    np.testing.assert_array_equal(result["id"], [1, -1, 1, -1])
    np.testing.assert_allclose(result["depth"][[0, 2]], [2.0, 3.0], rtol=4 * EPSILON["fp32"])
    np.testing.assert_allclose(result["normal"][[0, 2]], [[0, 0, 1], [0, 0, 1]], atol=4 * EPSILON["fp32"])


def camera_scenes():
    scenes = [pyclray.load_scene(path).with_size(48, 40) for path in sorted(SCENES.glob("*.toml"))]
    scene, _, _ = random_scene(6)
    camera = pyclray.Camera((1.0, 6.0, 14.0), (0.0, 0.0, 0.0), (0, 1, 0), 60.0)
    return scenes + [pyclray.Scene(camera, pyclray.Image(48, 40), scene.shapes, source="random scene 6")]


@pytest.mark.parametrize("scene", camera_scenes(), ids=lambda s: str(s.source).rsplit("/", 1)[-1])
def test_camera_rays_match_render(scene):
    """cast of the camera's own pixel rays gives render's images: both are within the error model
    of the oracle (render works in the eye's frame, cast traces each ray from next to each shape),
    so they differ by at most the sum of their bounds; ids agree except at silhouettes, edges, near
    ties and next to an id change (a ray moved by an ulp may cross an edge)."""
    image = pyclray.render(scene)
    origins, directions = oracle.camera_rays(scene)
    flat = directions.reshape(-1, 3)
    result = pyclray.cast(scene, scene.camera.eye, flat)
    truth = oracle.trace(scene, origins, directions, aovs=("depth", "normal", "id", "second"))
    cos = oracle.incidence_cosine(scene, directions, truth["id"], truth["normal"])

    def both(t, ids, c):  # render's bounds plus cast's
        rendered = error_model.pyclray_tolerances(scene, {"depth": t, "id": ids}, c, origins, "fp32", scene.camera.eye)
        cast = error_model.pyclray_tolerances(scene, {"depth": t, "id": ids}, c, origins, "fp32", directions=directions)
        return rendered[0] + cast[0], rendered[1] + cast[1]

    depth_tolerance, normal_tolerance = both(truth["depth"], truth["id"], cos)
    edge = error_model.at_edges(scene, origins, directions, [(truth["id"], truth["depth"]), (image["id"], image["depth"])],
                             depth_tolerance * cos)
    radius = error_model.curvature_radii(scene)[np.maximum(truth["id"], 0)]
    explained = (error_model.silhouettes(truth["id"], cos, depth_tolerance, radius) | next_to_id_change(truth["id"]) | edge
                 | error_model.near_ties(dict(truth, cos=cos), lambda t, ids, c: both(t, ids, c)[0])).ravel()
    ids = image["id"].ravel()
    # a lens's pixels outside its field (a camera of the sensors issue: scenes/lens.toml) are render's
    # misses whatever their stand-in ray meets: only the field's rays are the same in both
    table = scene.camera.space_directions(scene.image.width, scene.image.height)
    field = np.ones(ids.shape, bool) if table is None else table[1].ravel()
    assert np.all(ids[~field] == -1)
    explained |= ~field
    assert not ((result["id"] != ids) & ~explained).any()
    judged = (result["id"] == ids) & (ids >= 0) & ~explained
    assert judged.any()
    with np.errstate(invalid="ignore"):  # inf - inf where both miss
        depth_error = np.abs(result["depth"].astype(np.float64) - image["depth"].ravel())
    assert np.all(depth_error[judged] <= depth_tolerance.ravel()[judged])
    angle = error_model.angle_between(result["normal"], image["normal"].reshape(-1, 3))
    assert np.all(angle[judged] <= normal_tolerance.ravel()[judged])
    misses = (ids < 0) & (result["id"] < 0) & field
    assert np.all(np.isinf(result["depth"][misses])) and np.all(np.isinf(image["depth"].ravel()[misses]))


# -- one ray, one result: independence from the batch, far origins --------------------------------
def test_a_far_ray_changes_no_other_ray_of_its_batch():
    """The issue's case: 2,000 rays near the origin and one from (1e6, 1e6, 1e6). Each ray is traced
    on its own, so the 2,000 results are the same bits with or without the far ray, in any order,
    and meet the error model."""
    scene, origins, directions = random_scene(0)
    far_origin = np.array([[1e6, 1e6, 1e6]])
    far_direction = -far_origin
    alone = pyclray.cast(scene, origins, directions)
    both = pyclray.cast(scene, np.concatenate([origins, far_origin]), np.concatenate([directions, far_direction]))
    order = np.random.default_rng(1).permutation(len(origins))
    shuffled = pyclray.cast(scene, origins[order], directions[order])
    single = [pyclray.cast(scene, origins[k], directions[k]) for k in range(0, 2000, 97)]
    for name in pyclray.AOVS:
        assert np.array_equal(alone[name], both[name][:2000])
        assert np.array_equal(alone[name][order], shuffled[name])
        assert np.array_equal(alone[name][::97], np.array([one[name] for one in single]))
    assert_agrees_with_oracle(scene, origins, directions, alone, "fp32")
    assert both["id"][2000] >= 0  # the far ray is aimed at the scene's middle, through the plane


def far_scene(seed: int):
    """Spheres of radius 1e-4 to 1e4 near the world's origin, rays from 1e7 to 1e8 away aimed at
    them (offsets up to 1.2 radii sideways: hits, grazes and misses), and a tilted plane."""
    rng = np.random.default_rng(seed)
    count = 6
    radius = 10 ** rng.uniform(-4, 4, count)
    centers = rng.normal(size=(count, 3)) * radius[:, None] * 3
    normal = rng.normal(size=3)
    shapes = [pyclray.Sphere(tuple(c), float(r)) for c, r in zip(centers, radius)]
    shapes.append(pyclray.Plane(tuple(normal), float(-(normal @ centers[0]) - 3 * radius.max() * np.linalg.norm(normal))))
    scene = pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(8, 8), tuple(shapes))
    n = 3000
    target = rng.integers(0, count, n)
    away = rng.normal(size=(n, 3))
    away /= np.linalg.norm(away, axis=1, keepdims=True)
    origins = centers[target] + away * 10 ** rng.uniform(7, 8, (n, 1))
    sideways = np.cross(away, rng.normal(size=(n, 3)))
    sideways /= np.linalg.norm(sideways, axis=1, keepdims=True)
    aim = centers[target] + sideways * (radius[target] * rng.uniform(0, 1.2, n))[:, None]
    return scene, origins, aim - origins


@pytest.mark.parametrize("seed", range(4))
def test_far_origins_meet_the_error_model(seed):
    """Rays from 1e7 to 1e8 away against spheres of radius 1e-4 to 1e4: the depth within a few
    float32 ulps of t / cos and the normal within a few float32 ulps / cos (plus the oracle's own
    float64 error), as a camera next to the sphere would get, and every id right but at grazing."""
    scene, origins, directions = far_scene(seed)
    result = pyclray.cast(scene, origins, directions)
    assert_agrees_with_oracle(scene, origins, directions, result, "fp32")
    # the tiny spheres are hit, not lost in rounding: a float32 origin would be ~4 units off
    small = np.array([getattr(s, "radius", np.inf) for s in scene.shapes]) < 1e-2
    assert np.isin(result["id"], np.flatnonzero(small)).any() or not small.any()


# -- the API users expect: any leading shape, tmax, occluded ---------------------------------------
def test_any_leading_shape():
    scene, origins, directions = random_scene(5)
    flat = pyclray.cast(scene, origins[:1200], directions[:1200])
    shaped = pyclray.cast(scene, origins[:1200].reshape(4, 10, 30, 3), directions[:1200].reshape(4, 10, 30, 3))
    assert shaped["depth"].shape == (4, 10, 30) and shaped["normal"].shape == (4, 10, 30, 3)
    for name in pyclray.AOVS:
        assert np.array_equal(shaped[name].reshape(flat[name].shape), flat[name])
    one = pyclray.cast(scene, origins[7], directions[7])
    assert one["depth"].shape == () and one["normal"].shape == (3,) and one["id"].shape == ()
    assert one["id"] == flat["id"][7] and one["depth"] == flat["depth"][7]
    blocked = pyclray.occluded(scene, origins[:1200].reshape(40, 30, 3), directions[:1200].reshape(40, 30, 3))
    assert blocked.shape == (40, 30) and blocked.dtype == bool


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_tmax_turns_farther_hits_into_misses(precision):
    """A hit counts when its distance is below tmax (the same float64 distance that cast
    reports): per ray or one number, the results are the unlimited cast's where it hits within
    tmax, misses elsewhere."""
    need_precision(precision)
    scene, origins, directions = random_scene(6)
    full = pyclray.cast(scene, origins, directions, precision=precision)
    limit = np.random.default_rng(2).uniform(0.0, 8.0, len(origins)) + 1e-9
    for tmax in (limit, 3.0):
        part = pyclray.cast(scene, origins, directions, precision=precision, tmax=tmax)
        within = full["depth"].astype(np.float64) <= np.broadcast_to(tmax, limit.shape) * (1 + 1e-6)
        away = np.abs(full["depth"].astype(np.float64) - tmax) > 1e-5 * np.abs(tmax)  # not within rounding of tmax
        assert np.array_equal(part["id"][away], np.where(within, full["id"], -1)[away])
        assert np.array_equal(part["depth"][away & within], full["depth"][away & within])
        assert np.all(np.isinf(part["depth"][part["id"] < 0])) and np.all(part["normal"][part["id"] < 0] == 0)
        assert (part["id"] >= 0).sum() < (full["id"] >= 0).sum()


@pytest.mark.parametrize("seed", range(2))
def test_occluded_is_any_hit_within_tmax(seed):
    """occluded(tmax) is true exactly where cast(tmax) finds a hit: the same tests of the same
    rays, bit for bit, stopped at the first hit."""
    scene, origins, directions = random_scene(10 + seed)
    tmax = np.random.default_rng(seed).uniform(0.0, 10.0, len(origins)) + 1e-9
    hits = pyclray.cast(scene, origins, directions, aovs=("id",), tmax=tmax)["id"] >= 0
    assert np.array_equal(pyclray.occluded(scene, origins, directions, tmax), hits)
    assert np.array_equal(pyclray.occluded(scene, origins, directions), pyclray.cast(scene, origins, directions)["id"] >= 0)
    assert 0 < hits.sum() < len(hits)


@pytest.mark.parametrize("tmax, words", [(0.0, "> 0"), (-1.0, "> 0"), (np.nan, "> 0"), (np.ones(3), "shape"), ("far", "number")])
def test_bad_tmax_is_a_clear_error(tmax, words):
    scene = pyclray.load_scene(SCENES / "tp02.toml")
    with pytest.raises(pyclray.PyclrayError, match="tmax") as error:
        pyclray.cast(scene, (0, 1, 5), np.ones((4, 3)), tmax=tmax)
    assert words in str(error.value)
    with pytest.raises(pyclray.PyclrayError, match="tmax"):
        pyclray.occluded(scene, (0, 1, 5), np.ones((4, 3)), tmax)


def test_origins_beyond_double_range_are_refused():
    """An fp64 ray from 1e30 away hits (distance 1e30, the sphere's id); from 1e155, where the
    kernel's squared distances would overflow even in double, it is one clear error."""
    need_precision("fp64")
    scene = pyclray.Scene(pyclray.Camera((0.0, 2.0, 6.0), (0.0, 0.5, 0.0)), pyclray.Image(8, 8),
                          (pyclray.Plane((0.0, 1.0, 0.0), 0.0), pyclray.Sphere((0.0, 1.0, 0.0), 1.0)))
    near = pyclray.cast(scene, (0.0, 1.0, 1e30), (0.0, 0.0, -1.0), precision="fp64")
    assert near["id"] == 1 and near["depth"] == pytest.approx(1e30, rel=1e-15)
    with pytest.raises(pyclray.PyclrayError, match="too far"):
        pyclray.cast(scene, (0.0, 1.0, 1e155), (0.0, 0.0, -1.0), precision="fp64")


def test_large_batches_cast_in_a_coherent_order_give_the_same_bits():
    """From render.COHERENT_FROM rays on, cast runs them in a Morton order of their origins (or of
    their directions, sharing one origin) and puts the results back: the same bits as batches too
    small to be reordered, for cast and occluded."""
    import sys

    render_module = sys.modules["pyclray.engine.queries.cast"]
    scene, origins, directions = random_scene(12)
    rng = np.random.default_rng(12)
    count = render_module.COHERENT_FROM + 1000
    origins = rng.uniform(-6, 6, (count, 3))
    directions = rng.normal(size=(count, 3))
    tmax = rng.uniform(0.5, 10.0, count)
    chunks = range(0, count, 1000)
    for shared in (False, True):
        o = origins[0] if shared else origins
        whole = pyclray.cast(scene, o, directions, tmax=tmax)
        blocked = pyclray.occluded(scene, o, directions, tmax)
        parts = [pyclray.cast(scene, o if shared else o[c: c + 1000], directions[c: c + 1000], tmax=tmax[c: c + 1000]) for c in chunks]
        for name in pyclray.AOVS:
            assert np.array_equal(whole[name], np.concatenate([p[name] for p in parts]))
        assert np.array_equal(blocked, whole["id"] >= 0)


def test_origins_beyond_the_float_box_tests_still_hit():
    """fp64 accepts origins far beyond float32's range from the scene (up to sqrt of double's
    largest / 4); the BVH's box tests are in float, so such rays test every bounded shape instead
    (kernels/rays.h): the same hits, from 1e40 away as from 10."""
    need_precision("fp64")
    scene = pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(4, 4),
                          (pyclray.Sphere((0.0, 0.0, 0.0), 1.0), pyclray.Sphere((0.0, 3.0, 0.0), 1.0)))
    origins = np.array([[1e40, 0.0, 0.0], [10.0, 0.0, 0.0], [1e40, 3.0, 0.0], [1e40, 5.0, 0.0]])
    result = pyclray.cast(scene, origins, [[-1.0, 0.0, 0.0]] * 4, precision="fp64")
    np.testing.assert_array_equal(result["id"], [0, 0, 1, -1])
    np.testing.assert_allclose(result["depth"][:3], [1e40 - 1.0, 9.0, 1e40 - 1.0], rtol=1e-15)
    np.testing.assert_array_equal(result["normal"][:3], [[1.0, 0.0, 0.0]] * 3)


# -- tmin and every per-hit AOV (issue 38) -------------------------------------------------------------
def tmin_scene():
    """Solids (a sphere, a box, a capped cylinder, a closed mesh and its instance), a disk and a plane:
    from a tmin inside a solid the nearest hit is its far side, which a cast from the origin never
    returns."""
    from pyclray.model.shapes.mesh_shapes import perturbed_sphere

    v, f = perturbed_sphere(8, 12, 1.0, 0.2, np.random.default_rng(1))
    base = pyclray.Mesh(v, f)
    shapes = (pyclray.Sphere((3.0, 0.0, 0.0), 1.0, label=7), pyclray.Box((-3.0, 0.0, 0.0), (1.0, 2.0, 1.5), (1.0, 1.0, 0.0), 20.0),
              pyclray.Cylinder((0.0, 3.0, 0.0), (0.0, 4.0, 1.0), 0.7), pyclray.Mesh(v, f, translate=(0.0, -3.0, 0.0)),
              base.placed(scale=0.7, translate=(3.0, 3.0, 0.0)), base.placed(scale=0.6, translate=(-3.0, 3.0, 0.0)),
              pyclray.Disk((0.0, 0.0, 3.0), (0.0, 0.0, 1.0), 1.0), pyclray.Plane((0.0, 0.0, 1.0), 6.0))
    return pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(8, 8), shapes)


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_tmin_gives_the_nearest_hit_beyond_it(precision):
    """cast(tmin=...) (one number or one per ray) is the oracle's first crossing beyond tmin: the same
    id and primitive, the depth within the error model; occluded(tmin=...) says whether there is one."""
    need_precision(precision)
    scene = tmin_scene()
    rng = np.random.default_rng(11)
    origins = rng.uniform(-5, 5, (3000, 3))
    directions = rng.normal(size=(3000, 3))
    tmin = rng.uniform(0.0, 5.0, len(origins))
    result = pyclray.cast(scene, origins, directions, aovs=("depth", "id", "primitive"), tmin=tmin, precision=precision)
    ref = oracle.all_hits(scene, origins, directions, tmin=tmin)
    has = np.diff(ref["offsets"]) > 0
    first = ref["offsets"][:-1][has]
    # a crossing within rounding of tmin may count either way: those rays are left out
    crossings = oracle.all_hits(scene, origins, directions)
    near = np.abs(crossings["depth"] - tmin[crossings["ray"]]) < 1e-3
    sure = np.bincount(crossings["ray"][near], minlength=len(origins)) == 0
    assert np.array_equal((result["id"] >= 0)[sure], has[sure])
    mine = sure & has
    assert np.array_equal(result["id"][mine], ref["id"][ref["offsets"][:-1][mine]])
    assert np.array_equal(result["primitive"][mine], ref["primitive"][ref["offsets"][:-1][mine]])
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    t = ref["depth"][first]
    cos = np.ones(len(first))
    points = origins[has] + t[:, None] * unit[has]
    for index, shape in enumerate(scene.shapes):
        rows = ref["id"][first] == index
        if rows.any():
            cos[rows] = np.abs(np.einsum("ij,ij->i", shape.oracle_normal(points[rows]), unit[has][rows]))
    tolerance, _ = error_model.pyclray_tolerances(scene, {"depth": t, "id": ref["id"][first]}, cos, origins[has], precision,
                                                   directions=unit[has])
    error = np.abs(result["depth"][has].astype(np.float64) - t)
    assert (error[sure[has]] <= tolerance[sure[has]]).all()
    from_origin = pyclray.cast(scene, origins, directions, aovs=("id",), precision=precision)["id"]
    assert ((result["id"] >= 0) & (from_origin >= 0) & (result["id"] != from_origin)).any()  # tmin changed answers
    occluded = pyclray.occluded(scene, origins, directions, tmin=tmin, precision=precision)
    assert np.array_equal(occluded[sure], has[sure])
    # one tmin for every ray
    one = pyclray.cast(scene, origins, directions, aovs=("id",), tmin=2.0, precision=precision)["id"]
    ref_one = oracle.all_hits(scene, origins, directions, tmin=2.0)
    has_one = np.diff(ref_one["offsets"]) > 0
    sure_one = np.bincount(crossings["ray"][np.abs(crossings["depth"] - 2.0) < 1e-3], minlength=len(origins)) == 0
    assert np.array_equal((one >= 0)[sure_one], has_one[sure_one])


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_every_per_hit_aov(precision):
    """label, primitive, barycentric and position of cast's rays: the hit shape's label, the
    triangle (or sphere of a batch) the oracle finds, barycentrics that give the hit point, and
    origin + depth times the unit direction."""
    need_precision(precision)
    scene = tmin_scene()
    spheres = pyclray.Spheres(np.array([[0.0, -1.0, -3.0], [1.0, -1.0, -3.0]]), np.array([0.4, 0.3]))
    scene = pyclray.Scene(scene.camera, scene.image, scene.shapes + (spheres,))
    rng = np.random.default_rng(12)
    origins = rng.uniform(-5, 5, (3000, 3))
    directions = rng.normal(size=(3000, 3))
    aovs = ("depth", "normal", "id", "label", "primitive", "barycentric", "position")
    result = pyclray.cast(scene, origins, directions, aovs=aovs, precision=precision)
    real = np.float32 if precision == "fp32" else np.float64
    assert result["position"].dtype == real and result["barycentric"].dtype == real and result["barycentric"].shape == (3000, 2)
    assert result["primitive"].dtype == np.int32 and result["label"].dtype == np.int32
    ids = result["id"]
    labels = np.array([7 if i == 0 else -1 for i in range(len(scene.shapes))] + [-1])
    assert np.array_equal(result["label"], labels[ids])
    first = oracle.all_hits(scene, origins, directions)
    has = np.diff(first["offsets"]) > 0
    assert np.array_equal(ids >= 0, has)
    same = has & (ids == np.where(has, first["id"][np.minimum(first["offsets"][:-1], len(first["id"]) - 1)], -1))
    assert same.sum() > 0.99 * has.sum()  # (near-ties of two shapes may go either way)
    row = first["offsets"][:-1][same]
    assert np.array_equal(result["primitive"][same], first["primitive"][row])
    assert (result["primitive"][~has] == -1).all() and (result["barycentric"][~has] == 0).all()
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    expected = origins + np.where(has, result["depth"], 0)[:, None].astype(np.float64) * unit
    assert np.allclose(result["position"][has], expected[has], rtol=1e-6, atol=1e-6)  # (float32 rounding at fp32)
    assert (result["position"][~has] == 0).all()
    # a triangle's barycentrics give its hit point (meshes and instances); other shapes' are 0, 0
    for index, shape in enumerate(scene.shapes):
        mine = ids == index
        if isinstance(shape, pyclray.Mesh):
            a, b, c = (x[result["primitive"][mine]] for x in shape.corners())
            u, v = (result["barycentric"][mine, k, None].astype(np.float64) for k in (0, 1))
            point = (1 - u - v) * a + u * b + v * c
            assert np.abs(point - result["position"][mine]).max() < (1e-4 if precision == "fp32" else 1e-10)
        else:
            assert (result["barycentric"][mine] == 0).all()
    # fewer AOVs: the same values
    alone = pyclray.cast(scene, origins, directions, aovs=("primitive",), precision=precision)
    assert np.array_equal(alone["primitive"], result["primitive"])


@pytest.mark.parametrize("tmin, words", [(-1.0, ">= 0"), (np.inf, ">= 0"), (np.nan, ">= 0"), ([0.0, 0.0, -2.0, 0.0], "row 2"),
                                         (np.ones(3), "shape"), ("near", "number")])
def test_bad_tmin_is_a_clear_error(tmin, words):
    scene = pyclray.load_scene(SCENES / "tp02.toml")
    with pytest.raises(pyclray.RequestError, match="tmin") as error:
        pyclray.cast(scene, (0, 1, 5), np.ones((4, 3)), tmin=tmin)
    assert words in str(error.value)
    with pytest.raises(pyclray.RequestError, match="tmin"):
        pyclray.occluded(scene, (0, 1, 5), np.ones((4, 3)), tmin=tmin)
