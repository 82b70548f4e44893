"""Every AOV of every camera model against the float64 oracle, and the shaded image of a render by
casting (the orthographic camera: engine/queries/shade.py) held to the render kernel's own.

Each model renders a lit scene (a point and a directional light, shadows, ambient, a background, a
specular ball, a smooth mesh, a batch of spheres, labels) with every AOV it has, in fp32, fp64 and
with PYCLRAY_LANES=1; per pixel in the model's field:
- depth, normal, id: the oracle of the model's own float64 rays within the error model
  (oracle_checks.assert_agrees_with_oracle: a render's bounds in the eye's frame, a cast's for the
  orthographic camera, whose rays start apart);
- primitive and barycentric: the oracle's triangle or batch sphere, and its (u, v) within the
  precision's rounding relative to the triangle (as tests/test_mesh.py);
- label: the hit shape's, exactly; position and zdepth: the oracle's hit point and its depth along
  w, within the depth tolerance;
- shaded: the float64 shading model (pyclray.reference.shading) at the oracle's hits, within
  shading.tolerance of the error model's bounds on the hit and the normal; terminators of the
  specular term and shadow edges (the float64 visibility changes within 4 times the larger of the
  two shadow-ray offsets: the kernel's 16 eps |p|, the cast path's 16 (eps t + eps64 (|p|_1 + R)),
  R the hit shape's size) left out.
Pixels beyond a model's field are misses in every image (the background in shaded)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import pyclray
from pyclray.engine.queries.render import start_cast_view
from pyclray.engine.queries.shade import shadow_offset, shape_sizes
from pyclray.engine.scene.lighting import shadow_reach
from pyclray.model.aovs import RENDER_AOVS
from pyclray.model.shapes.mesh_shapes import perturbed_sphere
from pyclray.reference import error_model, shading

from oracle_checks import assert_agrees_with_oracle, judge
from test_lenses import looking_at, needs_fp64

WIDTH, HEIGHT = 64, 48
EPS = {"fp32": 2.0**-24, "fp64": 2.0**-53}
EYE, TARGET = (0.6, 2.4, 5.5), (0.0, 0.4, 0.0)
K = np.array([[48.0, 0.0, 31.5], [0.0, 48.0, 23.5], [0.0, 0.0, 1.0]])
FISHEYE_K = np.array([[18.0, 0.0, 31.5], [0.0, 18.0, 23.5], [0.0, 0.0, 1.0]])


def lit_shapes():
    vertices, faces = perturbed_sphere(6, 10, 0.8, 0.15, np.random.default_rng(5))
    rng = np.random.default_rng(7)
    centers = np.column_stack([rng.uniform(-2.5, 2.5, 12), rng.uniform(0.1, 0.3, 12), rng.uniform(-2.5, 1.5, 12)])
    gloss = pyclray.Material((0.9, 0.3, 0.2), 0.6, 20.0)
    return (
        pyclray.Plane((0.0, 1.0, 0.0), 0.0, label=0),
        dataclasses.replace(pyclray.Sphere((-1.2, 0.7, -0.3), 0.7), material=gloss, label=1),
        pyclray.Box((1.4, 0.5, 0.2), (0.8, 1.0, 0.8), axis=(0.0, 1.0, 0.0), angle=25.0),
        pyclray.Mesh(vertices, faces, smooth=True, translate=(0.2, 0.9, -1.4), label=2),
        pyclray.Spheres(centers, rng.uniform(0.1, 0.25, 12)),
    )


def lit_scene(camera, lights=True):
    scene = pyclray.Scene(camera, pyclray.Image(WIDTH, HEIGHT), lit_shapes())
    light_list = (pyclray.PointLight((-2.0, 5.0, 2.0), (25.0, 22.0, 20.0), "key"),
                  pyclray.DirectionalLight((0.5, -1.0, -0.3), (0.3, 0.3, 0.35), "sun")) if lights else ()
    return dataclasses.replace(scene, lights=light_list,
                               shading=pyclray.Shading((0.05, 0.05, 0.06), (0.1, 0.2, 0.3), True))


CAMERAS = {
    "perspective": pyclray.Camera(EYE, TARGET, fov=50.0),
    "distorted": pyclray.Camera.from_intrinsics(K, looking_at(EYE, TARGET), WIDTH, HEIGHT, distortion=[-0.4, 0.0, 0.0, 0.0]),
    "fisheye": pyclray.Fisheye.from_intrinsics(FISHEYE_K, looking_at(EYE, TARGET), WIDTH, HEIGHT,
                                               distortion=[0.02, -0.005, 0.001, 0.0], fov=190.0),
    "orthographic": pyclray.Orthographic(EYE, TARGET, height=5.0),
    "equirectangular": pyclray.Equirectangular(EYE, TARGET, longitude=(-70.0, 70.0), latitude=(-60.0, 30.0)),
}


def aovs_of(camera) -> tuple[str, ...]:
    return tuple(a for a in RENDER_AOVS if a != "zdepth" or camera.has_zdepth)


def shadow_blur(scene, ids, depth, points, origins, precision):
    """4 x the larger of the two shadow-ray offsets at each hit (the kernel's, the cast path's)."""
    kernel = shadow_reach(np.linalg.norm(points - origins, axis=-1), EPS[precision])
    cast = shadow_offset(depth, points, shape_sizes(scene.shapes)[np.where(ids >= 0, ids, -1)], precision)
    return 4 * np.maximum(kernel, cast)


def shaded_against_the_model(scene, O, D, mine, truth, judged, depth_tol, normal_tol, precision):
    """shaded: the float64 shading model at the oracle's hits (truth) within shading.tolerance on the
    judged rays, terminators and shadow edges left out; returns the counts of judged pixels lit by
    some light and of those facing a light that a shape hides from them."""
    hit = truth["id"] >= 0
    points = O + np.where(hit, truth["depth"], 0.0)[:, None] * D
    truth["points"] = points
    blur = shadow_blur(scene, truth["id"], np.where(hit, truth["depth"], 0.0), points, O, precision)
    V, edges = shading.reference_visibility(scene, points, truth["normal"], D, truth["id"], blur=blur)
    expected = shading.reference_shading(scene, D, truth, V)
    tolerance, jump = shading.tolerance(scene, D, truth, depth_tol, normal_tol, EPS[precision])
    shaded_judged = judged & ~jump & ~np.any(edges, axis=0)
    error = np.abs(mine["shaded"].astype(np.float64) - expected).max(axis=-1)
    assert np.all(error[shaded_judged] <= tolerance[shaded_judged]), (error / tolerance)[shaded_judged].max()
    lit = np.any([v > 0 for v in V], axis=0)
    n_s = shading.facing_normals(shading.lighting_normals(scene, truth), D)
    facing = [np.einsum("ij,ij->i", n_s, shading.light_terms(light, points)[0]) > 0 for light in scene.lights]
    shadowed = np.any([f & (v == 0) for f, v in zip(facing, V)], axis=0)
    return int((shaded_judged & hit & lit).sum()), int((shaded_judged & hit & shadowed).sum())


def check_every_aov(scene, frame, precision):
    """The module docstring's checks of a rendered frame against the oracle; returns the counts
    of judged pixels (lit, in shadow) and of pixels out of the field."""
    camera = scene.camera
    origins, directions = camera.rays(WIDTH, HEIGHT)
    O, D = origins.reshape(-1, 3), directions.reshape(-1, 3)
    table = camera.space_directions(WIDTH, HEIGHT)
    field = np.ones(len(D), bool) if table is None else np.asarray(table[1]).reshape(-1)
    flat = {k: np.asarray(v).reshape((len(D),) + np.shape(v)[2:]) for k, v in frame.items()}
    # beyond the field: a miss in every image
    out = ~field
    assert np.all(flat["id"][out] == -1) and np.all(flat["label"][out] == -1) and np.all(flat["primitive"][out] == -1)
    assert np.all(np.isinf(flat["depth"][out])) and not flat["normal"][out].any() and not flat["position"][out].any()
    assert not flat["barycentric"][out].any()
    assert np.all(flat["shaded"][out] == np.asarray(scene.shading.background, flat["shaded"].dtype))
    mine = {k: v[field] for k, v in flat.items()}
    O, D = np.ascontiguousarray(O[field]), D[field]
    eye = np.array(camera.eye) if camera.rays_from_eye else None
    assert_agrees_with_oracle(scene, O, D, mine, precision, reference_point=eye)
    truth, cos, judged, _, depth_tol, normal_tol = judge(scene, O, D, mine, precision, eye)
    # primitive: the oracle's triangle of a mesh or sphere of a batch, 0 for a single shape, -1 on a miss
    expected = np.where(truth["id"] >= 0, 0, -1)
    for index, shape in enumerate(scene.shapes):
        of_shape = truth["id"] == index
        if hasattr(shape, "oracle_hits") and of_shape.any():
            expected[of_shape] = shape.oracle_hits(O[of_shape], D[of_shape])[1]
    assert np.array_equal(mine["primitive"][judged], expected[judged])
    assert np.all(mine["primitive"][mine["id"] < 0] == -1)
    hit = truth["id"] >= 0
    # label: the hit shape's, exactly (-1 without one)
    labels = np.array([-1 if s.label is None else s.label for s in scene.shapes] + [-1])
    assert np.array_equal(mine["label"], labels[mine["id"]])
    # barycentric: the oracle's (u, v) of the same triangle, within rounding relative to the triangle
    mesh_id = next(i for i, s in enumerate(scene.shapes) if isinstance(s, pyclray.Mesh))
    _, which, uv = scene.shapes[mesh_id].oracle_hits(O, D)
    same = judged & (truth["id"] == mesh_id) & (mine["primitive"] == which)
    assert same.sum() > 10
    assert np.abs(mine["barycentric"][same] - uv[same]).max() < (1e-4 if precision == "fp32" else 1e-10)
    assert not mine["barycentric"][mine["id"] != mesh_id].any()
    # position and zdepth: the oracle's hit point, its depth along w
    points = O + np.where(hit, truth["depth"], 0.0)[:, None] * D
    slack = depth_tol + 8 * EPS[precision] * np.abs(points).max(axis=-1)
    position_error = np.linalg.norm(mine["position"].astype(np.float64) - points, axis=-1)
    assert np.all(position_error[judged] <= slack[judged])
    if "zdepth" in frame:
        along = D @ camera.basis()[2]
        with np.errstate(invalid="ignore"):  # inf - inf where both miss (judged rays hit)
            zdepth_error = np.abs(mine["zdepth"].astype(np.float64) - truth["depth"] * along)
        assert np.all(zdepth_error[judged] <= (slack * np.abs(along))[judged])
    # object_coordinates: the hit point in its shape's own space (carried back to the world, the
    # oracle's hit point); flow: 0 in a scene that does not move; both 0 on a miss
    if "object_coordinates" in frame:
        from pyclray.engine.queries.motion import _world_points

        rows = np.flatnonzero(judged)
        back = _world_points(scene.shapes, mine["id"][rows], mine["primitive"][rows],
                             mine["object_coordinates"][rows].astype(np.float64))
        assert np.all(np.linalg.norm(back - points[rows], axis=-1) <= 2 * slack[rows])
        assert not mine["object_coordinates"][mine["id"] < 0].any()
    if "flow" in frame:
        assert not mine["flow"].any()
    lit, shadowed = shaded_against_the_model(scene, O, D, mine, truth, judged, depth_tol, normal_tol, precision)
    return lit, shadowed, int(out.sum())


@pytest.mark.parametrize("precision,lanes", [("fp32", None), ("fp64", None), ("fp32", "1")],
                         ids=["fp32", "fp64", "fp32-lanes=1"])
@pytest.mark.parametrize("name", list(CAMERAS))
def test_every_aov_of_every_camera_model_meets_the_oracle(name, precision, lanes, monkeypatch):
    if precision == "fp64":
        needs_fp64()
    if lanes:
        monkeypatch.setenv("PYCLRAY_LANES", lanes)
        pyclray.clear_cache()
    camera = CAMERAS[name]
    scene = lit_scene(camera)
    frame = pyclray.render(scene, aovs=aovs_of(camera), precision=precision)
    assert set(frame) == set(aovs_of(camera))
    for aov, image in frame.items():
        expected = pyclray.model.aovs.TABLE[aov]
        assert image.dtype == expected.dtype(precision) and image.shape == expected.shape((HEIGHT, WIDTH))
    lit, shadowed, outside = check_every_aov(scene, frame, precision)
    assert lit > 300 and shadowed > 10, (lit, shadowed)  # (the wide models see the shadows small)
    if name in ("distorted", "fisheye"):
        assert outside > 0  # the barrel's fold, the fisheye's circle: their misses were checked
    if lanes:
        pyclray.clear_cache()


@pytest.mark.parametrize("precision,lanes", [("fp32", None), ("fp64", None), ("fp32", "1")],
                         ids=["fp32", "fp64", "fp32-lanes=1"])
def test_shading_cast_hits_is_the_render_kernels_shading_on_the_same_rays(precision, lanes, monkeypatch):
    """A perspective camera's own pixel rays, rendered by the kernel and cast and shaded by the
    orthographic camera's path (start_cast_view): the same ids, and shaded images within the sum of
    both bounds of the float64 model (each also within its own), on every pixel the error model
    judges (shadow edges by both offsets left out)."""
    if precision == "fp64":
        needs_fp64()
    if lanes:
        monkeypatch.setenv("PYCLRAY_LANES", lanes)
        pyclray.clear_cache()
    scene = lit_scene(CAMERAS["perspective"])
    aovs = ("depth", "normal", "id", "primitive", "barycentric", "shaded")
    with pyclray.prepare(scene, precision=precision) as tracer:
        rendered = tracer.render(aovs=aovs)
        cast = start_cast_view(tracer, scene, aovs, None)()
    origins, directions = scene.camera.rays(WIDTH, HEIGHT)
    O, D = origins.reshape(-1, 3), directions.reshape(-1, 3)
    flat = {k: np.asarray(v).reshape((len(D),) + np.shape(v)[2:]) for k, v in cast.items()}
    truth, _, judged, _, cast_depth, cast_normal = judge(scene, O, D, flat, precision)
    _, _, judged_render, _, render_depth, render_normal = judge(
        scene, O, D, {k: np.asarray(v).reshape(flat[k].shape) for k, v in rendered.items()}, precision, np.array(scene.camera.eye))
    both = judged & judged_render
    assert np.array_equal(rendered["id"].reshape(-1)[both], flat["id"][both])
    hit = truth["id"] >= 0
    truth["points"] = O + np.where(hit, truth["depth"], 0.0)[:, None] * D
    blur = shadow_blur(scene, truth["id"], np.where(hit, truth["depth"], 0.0), truth["points"], O, precision)
    V, edges = shading.reference_visibility(scene, truth["points"], truth["normal"], D, truth["id"], blur=blur)
    cast_tol, jump = shading.tolerance(scene, D, truth, cast_depth, cast_normal, EPS[precision])
    render_tol, jump2 = shading.tolerance(scene, D, truth, render_depth, render_normal, EPS[precision])
    keep = both & ~jump & ~jump2 & ~np.any(edges, axis=0)
    difference = np.abs(rendered["shaded"].reshape(-1, 3).astype(np.float64) - flat["shaded"]).max(axis=-1)
    assert np.all(difference[keep] <= (cast_tol + render_tol)[keep]), (difference / (cast_tol + render_tol))[keep].max()
    expected = shading.reference_shading(scene, D, truth, V)
    assert np.all(np.abs(flat["shaded"] - expected).max(axis=-1)[keep] <= cast_tol[keep])
    lit = np.any([v > 0 for v in V], axis=0)
    assert (keep & hit & lit).sum() > 500 and (keep & hit & ~lit).sum() > 50
    # the two paths compute the same formula, not merely two within bounds: on most pixels they are
    # within a few roundings of each other
    assert np.median(difference[keep & hit]) < 64 * EPS[precision]
    if lanes:
        pyclray.clear_cache()


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_an_orthographic_headlight_travels_along_w(precision):
    """A scene without lights: its headlight travels along the camera's view direction w, so an
    orthographic view straight onto a plane facing it is lit at cos = 1 in every pixel: shaded is
    the albedo exactly (ambient 0); tilted by 60 degrees, half of it."""
    if precision == "fp64":
        needs_fp64()
    color = pyclray.Material((0.25, 0.5, 0.75))
    plane = dataclasses.replace(pyclray.Plane((0.0, 0.0, 1.0), 0.0), material=color)
    camera = pyclray.Orthographic((0.3, -0.2, 5.0), (0.3, -0.2, 0.0), height=2.0)
    scene = pyclray.Scene(camera, pyclray.Image(16, 12), (plane,))
    frame = pyclray.render(scene, aovs=("shaded", "id"), precision=precision)
    assert (frame["id"] == 0).all()
    assert np.array_equal(frame["shaded"], np.broadcast_to(np.asarray(color.color, frame["shaded"].dtype), (12, 16, 3)))
    tilted = dataclasses.replace(scene, camera=pyclray.Orthographic((0.0, 5.0 * np.sin(np.pi / 3), 5.0 * np.cos(np.pi / 3)),
                                                                    (0.0, 0.0, 0.0), height=2.0))
    frame = pyclray.render(tilted, aovs=("shaded",), precision=precision)
    assert np.abs(frame["shaded"] - 0.5 * np.array(color.color)).max() < 8 * EPS[precision]


def test_an_orthographic_window_and_view_give_the_whole_images_pixels(tmp_path):
    """A window of an orthographic render (pyclray view's bands, render --size) holds the whole
    image's pixels of every AOV, shaded included; pyclray view's default picture (shaded) renders an
    orthographic scene, and offers zdepth only where the model has it."""
    from pyclray.apps.view.frames import offered_aovs, render_picture

    scene = lit_scene(CAMERAS["orthographic"])
    whole = pyclray.render(scene, aovs=aovs_of(scene.camera))
    with pyclray.prepare(scene) as tracer:
        part = tracer.render(aovs=aovs_of(scene.camera), window=(10, 7, 30, 20))
    for aov in whole:
        assert np.array_equal(part[aov], whole[aov][7:27, 10:40]), aov
    picture = render_picture(scene, scene.camera, "shaded", (WIDTH, HEIGHT))
    assert picture.rgb.shape == (HEIGHT, WIDTH, 3) and picture.rgb.std() > 10
    assert "zdepth" in offered_aovs(scene, "shaded")
    assert "zdepth" not in offered_aovs(lit_scene(CAMERAS["equirectangular"]), "shaded")


def stiff_scene(case):
    """tests/test_shadows.py's stiff shadow scenes, seen by an orthographic camera: a ball and a small
    ball on ground spheres of radius 1e4 and 1e8 (contact shadows an offset growing with the ground's
    size would jump), moved 1e5 away, and a light inside a sphere of radius 20 (its inner wall lit:
    the offset toward the viewer, not skipped)."""
    from test_shading import ball, lit_scene
    from test_shadows import on_ground_sphere

    if case == "inside":
        shapes = (ball((0.0, 0.0, 0.0), 20.0), ball((0.0, -3.0, -8.0), 2.0))
        lights = ({"type": "point", "position": [0.0, 6.0, 0.0], "intensity": 400.0},)
        scene, height = lit_scene(shapes, lights, ((0.0, 2.0, 12.0), (0.0, -6.0, -10.0)), size=64), 14.0
    else:
        radius, shift = {"ground 1e4": (1e4, (0.0, 0.0, 0.0)), "ground 1e8": (1e8, (0.0, 0.0, 0.0)),
                         "ground 1e6 moved 1e5": (1e6, (1e5, 5e4, -1e5))}[case]
        scene, height = lit_scene(*on_ground_sphere(radius), size=64, shift=shift), 2.5
    camera = scene.camera
    return dataclasses.replace(scene, camera=pyclray.Orthographic(camera.eye, camera.target, camera.up, height))


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("case", ["ground 1e4", "ground 1e8", "ground 1e6 moved 1e5", "inside"])
def test_orthographic_shadows_neither_acne_nor_leak(case, precision):
    """The cast path's shadow rays (from p moved by 16 (eps t + eps64 (|p|_1 + R)) along n_s, cast from
    their own float64 origins) on the stiff scenes: the shaded image within the float64 model's
    bound on every judged pixel, with lit and shadowed pixels both present (acne would shadow the
    lit ones, a leak light the shadowed ones)."""
    if precision == "fp64":
        needs_fp64()
    scene = stiff_scene(case)
    width, height = scene.image.width, scene.image.height
    frame = pyclray.render(scene, aovs=("depth", "normal", "id", "shaded"), precision=precision)
    origins, directions = scene.camera.rays(width, height)
    O, D = origins.reshape(-1, 3), directions.reshape(-1, 3)
    mine = {k: np.asarray(v).reshape((len(D),) + np.shape(v)[2:]) for k, v in frame.items()}
    assert_agrees_with_oracle(scene, O, D, mine, precision)
    truth, _, judged, _, depth_tol, normal_tol = judge(scene, O, D, mine, precision)
    lit, shadowed = shaded_against_the_model(scene, O, D, mine, truth, judged, depth_tol, normal_tol, precision)
    assert lit > 500 and shadowed > 40, (lit, shadowed)


def test_an_orthographic_cameras_flow_lands_where_the_point_is_in_the_next_frame(tmp_path):
    """tests/test_dataset_flow.py's moving scene (the camera, a cube, a ball and a crate keyed) seen
    by an orthographic camera: each hit point projects back onto its own pixel's centre
    (Orthographic.project inverts its rays), and its flow lands where the point, carried by its
    shape's motion, projects in the next frame's camera (float64 here, from the object coordinates)."""
    from test_dataset_flow import FPS, SCENE, T

    path = tmp_path / "moving.toml"
    path.write_text(SCENE.replace("fov = 45.0", 'model = "orthographic"\nheight = 3.0'))
    scene = pyclray.load_scene(path)
    width, height = scene.image.width, scene.image.height
    now, then = scene.at(T), scene.at(T + 1 / FPS)
    assert isinstance(now.camera, pyclray.Orthographic) and now.camera.eye != then.camera.eye
    frame = pyclray.render(scene, aovs=("flow", "object_coordinates", "position", "id"), time=T)
    hit = frame["id"] >= 0
    assert hit.mean() > 0.9 and not frame["flow"][~hit].any()
    j, i = np.nonzero(hit)
    pixels, z = now.camera.project(frame["position"][hit].astype(np.float64), width, height)
    assert np.abs(pixels - np.stack([i, j], axis=-1)).max() < 1e-3 and (z > 0).all()
    X = frame["object_coordinates"].astype(np.float64)
    expected = np.full((height, width, 2), np.nan)
    for shape_id, shape in enumerate(then.shapes):
        chosen = frame["id"] == shape_id
        F = shape.object_poses()[0]
        expected[chosen] = then.camera.project(X[chosen] @ F[:3, :3].T + F[:3, 3], width, height)[0]
    landed = np.stack([i, j], axis=-1) + frame["flow"][hit]
    assert np.abs(landed - expected[hit]).max() <= 1e-3
    assert np.abs(frame["flow"][hit]).max() > 1  # things move by pixels
