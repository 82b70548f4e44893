"""Cameras as vision users write them (scene-format.md, "Camera from intrinsics"): K and a
camera-to-world pose in OpenCV's convention, in TOML and in Python; their renders against the
float64 oracle (off-centre principal points, fx != fy, a principal point outside the image); a
look-at camera turned into K and a pose renders the same images; back-projection of the depth
map; the EXR header; the Mitsuba mapping; the command line; animation."""
import dataclasses
import os
import subprocess
import sys
import tomllib

import numpy as np
import pytest

import pyclray
from pyclray import SceneError
from pyclray.engine.bvh import tiles as culling
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.reference import check, error_model, mitsuba, oracle

from conftest import REPO, SCENES
from test_render import assert_matches_oracle

# A pose looking down at TP02's spheres from the front right (columns: x right, y down, z forward
# in the world, then the eye), as in scenes/intrinsics.toml
POSE = [[0.8, 0.168, -0.576, 2.5], [0.0, -0.96, -0.28, 1.8], [-0.6, 0.224, -0.768, 4.2], [0.0, 0.0, 0.0, 1.0]]
SHAPES = (pyclray.Plane((0, 1, 0), 0.0, "ground"), pyclray.Sphere((-1.6, 0.7, -0.5), 0.7, "red"),
          pyclray.Sphere((0.0, 1.0, 0.0), 1.0, "green"), pyclray.Sphere((1.5, 0.5, 1.0), 0.5, "blue"),
          pyclray.Box((-0.4, 0.35, 1.6), (0.7, 0.7, 0.7), (0, 1, 0), 30.0, "crate"))


def K(fx, fy, cx, cy):
    return [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]


def needs_fp64():
    if not has_fp64(context_for().device):
        pytest.skip("device lacks cl_khr_fp64")


def scene_of(intrinsics, width=64, height=48, pose=POSE, shapes=SHAPES):
    return pyclray.Scene(pyclray.Camera.from_intrinsics(intrinsics, pose), pyclray.Image(width, height), shapes)


def write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def camera_table(intrinsics, pose=POSE, extra=""):
    return f"[camera]\nintrinsics = {intrinsics!r}\npose = {pose!r}\n{extra}"


SCENE_REST = """
[image]
width = 64
height = 48

[[shapes]]
type = "plane"
normal = [0.0, 1.0, 0.0]
offset = 0.0

[[shapes]]
type = "sphere"
center = [0.0, 1.0, 0.0]
radius = 1.0
"""


# -- the scene file and the model ---------------------------------------------------------------
def test_a_toml_camera_from_intrinsics_loads_as_from_intrinsics_builds_it(tmp_path):
    intrinsics = K(50.0, 55.0, 20.5, 30.25)
    scene = pyclray.load_scene(write(tmp_path, camera_table(intrinsics) + SCENE_REST))
    camera = scene.camera
    assert camera == pyclray.Camera.from_intrinsics(intrinsics, POSE, 64, 48)  # K is in pixels of [image]
    assert camera.size == (64, 48) and camera.target is None and camera.fov is None
    assert np.array_equal(camera.intrinsics(64, 48), intrinsics)  # as given, at its size
    assert np.array_equal(camera.pose(), POSE)
    assert camera.eye == (2.5, 1.8, 4.2)
    u, v, w = camera.basis()  # the frame the kernels use: u left, v up, w forward
    assert np.array_equal(w, np.array(POSE)[:3, 2]) and np.array_equal(u, -np.array(POSE)[:3, 0])


def test_the_shipped_intrinsics_scene_is_a_camera_from_intrinsics():
    scene = pyclray.load_scene(SCENES / "intrinsics.toml")
    assert scene.camera.K is not None and scene.camera.size == (640, 480)
    # written in OpenCV's convention since the sensors issue: 10 px right of the centre (319.5)
    assert scene.camera.intrinsics(640, 480)[0, 2] == 329.5


def test_a_corner_origin_k_is_the_same_camera_as_its_opencv_k():
    """pixel_origin "corner" (COLMAP, NeRF: centres at i + 0.5) reads K half a pixel off OpenCV's:
    the same rays, and the camera's K (and every K written) in OpenCV's convention."""
    corner = pyclray.Camera.from_intrinsics(K(50.0, 60.0, 32.0, 24.0), POSE, 64, 48, pixel_origin="corner")
    center = pyclray.Camera.from_intrinsics(K(50.0, 60.0, 31.5, 23.5), POSE, 64, 48)
    assert corner == center and np.array_equal(corner.intrinsics(64, 48), K(50.0, 60.0, 31.5, 23.5))
    table = camera_table(K(50.0, 60.0, 32.0, 24.0)) + 'pixel_origin = "corner"\n'
    assert pyclray.scene_from_dict(tomllib.loads(table + "[image]\nwidth = 64\nheight = 48\n")).camera == center
    with pytest.raises(pyclray.SceneError, match="key 'pixel_origin'"):
        pyclray.Camera.from_intrinsics(K(50.0, 60.0, 32.0, 24.0), POSE, pixel_origin="centre")


BAD = [
    # (the [camera] table, the key named, a part of the message)
    (camera_table(K(50, 50, 32, 24)) + "eye = [0.0, 1.0, 2.0]\n", "eye", "not a mix"),
    (camera_table(K(50, 50, 32, 24)) + "fov = 40.0\n", "fov", "not a mix"),
    (camera_table(K(50, 50, 32, 24)) + "fov_axis = \"y\"\n", "fov_axis", "not a mix"),
    (camera_table(K(50, 50, 32, 24)) + "focal = 3.0\n", "focal", "unknown key"),
    (f"[camera]\nintrinsics = {K(50, 50, 32, 24)!r}\n", "pose", "needs both"),
    (f"[camera]\npose = {POSE!r}\n", "intrinsics", "needs both"),
    (f"[camera]\neye = [0.0, 1.0, 2.0]\ntarget = [0.0, 0.0, 0.0]\nfov = 40.0\npose = {POSE!r}\n", "eye", "not a mix"),
    (camera_table([[50, 0, 32], [0, 50, 24]]), "intrinsics", "3x3 matrix"),
    (camera_table([[50, 0, 32, 0], [0, 50, 24, 0], [0, 0, 1, 0]]), "intrinsics", "3x3 matrix"),
    (camera_table([[50, 0], [0, 50, 24], [0, 0, 1]]), "intrinsics", "3x3 matrix"),
    (camera_table("nan"), "intrinsics", "3x3 matrix"),
    ("[camera]\nintrinsics = [[nan, 0.0, 32.0], [0.0, 50.0, 24.0], [0.0, 0.0, 1.0]]\npose = " + repr(POSE) + "\n",
     "intrinsics", "finite"),
    ("[camera]\nintrinsics = [[50.0, 0.0, inf], [0.0, 50.0, 24.0], [0.0, 0.0, 1.0]]\npose = " + repr(POSE) + "\n",
     "intrinsics", "finite"),
    (camera_table([["50", 0, 32], [0, 50, 24], [0, 0, 1]]), "intrinsics", "of numbers"),
    (camera_table([[50, 0, 32], [0, 50, 24], [0, 0, 1]]).replace("[[50,", "[[true,"), "intrinsics", "of numbers"),
    (camera_table(K(0.0, 50, 32, 24)), "intrinsics", "fx = K[0][0] > 0"),
    (camera_table(K(50, -50.0, 32, 24)), "intrinsics", "fy = K[1][1] > 0"),
    (camera_table([[50, 0.5, 32], [0, 50, 24], [0, 0, 1]]), "intrinsics", "no skew"),
    (camera_table([[50, 0, 32], [0, 50, 24], [0, 0, 2]]), "intrinsics", "pinhole matrix"),
    (camera_table([[50, 0, 32], [0.1, 50, 24], [0, 0, 1]]), "intrinsics", "pinhole matrix"),
    (camera_table(K(50, 50, 1e12, 24)), "intrinsics", "principal point"),
    (camera_table(K(50, 50, 32, 24), [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]), "pose", "4x4 matrix"),
    (camera_table(K(50, 50, 32, 24), [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]), "pose", "last row"),
    (camera_table(K(50, 50, 32, 24), [[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]), "pose", "rigid"),
    (camera_table(K(50, 50, 32, 24), [[1, 0.1, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), "pose", "rigid"),
    (camera_table(K(50, 50, 32, 24), [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), "pose", "reflection"),
    ("[camera]\nintrinsics = " + repr(K(50, 50, 32, 24)) + "\npose = [[1.0, 0.0, 0.0, inf], [0.0, 1.0, 0.0, 0.0], "
     "[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]\n", "pose", "finite"),
    (camera_table(K(1e-40, 1e-40, 32, 24)), "intrinsics", "too short"),
    (camera_table(K(1e40, 1e40, 32, 24)), "intrinsics", "too long"),
]


@pytest.mark.parametrize("table, key, fragment", BAD, ids=[f"{k}-{i}" for i, (_, k, _) in enumerate(BAD)])
def test_a_bad_camera_is_one_line_naming_file_table_and_key(tmp_path, table, key, fragment):
    path = write(tmp_path, table + SCENE_REST)
    with pytest.raises(SceneError) as error:
        pyclray.load_scene(path)
    message = str(error.value)
    assert message.startswith(f"{path}: table [camera]: key {key!r}: "), message
    assert fragment in message and "\n" not in message, message


def test_the_command_line_reports_a_bad_camera_in_one_line(tmp_path):
    path = write(tmp_path, camera_table(K(50, 50, 32, 24)) + "fov = 40.0\n" + SCENE_REST)
    result = subprocess.run([sys.executable, "-m", "pyclray", "render", str(path), "-o", str(tmp_path / "o.exr")],
                            capture_output=True, text=True, env=dict(os.environ))
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "table [camera]: key 'fov'" in result.stderr
    assert not (tmp_path / "o.exr").exists()


def test_from_intrinsics_in_python_names_its_arguments():
    with pytest.raises(SceneError, match="key 'intrinsics'.*no skew"):
        pyclray.Camera.from_intrinsics([[50, 1, 32], [0, 50, 24], [0, 0, 1]], POSE)
    with pytest.raises(SceneError, match="key 'pose'.*rigid"):
        pyclray.Camera.from_intrinsics(K(50, 50, 32, 24), np.diag([1.0, 1.0, 1.5, 1.0]))
    with pytest.raises(SceneError, match="key 'height'.*both width and height"):
        pyclray.Camera.from_intrinsics(K(50, 50, 32, 24), POSE, width=64)
    with pytest.raises(SceneError, match="key 'width'"):
        pyclray.Camera.from_intrinsics(K(50, 50, 32, 24), POSE, width=0, height=48)
    camera = pyclray.Camera.from_intrinsics(np.array(K(50, 50, 32, 24)), np.array(POSE))  # numpy arrays too
    assert camera == pyclray.Camera.from_intrinsics(K(50, 50, 32, 24), POSE)
    # the dataclass's own fields: a mix of the two kinds is refused there too, naming the field
    with pytest.raises(SceneError, match="key 'fov'.*not a mix"):
        dataclasses.replace(camera, fov=30.0)
    with pytest.raises(SceneError, match="key 'size'"):
        pyclray.Camera((0, 0, 0), (0, 0, -1), size=(64, 48))
    with pytest.raises(SceneError, match="key 'rotation'.*rigid"):
        dataclasses.replace(camera, rotation=((1, 0, 0), (0, 1, 0), (0, 0, -1)))


def test_replace_equality_and_hashing_keep_working():
    camera = pyclray.Camera.from_intrinsics(K(50, 50, 32, 24), POSE, 64, 48)
    moved = dataclasses.replace(camera, eye=(0.0, 1.0, 5.0))  # the pose's translation
    assert moved.pose()[:3, 3].tolist() == [0.0, 1.0, 5.0] and np.array_equal(moved.pose()[:3, :3], camera.pose()[:3, :3])
    zoomed = dataclasses.replace(camera, K=K(100, 100, 32, 24))
    assert zoomed != camera and zoomed.intrinsics(64, 48)[0, 0] == 100
    assert camera == pyclray.Camera.from_intrinsics(K(50, 50, 32, 24), POSE, 64, 48)
    assert len({camera, pyclray.Camera.from_intrinsics(K(50, 50, 32, 24), POSE, 64, 48), moved}) == 2


def test_a_pose_rigid_within_the_tolerance_renders_with_its_nearest_rotation():
    """Seven significant digits (a pose written by hand) pass; the camera holds the nearest rotation,
    orthonormal to float64 rounding, and its pose() is that rigid pose."""
    rotated = np.round(np.array(POSE) @ np.array([[0.6, 0, 0.8, 0], [0, 1, 0, 0], [-0.8, 0, 0.6, 0], [0, 0, 0, 1]])
                       @ np.array([[1, 0, 0, 0], [0, np.cos(0.3), -np.sin(0.3), 0], [0, np.sin(0.3), np.cos(0.3), 0],
                                   [0, 0, 0, 1]]), 7)
    camera = pyclray.Camera.from_intrinsics(K(50, 50, 32, 24), rotated)
    R = camera.pose()[:3, :3]
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-15 and np.abs(R - rotated[:3, :3]).max() < 1e-6
    assert np.abs(camera.basis() @ camera.basis().T - np.eye(3)).max() < 1e-15


def test_intrinsics_scale_with_the_image_size():
    """K is in pixels of the camera's size (the scene's image); at another size it scales with the
    image as resizing the image would: fx, cx + 1/2 by the ratio of widths, fy, cy + 1/2 by that of
    heights (OpenCV's convention since the sensors issue: the image's edge is at -1/2, so cx + 1/2
    scales, where the corner convention before scaled cx itself). So --size and with_size keep the
    view (and an aspect change stretches it, fx != fy)."""
    scene = scene_of(K(50.0, 60.0, 20.5, 30.25))
    assert scene.camera.size == (64, 48)
    bigger = scene.with_size(128, 96)
    assert bigger.camera == scene.camera  # the camera keeps its K and size ...
    assert np.array_equal(bigger.camera.intrinsics(128, 96), K(100.0, 120.0, 41.5, 61.0))  # ... which scales
    assert np.array_equal(scene.camera.intrinsics(32, 96), K(25.0, 120.0, 10.0, 61.0))
    # the same view: the four corners of the image look the same way at both sizes
    small_rays = oracle.camera_rays(scene)[1]
    big_rays = oracle.camera_rays(bigger)[1]
    corners = (big_rays[0, 0] + big_rays[1, 1]) / 2  # the corner between the big image's first 4 pixels
    assert np.allclose(corners / np.linalg.norm(corners), small_rays[0, 0], atol=1e-3)
    # a camera from intrinsics without a size takes the scene's image's
    unbound = pyclray.Camera.from_intrinsics(K(50.0, 60.0, 20.5, 30.25), POSE)
    assert unbound.size is None and pyclray.Scene(unbound, pyclray.Image(64, 48)).camera == scene.camera


# -- renders against the float64 oracle ---------------------------------------------------------
@pytest.mark.parametrize("intrinsics", [
    K(55.0, 55.0, 32.0, 24.0),           # centred
    K(55.0, 55.0, 11.3, 40.7),           # off-centre
    K(40.0, 70.0, 45.25, 9.5),           # fx != fy, off-centre
    K(30.0, 30.0, -5.0, 24.0),           # the principal point outside the image
    K(3000.0, 2900.0, 33.0, 20.0),       # a narrow view
    K(12.0, 14.0, 30.0, 25.0),           # a wide view (about 140 degrees)
], ids=["centred", "off-centre", "fx-fy", "outside", "narrow", "wide"])
def test_renders_from_intrinsics_match_the_oracle(intrinsics):
    scene = scene_of(intrinsics)
    assert_matches_oracle(scene)
    assert (oracle.render(scene, aovs=("id",))["id"] >= 1).sum() > 20  # the spheres or the crate in view


def test_fp64_renders_from_intrinsics_match_the_oracle():
    needs_fp64()
    scene = scene_of(K(40.0, 70.0, 45.25, 9.5))
    assert_matches_oracle(scene, pyclray.render(scene, precision="fp64"), precision="fp64")


def test_the_kernel_looks_through_k_inverse_of_the_pixel_centre():
    """A plane facing the camera at distance 3: pixel (j, i)'s z-depth is exactly 3, and its
    depth 3 |K^-1 [i, j, 1]| (the contract's formula, not just the oracle's: OpenCV's pixel
    convention since the sensors issue, pixel centres at integers; it was [i + 0.5, j + 0.5, 1])."""
    needs_fp64()
    intrinsics = np.array(K(7.0, 5.0, 2.25, 1.0))
    scene = pyclray.Scene(pyclray.Camera.from_intrinsics(intrinsics, np.eye(4)), pyclray.Image(5, 3),
                          (pyclray.Plane((0, 0, 1), -3.0),))  # z = 3, in front along OpenCV's +z
    frame = pyclray.render(scene, aovs=("depth", "zdepth", "position"), precision="fp64")
    j, i = np.mgrid[0:3, 0:5]
    rays = np.stack([i, j, np.ones((3, 5))], axis=-1) @ np.linalg.inv(intrinsics).T
    assert np.allclose(frame["zdepth"], 3.0, rtol=1e-15)
    assert np.allclose(frame["depth"], 3 * np.linalg.norm(rays, axis=-1), rtol=1e-15)
    assert np.allclose(frame["position"], 3 * rays, rtol=1e-15, atol=1e-15)  # x right, y down in the world here


def test_culling_stays_conservative_for_any_principal_point_and_focal_lengths(monkeypatch):
    """Tile lists (screen bounds from the tangents and the principal point) against every shape in
    every tile and against the BVH: the same images bit for bit."""
    rng = np.random.default_rng(7)
    shapes = [pyclray.Plane((0, 1, 0), 0.0)] + [
        pyclray.Sphere(tuple(rng.uniform(-3, 3, 3) * [1, 0.3, 1] + [0, 0.5, 0]), float(rng.uniform(0.05, 0.5)))
        for _ in range(60)]
    for intrinsics in (K(40.0, 70.0, 45.25, 9.5), K(37.5, 37.5, -6.25, 28.0), K(31.25, 37.5, 40.0, 60.0)):
        scene = scene_of(intrinsics, 80, 56, shapes=tuple(shapes))
        tiles = pyclray.render(scene, acceleration="tiles")
        bvh = pyclray.render(scene, acceleration="bvh")
        with monkeypatch.context() as patch:
            patch.setattr(culling, "ENABLED", False)
            everything = pyclray.render(dataclasses.replace(scene), acceleration="tiles")  # a new scene: new lists
        assert (tiles["id"] >= 1).sum() > 50
        for name in tiles:
            assert np.array_equal(tiles[name], everything[name]) and np.array_equal(tiles[name], bvh[name]), name


def test_views_from_many_poses_are_those_of_their_own_scenes():
    """render_views and render(camera=...) with cameras from intrinsics (a data set of depth maps
    from many poses): each frame is the render of the scene with that camera, bit for bit, and
    holds that camera's K and pose; a camera without a size takes the scene's image's."""
    base = scene_of(K(50.0, 50.0, 30.0, 20.0))
    cameras = [pyclray.Camera.from_intrinsics(K(50.0 + 5 * k, 50.0 + 5 * k, 30.0 + k, 20.0 - k),
                                              np.array(POSE) + [[0, 0, 0, 0.2 * k], [0, 0, 0, 0], [0, 0, 0, -0.1 * k],
                                                                [0, 0, 0, 0]]) for k in range(3)]
    frames = list(pyclray.render_views(base, cameras, aovs=("depth", "id")))
    for camera, frame in zip(cameras, frames):
        alone = pyclray.render(dataclasses.replace(base, camera=camera), aovs=("depth", "id"))
        assert np.array_equal(frame["depth"], alone["depth"]) and np.array_equal(frame["id"], alone["id"])
        assert np.array_equal(frame.intrinsics, camera.K) and np.array_equal(frame.pose, camera.pose())
    assert np.array_equal(pyclray.render(base, aovs=("depth",), camera=cameras[1])["depth"], frames[1]["depth"])


# -- a look-at camera as K and a pose -------------------------------------------------------------
@pytest.mark.parametrize("name", ["tp02", "portrait", "room", "far", "shapes-lit", "sun"])
def test_a_look_at_camera_as_k_and_pose_renders_the_same_images(name):
    """Camera.from_intrinsics(camera.intrinsics(w, h), camera.pose()) has the same frame and eye,
    bit for bit, and image plane to float64 rounding (tan = w / (2 fx) rounds once more): its fp32
    images are the look-at camera's bit for bit, its fp64 images meet the oracle."""
    scene = pyclray.load_scene(SCENES / f"{name}.toml").with_size(72, 56)
    camera = scene.camera
    converted = pyclray.Camera.from_intrinsics(camera.intrinsics(72, 56), camera.pose())
    assert np.array_equal(converted.basis(), camera.basis()) and converted.eye == camera.eye
    assert np.array_equal(converted.intrinsics(72, 56), camera.intrinsics(72, 56))
    as_intrinsics = dataclasses.replace(scene, camera=converted)
    aovs = ("depth", "normal", "id", "zdepth", "position", "shaded")
    ours, theirs = pyclray.render(scene, aovs=aovs), pyclray.render(as_intrinsics, aovs=aovs)
    for aov in aovs:
        assert np.array_equal(ours[aov], theirs[aov]), aov
    _, directions = oracle.camera_rays(scene)
    assert np.abs(oracle.camera_rays(as_intrinsics)[1] - directions).max() < 1e-15
    if has_fp64(context_for().device):
        assert_matches_oracle(as_intrinsics, pyclray.render(as_intrinsics, precision="fp64"), precision="fp64")


# -- back-projection --------------------------------------------------------------------------------
@pytest.mark.parametrize("intrinsics", [K(40.0, 70.0, 45.25, 9.5), K(55.0, 55.0, 11.3, 40.7)], ids=["fx-fy", "off-centre"])
def test_the_depth_map_back_projects_onto_the_shapes(intrinsics):
    """pose @ (depth * normalize(K^-1 [i, j, 1])) (OpenCV's pixel centres, since the sensors issue)
    with the frame's own K and pose, in
    plain numpy, is the oracle's hit point to the depth's own error: the rays are the oracle's to
    float64 rounding, and the depth meets the error model."""
    scene = scene_of(intrinsics)
    frame = pyclray.render(scene, aovs=("depth", "id", "position"))
    assert np.array_equal(frame.intrinsics, intrinsics) and np.array_equal(frame.pose, POSE)
    j, i = np.mgrid[0:48, 0:64]
    pixels = np.stack([i, j, np.ones((48, 64))], axis=-1)
    rays = pixels @ np.linalg.inv(frame.intrinsics).T
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    origins, directions = oracle.camera_rays(scene)
    R, eye = frame.pose[:3, :3], frame.pose[:3, 3]
    assert np.abs(rays @ R.T - directions).max() < 1e-14
    ref = error_model.reference(scene)
    result = error_model.compare(frame, ref, engine="fp32")
    assert result["depth_ulps_max"] <= error_model.FP32_DEPTH_ULPS and result["id_mismatch"] == 0
    hit = (frame["id"] >= 0) & (frame["id"] == ref["id"])
    depth = frame["depth"].astype(np.float64)
    points = (np.where(hit, depth, 0)[..., None] * rays) @ R.T + eye
    truth = origins + np.where(hit, ref["depth"], 0)[..., None] * directions
    off = np.linalg.norm(points - truth, axis=-1)[hit]
    assert np.all(off <= np.abs(depth[hit] - ref["depth"][hit]) + 1e-12 * ref["depth"][hit])
    assert np.abs(points - frame["position"])[hit].max() < 1e-4  # and the position image says as much


def test_a_window_frame_holds_the_principal_point_of_its_own_pixels():
    scene = scene_of(K(40.0, 70.0, 45.25, 9.5))
    whole = pyclray.render(scene)
    part = pyclray.render(scene, window=(8, 16, 40, 20))
    assert np.array_equal(part.intrinsics, K(40.0, 70.0, 37.25, -6.5)) and np.array_equal(part.pose, whole.pose)
    assert np.array_equal(part["depth"], whole["depth"][16:36, 8:48])


# -- the EXR header ------------------------------------------------------------------------------
def test_the_exr_header_holds_k_and_the_pose(tmp_path):
    import OpenEXR

    scene = scene_of(K(40.0, 70.0, 45.25, 9.5))
    frame = pyclray.render(scene)
    pyclray.write_exr(tmp_path / "f.exr", frame)
    images, header = pyclray.read_exr(tmp_path / "f.exr", header=True)
    assert set(images) == {"depth", "normal", "id"} and np.array_equal(images["depth"], frame["depth"])
    assert header["intrinsics"].dtype == np.float64 and np.array_equal(header["intrinsics"], frame.intrinsics)
    assert np.array_equal(header["pose"], frame.pose)
    assert isinstance(pyclray.read_exr(tmp_path / "f.exr"), dict)  # without header=True: the images, as before
    # OpenEXR's own reader sees the attributes with their types (m33d, m44d, m44f)
    with OpenEXR.File(str(tmp_path / "f.exr")) as exr:
        attributes = dict(exr.header())
    assert attributes["intrinsics"].shape == (3, 3) and attributes["pose"].dtype == np.float64
    # worldToCamera: OpenEXR's convention, row vectors and camera x right, y up, z forward
    M = attributes["worldToCamera"].astype(np.float64)
    assert attributes["worldToCamera"].dtype == np.float32
    pose = frame.pose
    for camera_point in ([0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0]):  # OpenCV's: ahead, right, below
        world = pose[:3, :3] @ camera_point + pose[:3, 3]
        renderman = np.append(world, 1.0) @ M
        assert np.allclose(renderman[:3], np.multiply(camera_point, [1, -1, 1]), atol=1e-5) and renderman[3] == 1


def test_a_dict_of_images_is_written_without_a_camera(tmp_path):
    frame = pyclray.render(scene_of(K(40.0, 70.0, 45.25, 9.5)))
    pyclray.write_exr(tmp_path / "d.exr", dict(frame))
    _, header = pyclray.read_exr(tmp_path / "d.exr", header=True)
    assert "intrinsics" not in header and "pose" not in header and "worldToCamera" not in header


def test_the_render_command_writes_k_at_its_size(tmp_path):
    out = tmp_path / "i.exr"
    result = subprocess.run([sys.executable, "-m", "pyclray", "render", str(SCENES / "intrinsics.toml"), "-o", str(out),
                             "--size", "160x120", "--aov", "depth,zdepth"], capture_output=True, text=True,
                            env=dict(os.environ))
    assert result.returncode == 0, result.stderr
    images, header = pyclray.read_exr(out, header=True)
    scene = pyclray.load_scene(SCENES / "intrinsics.toml").with_size(160, 120)
    # 640x480's K / 4 (fx / 4, (cx + 1/2) / 4 - 1/2: OpenCV's convention, the file's cx = 329.5)
    assert np.array_equal(header["intrinsics"], K(131.25, 131.25, 82.0, 61.0))
    assert np.array_equal(header["pose"], scene.camera.pose())
    expected = pyclray.render(scene, aovs=("depth", "zdepth"))
    assert np.array_equal(images["depth"], expected["depth"]) and np.array_equal(images["zdepth"], expected["zdepth"])
    # z-depth back-projects with K alone: zdepth K^-1 [i, j, 1] is the hit in the camera's frame
    j, i = np.mgrid[0:120, 0:160]
    hit = np.isfinite(images["zdepth"])
    camera_points = images["zdepth"][hit][:, None] * (np.stack([i, j, np.ones((120, 160))], -1)[hit]
                                                      @ np.linalg.inv(header["intrinsics"]).T)
    assert np.allclose(np.linalg.norm(camera_points, axis=-1), images["depth"][hit], rtol=1e-5)


# -- the Mitsuba mapping -------------------------------------------------------------------------
def test_mitsubas_sensor_follows_the_principal_point_and_focal_length():
    """The sensor's own ray through each pixel centre is pyclray's pixel ray to float32 rounding
    (Mitsuba's principal_point_offset is added to the film position: offset = 0.5 - c / size, c the
    principal point from the image's corner: K's cx + 1/2 in OpenCV's convention)."""
    scene = scene_of(K(55.0, 55.0, 11.3, 40.7))
    sensor = mitsuba.sensor_of(scene)
    assert sensor["fov_axis"] == "x" and sensor["fov"] == pytest.approx(np.degrees(2 * np.arctan(64 / 110)))
    assert sensor["principal_point_offset_x"] == pytest.approx(0.5 - 11.8 / 64)
    assert sensor["principal_point_offset_y"] == pytest.approx(0.5 - 41.2 / 48)
    mitsuba.import_mitsuba("scalar_rgb")
    mi_scene, _ = mitsuba.load(scene, "scalar_rgb")
    rows, columns = np.mgrid[0:48:5, 0:64:7]
    _, directions = mitsuba.primary_rays(mi_scene, scene, rows.ravel(), columns.ravel())
    ours = oracle.camera_rays(scene)[1][rows.ravel(), columns.ravel()]
    angle = error_model.angle_between(directions, ours)
    assert angle.max() <= error_model.camera_angle_tolerance(scene)


@pytest.mark.parametrize("intrinsics", [K(55.0, 55.0, 11.3, 40.7), K(45.0, 45.0, -7.5, 36.0)], ids=["off-centre", "outside"])
def test_an_intrinsics_scene_agrees_with_mitsuba(intrinsics):
    scene = scene_of(intrinsics, 96, 72)
    images = check.cross_check(scene, "scalar_rgb")
    assert images.passed, images.failures
    assert images.counts["both hit the same shape"] > 96 * 72 // 3
    rays = check.ray_level(scene, "scalar_rgb", 256, seed=1)
    assert rays.passed, rays.failures


def test_the_check_refuses_unequal_focal_lengths_in_one_line(tmp_path):
    scene = scene_of(K(40.0, 70.0, 32.0, 24.0))
    with pytest.raises(SceneError, match="square pixels only") as error:
        mitsuba.sensor_of(scene)
    assert "table [camera]: key 'intrinsics'" in str(error.value)
    path = write(tmp_path, camera_table(K(40.0, 70.0, 32.0, 24.0)) + SCENE_REST)
    result = subprocess.run([sys.executable, "-m", "pyclray", "check", str(path)], capture_output=True, text=True,
                            env=dict(os.environ))
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.count("\n") == 1 and "fx = 40, fy = 70" in result.stderr, result.stderr
    # --size that changes the aspect ratio stretches the view: its pixels are no longer square
    result = subprocess.run([sys.executable, "-m", "pyclray", "check", str(SCENES / "intrinsics.toml"), "--size", "64x64"],
                            capture_output=True, text=True, env=dict(os.environ))
    assert result.returncode == 2 and "square pixels only" in result.stderr


def test_the_check_command_passes_on_the_intrinsics_scene():
    result = subprocess.run([sys.executable, "-m", "pyclray", "check", str(SCENES / "intrinsics.toml"),
                             "--size", "128x96", "--rays", "128"], capture_output=True, text=True, env=dict(os.environ),
                            cwd=REPO)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "passed: within the tolerance" in result.stdout


# -- animation -----------------------------------------------------------------------------------
ANIMATED = """
[animation]
fps = 2.0
duration = 2.0

[[animation.keys]]
target = "camera"
time = 0.0
{key} = {first}

[[animation.keys]]
target = "camera"
time = 1.5
{key} = {last}
"""


def test_an_intrinsics_camera_animates_its_eye(tmp_path):
    text = camera_table(K(50.0, 50.0, 30.0, 20.0)) + SCENE_REST + ANIMATED.format(
        key="eye", first="[2.5, 1.8, 4.2]", last="[0.5, 1.8, 5.2]")
    scene = pyclray.load_scene(write(tmp_path, text))
    at = scene.at(0.75)
    assert at.camera.eye == pytest.approx((1.5, 1.8, 4.7))
    assert np.array_equal(at.camera.pose()[:3, :3], scene.camera.pose()[:3, :3]) and at.camera.K == scene.camera.K
    frames = list(pyclray.render_animation(scene, aovs=("depth",), frames=[1]))
    assert np.array_equal(frames[0][1]["depth"], pyclray.render(scene.at(0.5), aovs=("depth",))["depth"])


@pytest.mark.parametrize("key, value", [("intrinsics", K(60.0, 60.0, 30.0, 20.0)), ("pose", POSE), ("fov", 30.0),
                                        ("target", [0.0, 0.0, 0.0]), ("K", K(60.0, 60.0, 30.0, 20.0))])
def test_keys_an_intrinsics_camera_cannot_animate_are_a_clear_error(tmp_path, key, value):
    text = camera_table(K(50.0, 50.0, 30.0, 20.0)) + SCENE_REST + ANIMATED.format(key=key, first=value, last=value)
    if key == "target":  # the camera's own "target" goes in values = {...}
        text = text.replace(f"target = {value!r}", f"values = {{ target = {value!r} }}")
    with pytest.raises(SceneError) as error:
        pyclray.load_scene(write(tmp_path, text))
    message = str(error.value)
    assert f"key {key!r}: cannot be animated" in message and "(expected one of: eye)" in message, message


def test_each_animated_frames_exr_holds_its_own_camera(tmp_path):
    """`pyclray animate` to a folder: frame k's header holds the camera at its time (the eye keyed)."""
    text = camera_table(K(50.0, 50.0, 30.0, 20.0)) + SCENE_REST + ANIMATED.format(
        key="eye", first="[2.5, 1.8, 4.2]", last="[0.5, 1.8, 5.2]")
    path = write(tmp_path, text)
    result = subprocess.run([sys.executable, "-m", "pyclray", "animate", str(path), "-o", str(tmp_path / "frames"),
                             "--aov", "depth"], capture_output=True, text=True, env=dict(os.environ))
    assert result.returncode == 0, result.stderr
    scene = pyclray.load_scene(path)
    for k in range(4):
        _, header = pyclray.read_exr(tmp_path / "frames" / f"frame_{k:05d}.exr", header=True)
        camera = scene.at(k / 2.0).camera
        assert np.array_equal(header["pose"], camera.pose()) and np.array_equal(header["intrinsics"], K(50.0, 50.0, 30.0, 20.0))
