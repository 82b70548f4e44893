"""The Mitsuba 3 bridge (pyclray.mitsuba): lazily imported, clip range, the plane's stand-in disk
and its horizon mask, shape ids in the scalar and JIT variants, Mitsuba's own primary rays.

Tolerances follow the error model of pyclray.accuracy (eps = 2^-24): Mitsuba intersects in float32
world coordinates, so two of its intersections of (nearly) the same ray differ by up to
k eps (t + L) / cos, L the size of the world coordinates involved (see error_model.world_sizes).
Measured k <= 1.5 here (the image's rays against sample_ray's, scalar against llvm); k = 4.
"""
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import pyclray
from pyclray.apps import cli
from pyclray.reference import error_model
from pyclray.reference import mitsuba
from pyclray.reference import oracle

from conftest import REPO, SCENES

EPSILON = 2.0**-24
VARIANTS = ("scalar_rgb", "llvm_ad_rgb")


def tp02(width=64, height=48):
    return pyclray.load_scene(SCENES / "tp02.toml").with_size(width, height)


def horizon_scene(distance: float, height: int = 33):
    """The camera looks at the horizon over a floor: the middle row's rays (odd height) meet the
    floor at `distance`; rows above miss it, rows below hit it nearer."""
    eye = (0.0, 1.0, 0.0)
    target = (0.0, 1.0 - 10.0 / distance, -10.0)
    shapes = (pyclray.Plane((0, 1, 0), 0.0, "floor"), pyclray.Sphere((3, 1, -40), 1.0, "ball"))
    return pyclray.Scene(pyclray.Camera(eye, target, (0, 1, 0), 30.0), pyclray.Image(33, height), shapes)


def test_render_and_the_cli_do_not_import_mitsuba(tmp_path):
    """`import pyclray`, pyclray.render and `pyclray render` (whose parser imports pyclray.reference.check)
    never load mitsuba or drjit: importing them takes about a second."""
    code = textwrap.dedent(f"""
        import sys
        import pyclray
        from pyclray.apps import cli
        scene = pyclray.load_scene({str(SCENES / "tp02.toml")!r}).with_size(8, 8)
        pyclray.render(scene)
        pyclray.cast(scene, scene.camera.eye, [[0.0, -0.2, -1.0]])
        assert cli.main(["render", {str(SCENES / "tp02.toml")!r}, "--size", "8x8", "-o", {str(tmp_path / "x.exr")!r}]) == 0
        assert "pyclray.apps.cli.check" in sys.modules, "the check command was not registered"
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("mitsuba", "drjit"))
        assert not loaded, loaded
        print("clean")
    """)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("clean")
    # and the check does load it, so the test above can tell
    code = "import sys, pyclray.reference.mitsuba as m; m.import_mitsuba(); print('mitsuba' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout.strip() == "True"


@pytest.mark.parametrize("path", sorted(SCENES.glob("*.toml")), ids=lambda p: p.name)
def test_clip_range_holds_every_hit(path):
    """near_clip is below a thousandth of the nearest surface's distance (the depth offset it
    adds is then exactly accounted for), far_clip beyond every shape's reach (the plane's
    stand-in disk: tests/test_plane.py)."""
    scene = pyclray.load_scene(path)
    near, far = mitsuba.clip_range(scene)
    eye = np.array(scene.camera.eye)
    for shape in scene.shapes:
        gap = shape.surface_distance(eye[None])[0]
        assert gap == 0 or near <= 1e-3 * gap
        assert far > shape.extent_from(eye)


def test_horizon_mask_marks_what_the_disk_cannot_show():
    """Looking at the horizon, the middle row meets the floor at 5 disk radii: pyclray sees the
    floor, Mitsuba's disk has ended. Exactly those pixels are masked; everywhere else the ids agree."""
    scene = horizon_scene(2e6)
    _, _, radius = scene.shapes[0].mitsuba_disk(scene)
    assert 2e6 > 4 * radius
    origins, directions = oracle.camera_rays(scene)
    mask = mitsuba.beyond_counterparts(scene, origins, directions)
    ours = pyclray.render(scene)
    for variant in VARIANTS:
        theirs = mitsuba.render(scene, variant)
        assert mask[16].all() and mask.sum() == scene.image.width  # the middle row, only
        floor_seen = mask & (ours["id"] == 0)
        assert floor_seen.sum() >= 20 and np.all(theirs["id"][floor_seen] == -1)
        assert np.all(ours["depth"][floor_seen] > radius)
        np.testing.assert_array_equal(ours["id"][~mask], theirs["id"][~mask])


def test_horizon_within_the_disk_is_not_masked():
    scene = horizon_scene(2e4)
    origins, directions = oracle.camera_rays(scene)
    assert not mitsuba.beyond_counterparts(scene, origins, directions).any()
    ours, theirs = pyclray.render(scene), mitsuba.render(scene, "scalar_rgb")
    np.testing.assert_array_equal(ours["id"], theirs["id"])
    assert (theirs["id"][16] == 0).sum() >= 20  # the far floor is there in Mitsuba too


def shuffled_scene():
    """tp02's shapes in another order: spheres first, the plane (a disk in Mitsuba) last."""
    shapes = (
        pyclray.Sphere((1.5, 0.5, 1.0), 0.5, "zeta"),
        pyclray.Sphere((-1.6, 0.7, -0.5), 0.7, "alpha"),
        pyclray.Sphere((0.0, 1.0, 0.0), 1.0, "mid"),
        pyclray.Plane((0.0, 1.0, 0.0), 0.0, "ground"),
    )
    return pyclray.Scene(pyclray.Camera((0.0, 2.0, 6.0), (0.0, 0.5, 0.0)), pyclray.Image(64, 48), shapes)


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("scene", [tp02(), shuffled_scene()], ids=["tp02", "shuffled"])
def test_ids_map_back_to_pyclray_ids(scene, variant):
    """shape_index is 1 + position (scalar) or the registry id (llvm): both map back to pyclray's
    ids; they agree with pyclray's image except at silhouettes (|cos| < 0.02)."""
    ours = pyclray.render(scene)
    theirs = mitsuba.render(scene, variant)
    origins, directions = oracle.camera_rays(scene)
    truth = oracle.trace(scene, origins, directions)
    cos = oracle.incidence_cosine(scene, directions, truth["id"], truth["normal"])
    assert set(np.unique(theirs["id"])) == set(range(-1, len(scene.shapes)))
    differ = ours["id"] != theirs["id"]
    assert not (differ & (cos >= error_model.SILHOUETTE_COS)).any()
    assert differ.sum() <= 4


@pytest.mark.parametrize("variant", VARIANTS)
def test_primary_rays_are_the_images_rays(variant):
    """position_sample ((i + 0.5) / W, (j + 0.5) / H) gives pixel (row j, column i): the directions
    are pyclray's pixel rays to a few eps (float32 rounding: measured <= 3.3 eps), the origin lies on
    the near-clip plane, and intersecting these rays gives the rendered image's depth and ids."""
    scene = tp02(40, 30)
    mitsuba.import_mitsuba(variant)
    mi_scene, ids = mitsuba.load(scene, variant)
    rows, columns = np.divmod(np.arange(40 * 30), 40)
    origins, directions = mitsuba.primary_rays(mi_scene, scene, rows, columns)
    _, pixel_directions = oracle.camera_rays(scene)
    angle = error_model.angle_between(directions, pixel_directions.reshape(-1, 3))
    assert angle.max() <= 6 * EPSILON
    near, _ = mitsuba.clip_range(scene)
    eye = np.array(scene.camera.eye)
    along = np.linalg.norm(origins - eye, axis=1)
    cos_axis = mitsuba.axis_cosines(scene).ravel()
    np.testing.assert_allclose(along, near / cos_axis, rtol=0, atol=4 * EPSILON * np.linalg.norm(eye))

    hits = mitsuba.intersect(mi_scene, ids, origins, directions)
    image = mitsuba.render(scene, variant)
    np.testing.assert_array_equal(hits["id"], image["id"].ravel())
    found = hits["id"] >= 0
    truth = oracle.trace(scene, origins, directions / np.linalg.norm(directions, axis=1, keepdims=True))
    cos = oracle.incidence_cosine(scene, directions, truth["id"], truth["normal"])
    with np.errstate(invalid="ignore"):  # inf - inf on a miss
        depth_error = np.abs(hits["depth"] + along - image["depth"].ravel())
    scale = error_model.world_sizes(scene, scene.camera.eye)[np.maximum(hits["id"], 0)]
    tolerance = 4 * EPSILON * (hits["depth"] + scale) / cos
    assert np.all(depth_error[found] <= tolerance[found])


def test_intersect_in_both_variants_agree():
    """The same rays through ray_intersect in scalar_rgb (float64 sphere solve) and llvm_ad_rgb
    (float32): within the model's bound for two float32 world-coordinate intersections."""
    scene = tp02(32, 24)
    rows, columns = np.divmod(np.arange(32 * 24), 32)
    mitsuba.import_mitsuba("scalar_rgb")
    mi_scene, ids = mitsuba.load(scene, "scalar_rgb")
    origins, directions = mitsuba.primary_rays(mi_scene, scene, rows, columns)
    scalar = mitsuba.intersect(mi_scene, ids, origins, directions)
    mitsuba.import_mitsuba("llvm_ad_rgb")
    mi_scene, ids = mitsuba.load(scene, "llvm_ad_rgb")
    llvm = mitsuba.intersect(mi_scene, ids, origins, directions)
    np.testing.assert_array_equal(scalar["id"], llvm["id"])
    found = scalar["id"] >= 0
    truth = oracle.trace(scene, origins, directions / np.linalg.norm(directions, axis=1, keepdims=True))
    cos = oracle.incidence_cosine(scene, directions, truth["id"], truth["normal"])
    scale = error_model.world_sizes(scene, scene.camera.eye)[np.maximum(scalar["id"], 0)]
    tolerance = 4 * EPSILON * (scalar["depth"] + scale) / cos
    with np.errstate(invalid="ignore"):  # inf - inf on a miss
        depth_error = np.abs(scalar["depth"] - llvm["depth"])
    assert np.all(depth_error[found] <= tolerance[found])
    assert np.all(np.isinf(llvm["depth"][~found])) and np.all(llvm["normal"][~found] == 0)
