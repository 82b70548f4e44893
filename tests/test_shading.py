"""Shading, shadows and the zdepth/position AOVs against the float64 reference; the scene model of
lights and materials; what the kernel compiles in.

Tolerances: the error model bounds the hit point along the ray (depth_tolerance: K eps (t + L) / cos,
L the size of the frame coordinates of the hit shape) and the normal (K eps + that / r); the shading
model is a smooth function of both, and pyclray.reference.shading.tolerance turns those bounds, term by term,
into a bound on the shaded colour (its docstring writes the terms out). Pixels outside the model are
left out, each for its reason: silhouettes and near ties (the error model's rules), the terminator of
a light with a specular term (where the model itself jumps), and shadow edges (where a hit point moved
by the test's blur changes the float64 visibility).
"""
import re

import numpy as np
import pytest

import pyclray
from pyclray import SceneError
from pyclray.engine.scene.lighting import shadow_reach
from pyclray.reference import error_model, oracle, shading
from pyclray.engine.launch.programs import Variant
from pyclray.model.lights import DirectionalLight, Material, PointLight, Shading
from pyclray.model.shapes import REGISTRY, Box, Disk, Plane, Sphere

K = 4.0  # the error model's K against the float64 oracle
EPS = {"fp32": 2.0**-24, "fp64": 2.0**-53}


def reference(scene, precision="fp32"):
    """The float64 hits, visibility per light and its shadow edges: where the float64 visibility
    changes when the hit point moves by 4 times how far the kernel's shadow ray may start from it,
    16 eps |p| (engine.scene.lighting.shadow_reach; |p| from the eye, whatever the shape's size)."""
    ref = error_model.reference(scene)
    O, D = ref["origins"], ref["directions"]
    ref["points"] = O + np.where(np.isfinite(ref["depth"]), ref["depth"], 0)[..., None] * D
    blur = 4 * shadow_reach(np.linalg.norm(ref["points"] - O, axis=-1), EPS[precision])
    V, edges = shading.reference_visibility(scene, ref["points"], ref["normal"], D, ref["id"], blur=blur)
    if not scene.shading.shadows:  # no shadow rays: every light reaches every point
        V, edges = [np.ones_like(v) for v in V], np.zeros_like(edges)
    ref["visibility"], ref["shadow_edge"] = V, np.any(edges, axis=0)
    return ref


def bounds(scene, ref, precision="fp32"):
    """(depth, normal) tolerances of pyclray's render per pixel: the error model's
    (pyclray.reference.error_model.pyclray_tolerances, the frame centred on the eye)."""
    return error_model.pyclray_tolerances(scene, ref, ref["cos"], ref["origins"], precision, scene.camera.eye)


def compare_shaded(scene, precision="fp32"):
    """Render shaded (and id), compare with the float64 model on the judged pixels; returns counts."""
    ref = reference(scene, precision)
    frame = pyclray.render(scene, aovs=("depth", "id", "shaded"), precision=precision)
    expected = shading.reference_shading(scene, ref["directions"], ref, ref["visibility"])
    depth_tol, normal_tol = bounds(scene, ref, precision)
    tol, jump = shading.tolerance(scene, ref["directions"], ref, depth_tol, normal_tol, EPS[precision])
    masks = error_model.judged_pixels(frame, ref, precision)  # silhouettes, near ties, edges
    outside = masks["silhouette"] | masks["near_tie"] | masks["edge"]
    assert not (frame["id"] != ref["id"])[~outside].any()  # ids are the image tests' business, but hold here
    judged = ~(outside | jump | ref["shadow_edge"])
    error = np.abs(frame["shaded"].astype(np.float64) - expected).max(axis=-1)
    assert np.all(error[judged] <= tol[judged]), (error[judged] / tol[judged]).max()
    hit = judged & (ref["id"] >= 0)
    lit = np.zeros(hit.shape, bool)
    for V in ref["visibility"]:
        lit |= V > 0
    return {"judged": int(judged.sum()), "lit": int((hit & lit).sum()), "shadowed": int((hit & ~lit).sum()),
            "worst": float((error[judged] / np.maximum(tol[judged], 1e-300)).max()), "frame": frame, "ref": ref}


# -- the scene model ---------------------------------------------------------------------------------
BASE = """
[camera]
eye = [0.0, 2.0, 6.0]
target = [0.0, 0.5, 0.0]
fov = 45.0

[[shapes]]
type = "sphere"
center = [0.0, 1.0, 0.0]
radius = 1.0
"""


def load(tmp_path, extra):
    path = tmp_path / "scene.toml"
    path.write_text(BASE + extra)
    return pyclray.load_scene(path)


def test_lights_materials_and_shading_load(tmp_path):
    scene = load(tmp_path, """
color = [0.8, 0.2, 0.2]
specular = 0.5
shininess = 10

[[lights]]
type = "point"
name = "key"
position = [2.0, 4.0, 3.0]
intensity = 10.0

[[lights]]
type = "directional"
direction = [-1.0, -2.0, -1.0]
irradiance = [1.0, 0.5, 0.25]

[shading]
ambient = 0.05
background = [0.1, 0.2, 0.3]
shadows = false
""")
    assert scene.shapes[0].material == Material((0.8, 0.2, 0.2), 0.5, 10.0)
    assert scene.lights == (PointLight((2.0, 4.0, 3.0), (10.0, 10.0, 10.0), "key"),
                            DirectionalLight((-1.0, -2.0, -1.0), (1.0, 0.5, 0.25), "light1"))
    assert scene.shading == Shading((0.05, 0.05, 0.05), (0.1, 0.2, 0.3), False)


def test_defaults_and_the_headlight(tmp_path):
    scene = load(tmp_path, "")
    assert scene.shapes[0].material == Material((0.8, 0.8, 0.8), 0.0, 32.0)
    assert scene.lights == () and scene.shading == Shading((0, 0, 0), (0, 0, 0), True)
    (light,) = pyclray.model.lights.effective_lights(scene)
    np.testing.assert_allclose(light.direction, scene.camera.basis()[2])
    assert light.irradiance == (1.0, 1.0, 1.0)


@pytest.mark.parametrize(
    "extra, table, key, words",
    [
        ('[[lights]]\ntype = "point"\nposition = [0, 1, 0]\nintensity = -1.0\n', "[[lights]] #0 (point)", "intensity", ">= 0"),
        ('[[lights]]\ntype = "point"\nposition = [0, 1, 0]\nintensity = [1, -1, 1]\n', "[[lights]] #0 (point)", "intensity", ">= 0"),
        ('[[lights]]\ntype = "directional"\ndirection = [0, 0, 0]\nirradiance = 1.0\n', "[[lights]] #0 (directional)", "direction", "non-zero"),
        ('[[lights]]\ntype = "spot"\n', "[[lights]] #0", "type", "unknown light type"),
        ('[[lights]]\ntype = "point"\nposition = [0, 1, 0]\nintensity = 1.0\ncolour = 1\n', "[[lights]] #0 (point)", "colour", "unknown key"),
        ('[[lights]]\ntype = "point"\nposition = [0, 1, 0]\n', "[[lights]] #0 (point)", "intensity", "missing"),
        ('[[lights]]\ntype = "point"\nname = "a"\nposition = [0, 1, 0]\nintensity = 1.0\n'
         '[[lights]]\ntype = "directional"\nname = "a"\ndirection = [0, -1, 0]\nirradiance = 1.0\n',
         "[[lights]] #1 (directional)", "name", "already used"),
        ("[shading]\nambient = -0.1\n", "[shading]", "ambient", ">= 0"),
        ("[shading]\nbackground = 0.5\n", "[shading]", "background", "3 numbers"),
        ("[shading]\nshadows = 1\n", "[shading]", "shadows", "true or false"),
        ("[shading]\nfog = 1\n", "[shading]", "fog", "unknown key"),
    ],
)
def test_bad_lights_and_shading_are_one_line_errors(tmp_path, extra, table, key, words):
    with pytest.raises(SceneError) as info:
        load(tmp_path, extra)
    error = info.value
    assert (error.table, error.key) == (table, key), str(error)
    assert words in str(error) and "\n" not in str(error) and "scene.toml" in str(error)


@pytest.mark.parametrize(
    "line, key, words",
    [("color = [1.2, 0.5, 0.5]", "color", "[0, 1]"), ("color = [-0.1, 0.5, 0.5]", "color", "[0, 1]"),
     ("color = 0.5", "color", "3 numbers"), ("specular = 2.0", "specular", "[0, 1]"),
     ("shininess = 0.0", "shininess", "> 0"), ("colr = [1, 1, 1]", "colr", "unknown key")],
)
def test_bad_materials_are_one_line_errors(tmp_path, line, key, words):
    with pytest.raises(SceneError) as info:
        load(tmp_path, line + "\n")
    assert (info.value.table, info.value.key) == ("[[shapes]] #0 (sphere)", key), str(info.value)
    assert words in str(info.value)


# -- what is compiled in -------------------------------------------------------------------------------
def code(source: str) -> str:
    """The program without its comments."""
    return re.sub(r"/\*.*?\*/", "", source, flags=re.S)


def test_a_depth_only_render_has_no_shading_code():
    variant = Variant("render", ("plane", "sphere"), ("depth",), "fp32", 8)
    source = code(variant.source())
    # no material or light struct, no shading function, no shading macro, no shadow switch
    for word in ("} Material;", "} Light;", "shade_light(", "space_from_world(", "PYCLRAY_WRITE_SHADED(index, first, end)  ",
                 "#define PYCLRAY_SHADOWS"):
        assert word not in source, word
    assert "#define PYCLRAY_WRITE_SHADED(index, first, end)\n" in source  # the empty one
    shaded = code(Variant("render", ("plane", "sphere"), ("shaded",), "fp32", 8).source())
    assert "} Material;" in shaded and "shade_light(" in shaded and "#define PYCLRAY_SHADOWS" not in shaded


def test_a_shaded_render_without_shadows_casts_no_shadow_rays(scenes_dir):
    from pyclray.engine.opencl.device import context_for
    from pyclray.engine.launch.programs import kernel_for

    scene = pyclray.load_scene(scenes_dir / "tp02-lit.toml").with_size(16, 16)
    no_shadows = Variant("render", scene.shape_types(), ("shaded",), "fp32", 8, shadows=False)
    shadows = Variant("render", scene.shape_types(), ("shaded",), "fp32", 8, shadows=True)
    assert "#define PYCLRAY_SHADOWS 1" not in no_shadows.source()
    assert "#define PYCLRAY_SHADOWS 1" in shadows.source()
    # the shadow rays' arguments (every shape type's count) exist only in the program with shadows
    ctx = context_for(None)
    types = len(scene.shape_types())
    assert kernel_for(ctx, shadows).num_args == kernel_for(ctx, no_shadows).num_args + types
    # and render picks the program from the scene's [shading]
    from dataclasses import replace

    dark = pyclray.render(scene, aovs=("shaded",))["shaded"]
    bright = pyclray.render(replace(scene, shading=replace(scene.shading, shadows=False)), aovs=("shaded",))["shaded"]
    assert (bright >= dark).all() and (bright > dark).any()


# -- zdepth and position ------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["tp02", "far"])
def test_zdepth_and_position_match_the_oracle(scenes_dir, name):
    scene = pyclray.load_scene(scenes_dir / f"{name}.toml").with_size(64, 48)
    frame = pyclray.render(scene, aovs=("depth", "id", "zdepth", "position"))
    ref = error_model.reference(scene)
    w = scene.camera.basis()[2]
    outside = error_model.judged_pixels(frame, ref, "fp32")
    judged = ~(outside["silhouette"] | outside["near_tie"] | outside["edge"]) & (ref["id"] >= 0)
    assert (frame["id"] == ref["id"])[judged].all()
    depth_tol, _ = bounds(scene, ref)
    zdepth = ref["depth"] * np.einsum("...k,k", ref["directions"], w)
    # zdepth = depth cos(ray, w): the depth's bound times cos plus the one more rounding
    with np.errstate(invalid="ignore"):  # inf - inf on misses, which are not judged
        z_err = np.abs(frame["zdepth"] - zdepth)
    assert np.all(z_err[judged] <= depth_tol[judged] + 2 * EPS["fp32"] * zdepth[judged])
    points = ref["origins"] + np.where(np.isfinite(ref["depth"]), ref["depth"], 0)[..., None] * ref["directions"]
    # the position: the hit's bound along the ray, plus the rounding of eye + offset to float32 (1 ulp)
    p_err = np.linalg.norm(frame["position"] - points, axis=-1)
    allowed = depth_tol + 2 * EPS["fp32"] * np.linalg.norm(points, axis=-1) * np.sqrt(3)
    assert np.all(p_err[judged] <= allowed[judged]), (p_err / allowed)[judged].max()
    miss = ref["id"] < 0
    assert np.all(np.isinf(frame["zdepth"][miss & (frame["id"] < 0)]))
    assert np.all(frame["position"][frame["id"] < 0] == 0)


# -- shading and shadows against the float64 reference ------------------------------------------------
def test_tp02_lit_matches_the_float64_model(scenes_dir):
    scene = pyclray.load_scene(scenes_dir / "tp02-lit.toml").with_size(96, 96)
    result = compare_shaded(scene)
    assert result["lit"] > 1000 and result["shadowed"] > 100, result
    miss = result["ref"]["id"] < 0
    assert np.all(result["frame"]["shaded"][miss & (result["frame"]["id"] < 0)] == np.array([0.02, 0.02, 0.03], np.float32))


POINT_KEYS = ("center", "p0", "p1", "point", "position")  # the keys that are points (moved by a shift)


def test_every_shape_type_is_shaded_as_the_float64_model(scenes_dir):
    """shapes-lit holds every type of the registry; shading knows none of them by name."""
    scene = pyclray.load_scene(scenes_dir / "shapes-lit.toml").with_size(96, 72)
    assert set(scene.shape_types()) == set(REGISTRY)
    result = compare_shaded(scene)
    judged_ids = set(np.unique(result["ref"]["id"][result["ref"]["id"] >= 0]))
    assert judged_ids == set(range(len(scene.shapes))) and result["shadowed"] > 100


def lit_scene(shapes, lights, camera, size=80, shift=(0.0, 0.0, 0.0)):
    """A scene from shape and light tables (as in a scene file), everything moved by shift; white
    diffuse surfaces, no ambient term."""
    shift = np.array(shift)

    def moved(table):
        return {k: (list(np.add(v, shift)) if k in POINT_KEYS else v) for k, v in table.items()}

    eye, target = camera
    return pyclray.scene_from_dict({
        "camera": {"eye": list(np.add(eye, shift)), "target": list(np.add(target, shift)), "fov": 50.0},
        "image": {"width": size, "height": size},
        "shapes": [dict(moved(t), color=[1.0, 1.0, 1.0]) for t in shapes],
        "lights": [moved(t) for t in lights],
    })


def ground(y=0.0):
    return {"type": "plane", "normal": [0.0, 1.0, 0.0], "point": [0.0, y, 0.0]}


def ball(center, radius):
    return {"type": "sphere", "center": list(center), "radius": radius}


SHADOW_SCENES = {
    # a sphere resting on a plane: the contact point and the shadow's wedge around it
    "sphere-on-plane": ((ground(), ball((0, 1, 0), 1.0)),
                        ({"type": "point", "position": [2.0, 5.0, 1.0], "intensity": 30.0},), ((0, 3, 6), (0, 0.5, 0))),
    # a ball on a huge ground sphere (the shadow test from the ground works with coordinates of 1e4)
    "huge-ground-sphere": ((ball((0, -1e4, 0), 1e4), ball((0, 0.5, 0), 0.5)),
                           ({"type": "directional", "direction": [-1.0, -0.8, -0.5], "irradiance": 1.0},),
                           ((0, 2, 4), (0, 0.3, 0))),
    # the camera close to the ground, looking along it: the shadows of two balls run to the horizon
    "grazing": ((ground(), ball((-1, 0.5, -3), 0.5), ball((1.5, 1, -8), 1)),
                ({"type": "directional", "direction": [0.3, -0.4, 1.0], "irradiance": 1.0},), ((0, 0.4, 3), (0, 0.2, -5))),
    # a rotated box standing on a disk: faces flush with the disk, edges along it
    "box-on-disk": (({"type": "disk", "center": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0], "radius": 3.0},
                     {"type": "box", "center": [0.0, 0.5, 0.0], "size": [1.0, 1.0, 1.2], "axis": [0.0, 1.0, 0.0], "angle": 30.0}),
                    ({"type": "point", "position": [2.5, 4.0, 1.5], "intensity": 25.0},), ((1, 3, 5), (0, 0.3, 0))),
}


@pytest.mark.parametrize("shift", [0.0, 1e5], ids=["at-origin", "moved-1e5"])
@pytest.mark.parametrize("name", list(SHADOW_SCENES))
def test_lit_regions_are_lit_and_shadowed_regions_shadowed(name, shift):
    shapes, lights, camera = SHADOW_SCENES[name]
    scene = lit_scene(shapes, lights, camera, shift=(shift, 0.5 * shift, -shift))
    result = compare_shaded(scene)
    assert result["lit"] > 300 and result["shadowed"] > 100, {k: v for k, v in result.items() if k not in ("frame", "ref")}


def test_fp64_shading_matches_the_float64_model(scenes_dir):
    from pyclray.engine.opencl.device import context_for, has_fp64

    if not has_fp64(context_for(None).device):
        pytest.skip("device lacks cl_khr_fp64")
    scene = pyclray.load_scene(scenes_dir / "tp02-lit.toml").with_size(48, 48)
    result = compare_shaded(scene, precision="fp64")
    assert result["lit"] > 200, result["lit"]


# -- outputs -------------------------------------------------------------------------------------------
def test_render_command_writes_the_new_channels_and_previews(scenes_dir, tmp_path):
    from pyclray.apps.cli import main
    from pyclray.io import exr

    out = tmp_path / "lit.exr"
    aovs = "depth,id,zdepth,position,shaded"
    assert main(["render", str(scenes_dir / "tp02-lit.toml"), "-o", str(out), "--aov", aovs, "--png", "--size", "40x30"]) == 0
    scene = pyclray.load_scene(scenes_dir / "tp02-lit.toml").with_size(40, 30)
    frame = pyclray.render(scene, aovs=aovs)
    back = exr.read_exr(out)
    assert set(back) == set(frame)
    for name in frame:  # the file holds the render's images bit for bit
        np.testing.assert_array_equal(back[name], frame[name])
    for name in ("depth", "id", "zdepth", "shaded"):
        assert (tmp_path / f"lit.{name}.png").is_file()
    assert not (tmp_path / "lit.position.png").exists()  # positions have no preview


def test_previews():
    from pyclray.io import png

    # shaded: clamped, sRGB-encoded (0.5 linear -> 188)
    rgb = png.srgb_preview(np.array([[[-1.0, 0.5, 2.0], [0.0031308, 1.0, np.nan]]]))
    assert rgb.tolist() == [[[0, 188, 255], [10, 255, 0]]]
    # id: misses black, every id its own colour, none black
    ids = np.arange(-1, 64).reshape(5, 13)
    image = png.id_preview(ids)
    assert (image[ids < 0] == 0).all()
    colours = {tuple(c) for c in image[ids >= 0]}
    assert len(colours) == 64 and (0, 0, 0) not in colours


# -- against Mitsuba 3's direct integrator --------------------------------------------------------------
# llvm_ad_rgb aborts in its LLVM back end on a directional emitter (Mitsuba 3.9.1, AVX-512: "Cannot
# select" an fma of v16f32), so the headlight (directional) is checked in scalar_rgb
@pytest.mark.parametrize("name, variant", [("tp02-lit", "llvm_ad_rgb"), ("tp02", "scalar_rgb"), ("shapes-lit", "scalar_rgb")])
def test_shaded_equals_mitsuba_direct_up_to_pi(scenes_dir, name, variant):
    """Point lights with shadows (tp02-lit) and the headlight, a directional light (tp02): the
    tolerance is the sum of both engines' bounds (pyclray.reference.validation.shaded)."""
    pytest.importorskip("mitsuba")
    from pyclray.reference.validation import shaded as shaded_check

    scene = pyclray.load_scene(scenes_dir / f"{name}.toml").with_size(64, 48)
    result = shaded_check.cross_check_shaded(scene, variant)
    assert result.passed, shaded_check.format_shaded_check(result)
    assert result.lit > 1500 and result.worst <= 1.0
    assert result.left_out["shadow edge"] < 0.01 * 64 * 48
    if name == "tp02-lit":
        assert result.shadowed > 50


@pytest.mark.parametrize("name", ["tp02-lit", "shapes-lit", "sun"])
def test_shadows_through_the_bvh_equal_the_tested_every_shape(scenes_dir, name):
    """With the BVH (large scenes) shadow rays find their occluders through its any-hit packet
    traversal; with tile lists they test every shape. The shape tests are the same, and the BVH must
    drop none that a ray would hit: the images are equal bit for bit (also with many spheres)."""
    scene = pyclray.load_scene(scenes_dir / f"{name}.toml").with_size(64, 48)
    tiles = pyclray.render(scene, aovs=("id", "shaded"), acceleration="tiles")
    through_bvh = pyclray.render(scene, aovs=("id", "shaded"), acceleration="bvh")
    np.testing.assert_array_equal(tiles["id"], through_bvh["id"])
    np.testing.assert_array_equal(tiles["shaded"], through_bvh["shaded"])


def test_shadows_of_many_spheres_through_the_bvh():
    rng = np.random.default_rng(7)
    shapes = [ground()] + [ball(rng.uniform([-6, 0.2, -12], [6, 3, 0]), float(rng.uniform(0.1, 0.6))) for _ in range(300)]
    lights = ({"type": "point", "position": [3.0, 8.0, 2.0], "intensity": 80.0},
              {"type": "directional", "direction": [-0.5, -1.0, -0.3], "irradiance": 0.5})
    scene = lit_scene(shapes, lights, ((0, 4, 6), (0, 1, -5)), size=64)
    tiles = pyclray.render(scene, aovs=("shaded",), acceleration="tiles")["shaded"]
    through_bvh = pyclray.render(scene, aovs=("shaded",), acceleration="bvh")["shaded"]
    np.testing.assert_array_equal(tiles, through_bvh)
    assert (tiles == 0).all(axis=-1).mean() > 0.05  # shadows there are


def test_the_srgb_preview_of_float32_is_the_formulas_bit_for_bit():
    """io/png.py looks float32 up in tables (pyclray view's frames): the same levels as the float64
    formula on both sides of every step, on random values in and around [0, 1], and the specials."""
    from pyclray.io import png

    _, _, thr = png._srgb_tables()
    steps = thr[np.isfinite(thr)].view(np.uint32).astype(np.int64)
    assert len(steps) == 255  # one per level
    near = (steps[:, None] + np.arange(-3, 4)).astype(np.uint32).view(np.float32).ravel()
    rng = np.random.default_rng(24)
    values = np.concatenate([near, rng.integers(0, 0x3F800001, 2_000_000, dtype=np.uint32).view(np.float32),
                             rng.uniform(-0.5, 1.5, 1_000_000).astype(np.float32),
                             np.array([np.nan, -np.nan, np.inf, -np.inf, 0.0, -0.0, 1.0, 2.0, 3e38, -1e-45, 1e-45,
                                       0.0031308, np.float32(0.0031308) * 1.0000001], np.float32)])
    with np.errstate(invalid="ignore"):
        assert np.array_equal(png.srgb_preview(values), png._srgb_levels(values))
    image = rng.uniform(0, 1, (7, 5, 3)).astype(np.float32)[:, ::2]  # not contiguous
    assert np.array_equal(png.srgb_preview(image), png._srgb_levels(image))
