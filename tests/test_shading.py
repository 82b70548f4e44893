"""Shading, shadows and the zdepth/position AOVs against the float64 reference; the scene model of
lights and materials; what the kernel compiles in.

Tolerances: the error model bounds the hit point along the ray (depth_tolerance: K eps (t + L) / cos,
L the size of the frame coordinates of the hit shape) and the normal (K eps + that / r); the shading
model is a smooth function of both, and pyclray.shading.tolerance turns those bounds, term by term,
into a bound on the shaded colour (its docstring writes the terms out). Pixels outside the model are
left out, each for its reason: silhouettes and near ties (the error model's rules), the terminator of
a light with a specular term (where the model itself jumps), and shadow edges (where a hit point moved
by the test's blur changes the float64 visibility).
"""
import re

import numpy as np
import pytest

import pyclray
from pyclray import SceneError, accuracy, oracle, shading
from pyclray.device import Variant
from pyclray.lighting import DirectionalLight, Material, PointLight, Shading
from pyclray.shapes import Plane, Sphere

K = 4.0  # the error model's K against the float64 oracle
EPS = {"fp32": 2.0**-24, "fp64": 2.0**-53}


def reference(scene, blur):
    """The float64 hits, visibility per light, its shadow edges (blur: how far a hit point is moved
    to find them, scene units) and the error model's bounds on depth and normal."""
    ref = accuracy.reference(scene)
    O, D = ref["origins"], ref["directions"]
    ref["points"] = O + np.where(np.isfinite(ref["depth"]), ref["depth"], 0)[..., None] * D
    V, edges = shading.reference_visibility(scene, ref["points"], ref["normal"], D, ref["id"], blur=blur)
    ref["visibility"], ref["shadow_edge"] = V, np.any(edges, axis=0)
    return ref


def bounds(scene, ref, precision="fp32"):
    """(depth, normal) tolerances of pyclray's render per pixel, from the error model: its frame is
    the eye's, so L = |anchor - eye| (a sphere's centre; a plane: the eye's distance to it)."""
    eye = np.array(scene.camera.eye)
    sizes = []
    for shape in scene.shapes:
        if isinstance(shape, Sphere):
            sizes.append(np.linalg.norm(np.subtract(shape.center, eye)))
        else:
            n, h = shape.unit()
            sizes.append(abs(float(n @ eye + h)))
    index = np.maximum(ref["id"], 0)
    t = np.where(np.isfinite(ref["depth"]), ref["depth"], 0.0)
    radius = np.array([getattr(s, "radius", np.inf) for s in scene.shapes])[index]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = K * EPS[precision] * (t + np.array(sizes)[index]) / ref["cos"]
        depth = depth + K * EPS["fp64"] * (t + np.linalg.norm(eye)) / ref["cos"]
        normal = K * EPS[precision] + depth / radius
    return depth, normal


def compare_shaded(scene, precision="fp32", blur=1e-3):
    """Render shaded (and id), compare with the float64 model on the judged pixels; returns counts."""
    ref = reference(scene, blur)
    frame = pyclray.render(scene, aovs=("id", "shaded"), precision=precision)
    expected = shading.reference_shading(scene, ref["directions"], ref, ref["visibility"])
    depth_tol, normal_tol = bounds(scene, ref, precision)
    tol, jump = shading.tolerance(scene, ref["directions"], ref, depth_tol, normal_tol, EPS[precision])
    near_tie = ref["near_tie"] if "near_tie" in ref else np.zeros(jump.shape, bool)
    judged = ~(ref["silhouette"] | near_tie | jump | ref["shadow_edge"]) & (frame["id"] == ref["id"])
    assert (frame["id"] != ref["id"])[~(ref["silhouette"] | near_tie)].sum() <= 0.002 * frame["id"].size
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
    (light,) = pyclray.lighting.effective_lights(scene)
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
    for word in ("} Material;", "} Light;", "shade_light(", "frame_from_world(", "PYCLRAY_WRITE_SHADED(index, first, end)  ",
                 "#define PYCLRAY_SHADOWS"):
        assert word not in source, word
    assert "#define PYCLRAY_WRITE_SHADED(index, first, end)\n" in source  # the empty one
    shaded = code(Variant("render", ("plane", "sphere"), ("shaded",), "fp32", 8).source())
    assert "} Material;" in shaded and "shade_light(" in shaded and "#define PYCLRAY_SHADOWS" not in shaded


def test_a_shaded_render_without_shadows_casts_no_shadow_rays(scenes_dir):
    from pyclray.device import context_for, kernel_for

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
    ref = accuracy.reference(scene)
    w = scene.camera.basis()[2]
    judged = (frame["id"] == ref["id"]) & ~ref["silhouette"] & (ref["id"] >= 0)
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


def lit_scene(shapes, lights, camera, size=80, shift=(0.0, 0.0, 0.0), ambient=0.0):
    """A scene moved by shift (camera, shapes and point lights), white diffuse surfaces."""
    shift = np.array(shift)

    def moved(p):
        return tuple(np.array(p) + shift)

    white = Material((1.0, 1.0, 1.0))
    placed = []
    for shape in shapes:
        if isinstance(shape, Sphere):
            placed.append(Sphere(moved(shape.center), shape.radius, shape.name, material=white))
        else:  # normal . (p - shift) + offset = 0
            placed.append(Plane(shape.normal, shape.offset - float(np.dot(shape.normal, shift)), shape.name, material=white))
    lights = tuple(PointLight(moved(l.position), l.intensity, l.name) if isinstance(l, PointLight) else l for l in lights)
    eye, target = camera
    return pyclray.Scene(pyclray.Camera(moved(eye), moved(target), (0, 1, 0), 50.0), pyclray.Image(size, size),
                         tuple(placed), lights=lights, shading=Shading(ambient=ambient))


SHADOW_SCENES = {
    # a sphere resting on a plane: the contact point and the shadow's wedge around it
    "sphere-on-plane": ((Plane((0, 1, 0), 0.0, "ground"), Sphere((0, 1, 0), 1.0, "ball")),
                        (PointLight((2.0, 5.0, 1.0), (30, 30, 30), "key"),), ((0, 3, 6), (0, 0.5, 0))),
    # a ball on a huge ground sphere (the shadow test from the ground works with coordinates of 1e4)
    "huge-ground-sphere": ((Sphere((0, -1e4, 0), 1e4, "ground"), Sphere((0, 0.5, 0), 0.5, "ball")),
                           (DirectionalLight((-1.0, -0.8, -0.5), (1, 1, 1), "sun"),), ((0, 2, 4), (0, 0.3, 0))),
    # the camera close to the ground, looking along it: the shadows of two balls run to the horizon
    "grazing": ((Plane((0, 1, 0), 0.0, "ground"), Sphere((-1, 0.5, -3), 0.5, "a"), Sphere((1.5, 1, -8), 1, "b")),
                (DirectionalLight((0.3, -0.4, 1.0), (1, 1, 1), "low sun"),), ((0, 0.4, 3), (0, 0.2, -5))),
}


@pytest.mark.parametrize("shift", [0.0, 1e5], ids=["at-origin", "moved-1e5"])
@pytest.mark.parametrize("name", list(SHADOW_SCENES))
def test_lit_regions_are_lit_and_shadowed_regions_shadowed(name, shift):
    shapes, lights, camera = SHADOW_SCENES[name]
    scene = lit_scene(shapes, lights, camera, shift=(shift, 0.5 * shift, -shift))
    # shadow edges: where the float64 visibility changes when the hit point moves by the shadow
    # ray's own offset (16 eps (|p| + R), R up to the huge sphere's 1e4), four times over
    extent = max(shading.shape_extent(s) for s in scene.shapes)
    blur = 4 * 16 * EPS["fp32"] * (10 + extent) + 1e-6
    result = compare_shaded(scene, blur=blur)
    assert result["lit"] > 300 and result["shadowed"] > 100, {k: v for k, v in result.items() if k not in ("frame", "ref")}


def test_fp64_shading_matches_the_float64_model(scenes_dir):
    from pyclray.device import context_for, has_fp64

    if not has_fp64(context_for(None).device):
        pytest.skip("device lacks cl_khr_fp64")
    scene = pyclray.load_scene(scenes_dir / "tp02-lit.toml").with_size(48, 48)
    result = compare_shaded(scene, precision="fp64", blur=1e-6)
    assert result["lit"] > 200, result["lit"]


# -- outputs -------------------------------------------------------------------------------------------
def test_render_command_writes_the_new_channels_and_previews(scenes_dir, tmp_path):
    from pyclray import output
    from pyclray.cli import main

    out = tmp_path / "lit.exr"
    aovs = "depth,id,zdepth,position,shaded"
    assert main(["render", str(scenes_dir / "tp02-lit.toml"), "-o", str(out), "--aov", aovs, "--png", "--size", "40x30"]) == 0
    scene = pyclray.load_scene(scenes_dir / "tp02-lit.toml").with_size(40, 30)
    frame = pyclray.render(scene, aovs=aovs)
    back = output.read_exr(out)
    assert set(back) == set(frame)
    for name in frame:  # the file holds the render's images bit for bit
        np.testing.assert_array_equal(back[name], frame[name])
    for name in ("depth", "id", "zdepth", "shaded"):
        assert (tmp_path / f"lit.{name}.png").is_file()
    assert not (tmp_path / "lit.position.png").exists()  # positions have no preview


def test_previews():
    from pyclray import output

    # shaded: clamped, sRGB-encoded (0.5 linear -> 188)
    rgb = output.srgb_preview(np.array([[[-1.0, 0.5, 2.0], [0.0031308, 1.0, np.nan]]]))
    assert rgb.tolist() == [[[0, 188, 255], [10, 255, 0]]]
    # id: misses black, every id its own colour, none black
    ids = np.arange(-1, 64).reshape(5, 13)
    image = output.id_preview(ids)
    assert (image[ids < 0] == 0).all()
    colours = {tuple(c) for c in image[ids >= 0]}
    assert len(colours) == 64 and (0, 0, 0) not in colours


# -- against Mitsuba 3's direct integrator --------------------------------------------------------------
# llvm_ad_rgb aborts in its LLVM back end on a directional emitter (Mitsuba 3.9.1, AVX-512: "Cannot
# select" an fma of v16f32), so the headlight (directional) is checked in scalar_rgb
@pytest.mark.parametrize("name, variant", [("tp02-lit", "llvm_ad_rgb"), ("tp02", "scalar_rgb")])
def test_shaded_equals_mitsuba_direct_up_to_pi(scenes_dir, name, variant):
    """Point lights with shadows (tp02-lit) and the headlight, a directional light (tp02): the
    tolerance is the sum of both engines' bounds (pyclray.shaded_check)."""
    pytest.importorskip("mitsuba")
    from pyclray import shaded_check

    scene = pyclray.load_scene(scenes_dir / f"{name}.toml").with_size(64, 64)
    result = shaded_check.cross_check_shaded(scene, variant)
    assert result.passed, shaded_check.format_shaded_check(result)
    assert result.lit > 2000 and result.worst <= 1.0
    assert result.left_out["shadow edge"] < 0.01 * 64 * 64
    if name == "tp02-lit":
        assert result.shadowed > 50
