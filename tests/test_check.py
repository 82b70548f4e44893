"""pyclray check: the image and ray-level cross-checks against Mitsuba 3, and the command.

Tolerances are pyclray.reference.error_model's error model (eps = 2^-24, float32's unit roundoff):

    same rays:  |depth difference| <= 6 eps (t + L) / cos,  normal angle <= 6 eps (1 + (t + L) / (r cos))
    cameras:    direction angle <= 3 eps (1 + S),  origin off our ray <= 2 eps max(|eye|, 1)
    images:     |depth difference| <= D = eps (6 (t + L) + 3 (1 + S) t + 2 max(|eye|, 1)) / cos,
                normal angle <= 6 eps + D / r

t is the distance, cos the |cosine of incidence| (float64 oracle), r a sphere's radius,
S = max(|eye|, |target|) / |target - eye|, and L = max(|eye|, |anchor|, |eye - anchor|): Mitsuba
works in float32 world coordinates, so "a few ulps" is relative to |t| plus the size of those
coordinates, and grows as 1/cos at grazing incidence. Measured over 75 random scenes: same rays
<= 2.8 eps (t + L) / cos, cameras <= 2.1 eps (1 + S), images <= 0.33 of D.
Silhouettes (|cos| < 0.02), pixels next to an id change and near ties are counted apart.
"""
import numpy as np
import pytest

import pyclray
from pyclray.apps import cli
from pyclray.reference import check
from pyclray.reference import error_model
from pyclray.reference.validation.files import RAMP
from pyclray.io.exr import read_exr

from conftest import SCENES

SMALL = (96, 96)


def random_scene(seed: int, size=SMALL, shift: float = 0.0):
    """Random spheres and a tilted plane, seen from a random eye; the whole scene moved by a random
    offset of about `shift` units (Mitsuba's error grows with its world coordinates, ours does not)."""
    rng = np.random.default_rng(seed)
    offset = rng.normal(size=3) * shift
    normal = rng.normal(size=3)
    normal[1] = abs(normal[1]) + 2.0
    shapes = [pyclray.Plane(tuple(normal), float(-normal @ offset), "floor")]
    for index in range(rng.integers(2, 6)):
        centre = rng.uniform(-3, 3, 3)
        centre[1] = abs(centre[1])
        shapes.append(pyclray.Sphere(tuple(centre + offset), float(rng.uniform(0.2, 2.0)), f"ball{index}"))
    eye = np.array([rng.uniform(-2, 2), rng.uniform(1, 4), rng.uniform(6, 12)]) + offset
    camera = pyclray.Camera(tuple(eye), tuple(offset + rng.uniform(-0.5, 0.5, 3)), (0, 1, 0), float(rng.uniform(30, 70)))
    return pyclray.Scene(camera, pyclray.Image(*size), tuple(shapes), source=f"random scene {seed}")


def scene_files():
    """The shipped scenes Mitsuba can render: not those whose camera it has no sensor of (a lens's
    distortion: scenes/lens.toml), whose cameras tests/test_lenses.py checks against OpenCV's own
    projection and the float64 oracle instead."""
    def has_sensor(path):
        try:
            scene = pyclray.load_scene(path)
            scene.camera.mitsuba_sensor(scene.image.width, scene.image.height)
        except pyclray.SceneError:
            return False
        return True

    files = sorted(SCENES.glob("*.toml"))
    checkable = [path for path in files if has_sensor(path)]
    assert len(checkable) >= len(files) - 1  # only the lens scene is left out
    return checkable


def assert_passed(result):
    assert result.passed, result.failures
    assert result.depth_ratio.count > 0 and result.depth_ratio.max <= 1
    assert result.normal_ratio.max <= 1


def small(scene):
    """The scene at SMALL; a camera from intrinsics keeps its aspect ratio (a new one would stretch
    its K to fx != fy, which Mitsuba's square pixels cannot show)."""
    if scene.camera.K is None:
        return scene.with_size(*SMALL)
    return scene.with_size(SMALL[0], round(SMALL[0] * scene.image.height / scene.image.width))


@pytest.mark.parametrize("path", scene_files(), ids=lambda p: p.name)
def test_every_scene_agrees_with_mitsuba_scalar(path):
    scene = small(pyclray.load_scene(path))
    result = check.cross_check(scene, "scalar_rgb")
    assert_passed(result)
    assert result.ids["unexplained"] == 0


def test_tp02_agrees_with_mitsuba_llvm():
    scene = pyclray.load_scene(SCENES / "tp02.toml").with_size(*SMALL)
    result = check.cross_check(scene, "llvm_ad_rgb")
    assert_passed(result)
    assert result.counts["both hit the same shape"] > SMALL[0] * SMALL[1] // 2


@pytest.mark.parametrize("seed, shift", [(1, 0.0), (2, 100.0)])
def test_random_scenes_agree_with_mitsuba(seed, shift):
    result = check.cross_check(random_scene(seed, shift=shift), "scalar_rgb")
    assert_passed(result)


def test_horizon_pixels_beyond_the_disk_are_left_out():
    """Looking at the horizon: the middle row meets the floor beyond its disk; those pixels are
    counted and left out, and the check still passes."""
    camera = pyclray.Camera((0, 1, 0), (0, 1 - 10 / 2e6, -10), (0, 1, 0), 30.0)
    scene = pyclray.Scene(camera, pyclray.Image(33, 33), (pyclray.Plane((0, 1, 0), 0.0), pyclray.Sphere((3, 1, -40), 1.0)))
    result = check.cross_check(scene, "scalar_rgb")
    assert result.counts["beyond a Mitsuba stand-in (left out)"] == 33
    assert_passed(result)


def grown(scene, amount: float):
    """The scene with its first sphere's radius grown by `amount`."""
    index = next(i for i, s in enumerate(scene.shapes) if s.type == "sphere")
    sphere = scene.shapes[index]
    shapes = scene.shapes[:index] + (pyclray.Sphere(sphere.center, sphere.radius + amount),) + scene.shapes[index + 1:]
    return pyclray.Scene(scene.camera, scene.image, shapes)


def test_a_slightly_different_mitsuba_scene_is_found_and_blamed_on_mitsuba():
    """A sphere 2e-5 larger in Mitsuba's scene (about 40 eps (t + L) at tp02's distances) is outside
    the tolerance between the two (it is not so loose that a real error passes) in both comparisons;
    the float64 oracle of the true scene puts it on Mitsuba, so the check passes and says so."""
    scene = pyclray.load_scene(SCENES / "tp02.toml").with_size(*SMALL)
    images = check.cross_check(scene, "scalar_rgb", mitsuba_scene=grown(scene, 2e-5))
    depth = images.verdicts["depth"]
    assert depth.disagree > 100 and depth.mitsuba >= depth.disagree - 2 and depth.pyclray == 0
    assert images.passed and images.depth_ratio.max > 1
    rays = check.ray_level(scene, "scalar_rgb", 512, seed=0, mitsuba_scene=grown(scene, 2e-5))
    assert rays.passed and rays.verdicts["depth"].mitsuba > 10 and rays.verdicts["depth"].pyclray == 0


def test_a_slightly_wrong_pyclray_fails_the_check(monkeypatch):
    """The same 2e-5 on pyclray's side (its render and its casts of a grown sphere, the oracle and
    Mitsuba of the true scene): pyclray's fault, and the check fails saying so."""
    import pyclray.engine.api as api

    scene = pyclray.load_scene(SCENES / "tp02.toml").with_size(*SMALL)
    wrong = grown(scene, 2e-5)
    real_render, real_cast = api.render, api.cast
    monkeypatch.setattr(api, "render", lambda s, **kw: real_render(wrong, **kw))
    monkeypatch.setattr(api, "cast", lambda s, *a, **kw: real_cast(wrong, *a, **kw))
    images = check.cross_check(scene, "scalar_rgb")
    assert not images.passed and images.failures[0].startswith("depth: pyclray wrong by the float64 oracle")
    assert images.verdicts["depth"].pyclray > 100 and images.verdicts["depth"].mitsuba == 0
    rays = check.ray_level(scene, "scalar_rgb", 512, seed=0)
    assert not rays.passed and any("pyclray wrong" in f for f in rays.failures)


def test_far_passes_saying_mitsuba_is_wrong(capsys):
    """scenes/far.toml (a unit ball 1e5 away beside a ground sphere of radius 1e6): where the two
    shaded images disagree, the float64 shading model sides with pyclray (Mitsuba's shadow rays from
    1e5 away start 1500 eps (1 + |p|), about 9 units, off the surface)."""
    status = cli.main(["check", str(SCENES / "far.toml"), "--rays", "256"])
    out = capsys.readouterr().out
    assert status == 0, out
    last = out.strip().splitlines()[-1]
    assert last.startswith("passed: within the tolerance; Mitsuba is wrong on ") and "shaded" in last


def test_scalar_images_are_mitsubas_aov_integrator_bit_for_bit():
    """The scalar variants cast Mitsuba's pixel rays one by one (its aov integrator takes time in
    proportion to the number of shapes there): the same depth, normals and shapes as the integrator."""
    from pyclray.reference import mitsuba

    scene = pyclray.load_scene(SCENES / "shapes.toml").with_size(48, 36)
    ours = mitsuba.render(scene, "scalar_rgb")
    mi = mitsuba.import_mitsuba("scalar_rgb")
    mi_scene, ids = mitsuba.load(scene, "scalar_rgb")
    image = np.array(mi_scene.integrator().render(mi_scene, mi_scene.sensors()[0]), dtype=np.float64)
    hit = image[..., 7] > 0
    assert np.array_equal(hit, ours["id"] >= 0)
    assert np.array_equal(np.vectorize(lambda k: ids.get(int(k), -1))(np.rint(image[..., 7]))[hit], ours["id"][hit])
    near, _ = mitsuba.clip_range(scene)
    assert np.array_equal((image[..., 0] + near / mitsuba.axis_cosines(scene))[hit], ours["depth"][hit])
    assert np.array_equal(image[..., 1:4][hit], ours["normal"][hit]) and mi.variant() == "scalar_rgb"


@pytest.mark.parametrize(
    "scene, variant",
    [
        (pyclray.load_scene(SCENES / "tp02.toml").with_size(*SMALL), "scalar_rgb"),
        (pyclray.load_scene(SCENES / "tp02.toml").with_size(*SMALL), "llvm_ad_rgb"),
        (random_scene(5), "scalar_rgb"),
        (random_scene(6, shift=100.0), "scalar_rgb"),
    ],
    ids=["tp02-scalar", "tp02-llvm", "random5-scalar", "random6-moved-scalar"],
)
def test_ray_level_agrees_within_a_few_ulps(scene, variant):
    """On the very same rays pyclray.cast and Mitsuba's ray_intersect agree within
    6 eps (t + L) / cos; Mitsuba's camera rays are pyclray's pixel rays to a few eps, more when
    the eye is far from the world origin (its look_at matrix is float32)."""
    result = check.ray_level(scene, variant, n_rays=512, seed=7)
    assert result.passed, result.failures
    assert result.depth_ratio.count > 100
    eye, target = np.array(scene.camera.eye), np.array(scene.camera.target)
    size = max(np.linalg.norm(eye), np.linalg.norm(target)) / np.linalg.norm(target - eye)
    assert result.camera_angle.max <= 3 * error_model.EPSILON["fp32"] * (1 + size)  # float32 look_at: measured 3.3 eps on tp02
    assert result.camera_origin.max <= 2  # Mitsuba's origin: the eye rounded to float32, on the ray
    assert result.ids["unexplained"] == 0


def test_tables_are_printed_and_exit_0_on_tp02(capsys):
    status = cli.main(["check", str(SCENES / "tp02.toml"), "--size", "64x64", "--rays", "256"])
    out = capsys.readouterr().out
    assert status == 0, out
    for title in ("depth: distance from the eye", "normal: angle", "id: ", "misses: ", "ray level, cameras",
                  "ray level, intersections", "6 eps (t + L) / cos", "arbitration: where pyclray and Mitsuba disagree",
                  "time by step", "Mitsuba scalar_rgb render", "Mitsuba's steps, in all", "float64 oracle",
                  "closest points of", "Mitsuba has no closest-point query", "passed: within the tolerance"):
        assert title in out, title


def test_exit_1_outside_the_tolerance(capsys, monkeypatch):
    """With tolerances a thousand times too tight (pyclray's against the oracle too) the same check
    fails with status 1 and says why; with only Mitsuba's too tight, Mitsuba is blamed and it passes.
    (Mitsuba's camera rays against the exact pixel rays stay a failure: they check the bridge.)"""
    monkeypatch.setattr(error_model, "K_MITSUBA", error_model.K_MITSUBA / 1000)
    status = cli.main(["check", str(SCENES / "tp02.toml"), "--size", "48x48", "--rays", "64"])
    out = capsys.readouterr().out
    assert status == 0 and "Mitsuba is wrong on" in out.splitlines()[-1], out
    monkeypatch.setattr(error_model, "K_ORACLE", error_model.K_ORACLE / 1000)
    status = cli.main(["check", str(SCENES / "tp02.toml"), "--size", "48x48", "--rays", "64"])
    out = capsys.readouterr().out
    assert status == 1
    assert "FAILED: " in out and "pyclray wrong by the float64 oracle" in out.splitlines()[-1]


@pytest.mark.parametrize(
    "arguments, words",
    [
        (["missing.toml"], ["missing.toml", "cannot read"]),
        (["BAD"], ["bad.toml", "[[shapes]] #0 (sphere)", "radius"]),
        ([str(SCENES / "tp02.toml"), "--rays", "0"], ["--rays"]),
        ([str(SCENES / "tp02.toml"), "--save", "FILE"], ["--save", "is not a folder"]),
        ([str(SCENES / "tp02.toml"), "--save", "no/such/folder/out"], ["--save", "does not exist"]),
    ],
)
def test_bad_input_is_one_line_and_exit_2(arguments, words, tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('[camera]\neye = [0, 1, 5]\ntarget = [0, 0, 0]\nfov = 40\n[[shapes]]\ntype = "sphere"\ncenter = [0, 0, 0]\nradius = -1\n')
    (tmp_path / "file").write_text("")
    arguments = [str(bad) if a == "BAD" else str(tmp_path / "file") if a == "FILE" else
                 str(tmp_path / a) if a.startswith("no/") else a for a in arguments]
    status = cli.main(["check", *arguments])
    captured = capsys.readouterr()
    assert status == 2
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    for word in words:
        assert word in lines[0]
    assert captured.out == ""


def test_save_writes_both_renders_and_the_heat_map(tmp_path, capsys):
    folder = tmp_path / "out"
    status = cli.main(["check", str(SCENES / "tp02.toml"), "--size", "40x30", "--rays", "64", "--save", str(folder)])
    assert status == 0, capsys.readouterr().out
    ours = read_exr(folder / "tp02.pyclray.exr")
    theirs = read_exr(folder / "tp02.mitsuba-scalar_rgb.exr")
    scene = pyclray.load_scene(SCENES / "tp02.toml").with_size(40, 30)
    image = pyclray.render(scene)
    for name in ("depth", "normal", "id"):
        np.testing.assert_array_equal(ours[name], image[name])
        assert theirs[name].shape == image[name].shape
    np.testing.assert_array_equal(theirs["id"], image["id"])
    png = (folder / "tp02.depth-error.png").read_bytes()
    assert png.startswith(b"\x89PNG\r\n\x1a\n") and png[16:24] == (40).to_bytes(4, "big") + (30).to_bytes(4, "big")
    assert not list(folder.glob(".*.tmp"))


def test_heat_map_colours():
    relative = np.array([[1e-9, 1e-4], [1e-6, np.nan]])
    judged = np.array([[True, True], [True, False]])
    outside = np.array([[False, False], [True, False]])
    rgb = check.heat_map(relative, judged, outside)
    assert tuple(rgb[0, 0]) == tuple(RAMP[0].astype(np.uint8))  # the low end: dark blue
    assert tuple(rgb[0, 1]) == tuple(RAMP[-1].astype(np.uint8))  # the high end: red
    assert tuple(rgb[1, 0]) == (255, 255, 255)  # outside the tolerance: white
    assert tuple(rgb[1, 1]) == (0, 0, 0)  # not compared: black


@pytest.mark.parametrize("variant", check.VARIANTS)
@pytest.mark.parametrize("name", ["shapes", "tp02-cylinder"])
def test_scenes_with_every_shape_agree_with_mitsuba(name, variant):
    """Images and the very same rays: the cylinder (Mitsuba's open cylinder and two disks, mapped
    back to one id), the disk, the rectangle and the box (Mitsuba's cube) within the tolerance, in
    both variants, every id disagreement explained."""
    scene = pyclray.load_scene(SCENES / f"{name}.toml").with_size(*SMALL)
    images = check.cross_check(scene, variant)
    assert_passed(images)
    assert images.ids["unexplained"] == 0
    assert set(np.unique(images.images["theirs"]["id"])) == set(range(-1, len(scene.shapes)))
    rays = check.ray_level(scene, variant, n_rays=384, seed=3)
    assert rays.passed, rays.failures


def random_shapes_scene(seed: int, shift: float = 0.0):
    """One random shape of every type (from the registry) around the origin, moved by ``shift``."""
    from pyclray.model.shapes import REGISTRY

    rng = np.random.default_rng(seed)
    offset = rng.normal(size=3) * shift
    shapes = tuple(cls.random(rng, offset) for cls in REGISTRY.values())
    eye = offset + np.array([rng.uniform(-2, 2), rng.uniform(3, 6), rng.uniform(9, 13)])
    camera = pyclray.Camera(tuple(eye), tuple(offset), (0, 1, 0), 60.0)
    return pyclray.Scene(camera, pyclray.Image(*SMALL), shapes, source=f"random shapes {seed}")


@pytest.mark.parametrize("seed, shift", [(1, 0.0), (2, 100.0)])
def test_random_scenes_of_every_shape_agree_with_mitsuba(seed, shift):
    assert_passed(check.cross_check(random_shapes_scene(seed, shift), "scalar_rgb"))
