"""The `flow` and `object_coordinates` AOVs: object coordinates are the hit point in its shape's own
frame (a mesh's file coordinates, a sphere's centre at 0, a box's centre and axes); a pixel moved by
its flow lands, to 1e-3 px in fp32, where the same surface point is in the next frame (t + 1/fps),
which the next frame's render sees there (its id and object coordinates); render, animate and
dataset give each frame its own."""
import os
import subprocess
import sys

import numpy as np
import pytest

import pyclray
from pyclray.io.dataset import Placement, view_cameras
from pyclray.model.errors import RequestError
from tests.dataset_scene import CUBE_FACES, CUBE_VERTICES

FPS = 10.0
SCENE = f"""
[camera]
eye = [0.5, 1.8, 4.5]
target = [0.0, 0.4, 0.0]
fov = 45.0

[image]
width = 96
height = 72

[[shapes]]
type = "plane"
name = "ground"
normal = [0.0, 1.0, 0.0]
offset = 0.0

[[shapes]]
type = "mesh"
name = "cube"
vertices = {CUBE_VERTICES}
faces = {CUBE_FACES}
scale = 0.8
axis = [0.2, 1.0, 0.1]
angle = 10.0
translate = [-0.6, 0.5, 0.0]
label = 1

[[shapes]]
type = "sphere"
name = "ball"
center = [0.7, 0.4, 0.3]
radius = 0.4

[[shapes]]
type = "box"
name = "crate"
center = [0.2, 0.3, -0.8]
size = [0.6, 0.4, 0.5]
axis = [0.0, 1.0, 0.0]
angle = 5.0

[animation]
fps = {FPS}
duration = 1.0

[[animation.keys]]
target = "camera"
time = 0.0
eye = [0.5, 1.8, 4.5]

[[animation.keys]]
target = "camera"
time = 1.0
eye = [1.5, 2.0, 4.0]

[[animation.keys]]
target = "cube"
time = 0.0
angle = 10.0
translate = [-0.6, 0.5, 0.0]

[[animation.keys]]
target = "cube"
time = 1.0
angle = 70.0
translate = [-0.3, 0.6, 0.2]

[[animation.keys]]
target = "ball"
time = 0.0
center = [0.7, 0.4, 0.3]

[[animation.keys]]
target = "ball"
time = 1.0
center = [0.4, 0.6, 0.5]

[[animation.keys]]
target = "crate"
time = 0.0
angle = 5.0

[[animation.keys]]
target = "crate"
time = 1.0
angle = 65.0
"""
T = 0.3


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    path = tmp_path_factory.mktemp("flow") / "moving.toml"
    path.write_text(SCENE)
    return pyclray.load_scene(path)


def pixel_centres(camera, width, height):
    """(H, W, 2): each pixel centre in K's pixel coordinates, from the camera model's own rays (so
    the test holds whichever pixel convention K has)."""
    K, pose = camera.intrinsics(width, height), camera.pose()
    _, directions = camera.rays(width, height)
    in_camera = directions @ pose[:3, :3]
    return (in_camera @ K.T)[..., :2] / in_camera[..., 2:3]


def project(camera, width, height, points):
    K, pose = camera.intrinsics(width, height), camera.pose()
    in_camera = (points - pose[:3, 3]) @ pose[:3, :3]
    return (in_camera @ K.T)[..., :2] / in_camera[..., 2:3]


def test_object_coordinates(scene):
    now = scene.at(T)
    frame = pyclray.render(scene, aovs=("object_coordinates", "position", "id"), time=T)
    assert frame["object_coordinates"].dtype == np.float32 and frame["object_coordinates"].shape == (72, 96, 3)
    assert (frame["object_coordinates"][frame["id"] < 0] == 0).all()
    cube, ball, crate = now.shapes[1], now.shapes[2], now.shapes[3]
    X = frame["object_coordinates"].astype(np.float64)
    tolerance = 1e-5  # float32 positions of a few units, turned into the frame in float64
    on_cube = X[frame["id"] == 1]
    assert len(on_cube) > 50 and np.abs(np.abs(on_cube).max(axis=1) - 0.5).max() < tolerance  # the file's unit cube
    on_ball = X[frame["id"] == 2]
    assert len(on_ball) > 50 and np.abs(np.linalg.norm(on_ball, axis=1) - 0.4).max() < tolerance  # centre at 0
    on_crate = X[frame["id"] == 3]
    assert len(on_crate) > 50 and np.abs((np.abs(on_crate) / [0.3, 0.2, 0.25]).max(axis=1) - 1).max() < 1e-4
    world = X[frame["id"] == 1] @ cube.transform()[:3, :3].T + cube.transform()[:3, 3]
    np.testing.assert_allclose(world, frame["position"][frame["id"] == 1], atol=tolerance)
    del ball, crate


def test_flow_lands_where_the_point_is_in_the_next_frame(scene):
    width, height = 96, 72
    now, then = scene.at(T), scene.at(T + 1 / FPS)
    frame = pyclray.render(scene, aovs=("flow", "object_coordinates", "id", "primitive"), time=T)
    assert frame["flow"].dtype == np.float32 and frame["flow"].shape == (height, width, 2)
    ids = frame["id"]
    hit = ids >= 0
    assert (frame["flow"][~hit] == 0).all()
    # each hit point carried by its shape's motion (its frame then, the same object coordinates),
    # projected by the next frame's camera: computed here in float64 from the shapes at both times
    X = frame["object_coordinates"].astype(np.float64)
    expected = np.full((height, width, 2), np.nan)
    for shape_id, shape in enumerate(then.shapes):
        chosen = ids == shape_id
        F = shape.object_poses()[0]
        expected[chosen] = project(then.camera, width, height, X[chosen] @ F[:3, :3].T + F[:3, 3])
    landed = pixel_centres(now.camera, width, height) + frame["flow"]
    error = np.abs(landed - expected)[hit]
    assert error.max() <= 1e-3, error.max()
    assert np.abs(frame["flow"][hit]).max() > 1  # things move by pixels
    # ... and the next frame's render sees that surface point there: where the landing pixel shows
    # the same shape, its object coordinates project to within the pixel of where the flow landed
    following = pyclray.render(scene, aovs=("object_coordinates", "id"), time=T + 1 / FPS)
    centres = pixel_centres(then.camera, width, height)
    checked = 0
    js, is_ = np.nonzero(hit)
    for j, i in zip(js, is_):
        target = landed[j, i]
        nearest = np.unravel_index(np.argmin(((centres - target) ** 2).sum(axis=2)), (height, width))
        if np.abs(centres[nearest] - target).max() > 0.5 or following["id"][nearest] != ids[j, i]:
            continue  # out of the image, or hidden in the next frame
        shape = then.shapes[ids[j, i]]
        F = shape.object_poses()[0]
        seen = project(then.camera, width, height, following["object_coordinates"][nearest].astype(np.float64)
                       @ F[:3, :3].T + F[:3, 3])
        assert np.abs(seen - target).max() <= 0.5 + 1e-3
        checked += 1
    assert checked > 0.8 * hit.sum()


def test_static_scene_flow_is_zero_and_animated_needs_a_time(scene):
    static = pyclray.Scene(scene.camera, scene.image, scene.shapes)
    frame = pyclray.render(static, aovs=("flow", "id"))
    assert (frame["flow"] == 0).all() and (frame["id"] >= 0).any()
    with pytest.raises(RequestError, match="flow"):
        pyclray.render(scene, aovs=("flow",))
    with pytest.raises(RequestError, match="time"):
        pyclray.render(static, aovs=("depth",), time=0.5)


def test_animation_frames_have_their_own_flow(scene):
    frames = list(pyclray.render_animation(scene, aovs=("flow",), frames=[2, 3]))
    for t, frame in frames:
        expected = pyclray.render(scene, aovs=("flow",), time=t)
        assert np.array_equal(frame["flow"], expected["flow"])
    assert not np.array_equal(frames[0][1]["flow"], frames[1][1]["flow"])


def test_cli_render_and_dataset_with_time(tmp_path, scene):
    path = tmp_path / "moving.toml"
    path.write_text(SCENE)
    out = tmp_path / "f.npz"
    env = dict(os.environ)
    run = lambda *a: subprocess.run([sys.executable, "-m", "pyclray", *map(str, a)], capture_output=True, text=True,
                                    env=env)
    result = run("render", path, "-o", out, "--aov", "flow,object_coordinates", "--time", T)
    assert result.returncode == 0, result.stderr
    arrays = np.load(out)
    expected = pyclray.render(scene, aovs=("flow", "object_coordinates"), time=T)
    assert np.array_equal(arrays["flow"], expected["flow"])
    assert np.array_equal(arrays["object_coordinates"], expected["object_coordinates"])
    result = run("dataset", path, "-o", tmp_path / "set", "--views", 2, "--format", "npz", "--aov", "flow,id", "--time", T)
    assert result.returncode == 0, result.stderr
    views = view_cameras(scene.at(T), Placement(), 2)
    for k, camera in enumerate(views):
        data = np.load(tmp_path / "set" / f"{k:06d}.npz")
        # the view's camera stays; the shapes move to the next frame
        motion = pyclray.render(scene, aovs=("flow",), time=T, camera=camera)
        assert np.array_equal(data["flow"], motion["flow"]) and np.abs(data["flow"]).max() > 0


def test_every_shape_type_has_its_own_frame():
    """scenes/shapes.toml holds every shape type: each hit's object coordinates, taken back to the
    world through its shape's frame (its primitive's, for a batch), are the hit point."""
    from pyclray.model.shapes import REGISTRY

    scene = pyclray.load_scene("scenes/shapes.toml").with_size(96, 72)
    assert {shape.type for shape in scene.shapes} == set(REGISTRY)
    frame = pyclray.render(scene, aovs=("object_coordinates", "position", "id", "primitive"))
    for shape_id, shape in enumerate(scene.shapes):
        chosen = frame["id"] == shape_id
        assert chosen.any(), shape.type
        frames = shape.object_poses()
        assert frames.ndim == 3 and frames.shape[1:] == (4, 4) and len(frames) in (1, shape.primitive_count())
        F = frames[frame["primitive"][chosen] if len(frames) > 1 else np.zeros(chosen.sum(), int)]
        X = frame["object_coordinates"][chosen].astype(np.float64)
        world = np.einsum("nij,nj->ni", F[:, :3, :3], X) + F[:, :3, 3]
        position = frame["position"][chosen].astype(np.float64)
        scale = max(1.0, float(np.abs(position).max()))
        assert np.abs(world - position).max() <= 1e-5 * scale, shape.type


def test_flow_needs_a_pinhole(scene):
    lens = pyclray.Camera.from_intrinsics(scene.camera.intrinsics(96, 72), scene.camera.pose(), 96, 72,
                                          distortion=(0.1, 0.0, 0.0, 0.0))
    with pytest.raises(RequestError, match="flow: needs a pinhole camera"):
        pyclray.render(scene, aovs=("flow",), time=T, camera=lens)
    frame = pyclray.render(scene, aovs=("object_coordinates",), time=T, camera=lens)  # any camera has those
    assert np.abs(frame["object_coordinates"]).max() > 0


def test_a_handle_of_an_animated_scene_asks_for_the_time(scene):
    with pyclray.prepare(scene) as tracer:
        with pytest.raises(RequestError, match="flow"):
            tracer.render(aovs=("flow",))
        assert tracer.render(aovs=("depth",))["depth"].shape == (72, 96)
