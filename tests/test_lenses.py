"""The lens and panorama camera models against OpenCV's own projection and the float64 oracle.

Hit points a render reports (its float64 position image at fp64, its float32 one near the origin)
projected back with cv2.projectPoints / cv2.fisheye.projectPoints (the same K, pose and
coefficients) land within 1e-4 px of their pixel's centre: each pixel's ray is the exact inverse of
the lens, and pixels the lens cannot reach are misses. The depth, normal and id images meet the
float64 oracle of the model's own rays within the error model (pyclray.reference.error_model)."""
from __future__ import annotations

import dataclasses
import math
import re

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import pyclray
from pyclray.model.cameras import lens
from pyclray.reference import oracle

from oracle_checks import assert_agrees_with_oracle

WIDTH, HEIGHT = 96, 72
K = np.array([[70.0, 0.0, 47.5], [0.0, 70.0, 35.5], [0.0, 0.0, 1.0]])  # OpenCV's: centred at (W - 1) / 2
PIXEL = 1e-4  # the contract's bound on a hit point's projection, in pixels


def looking_at(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """A camera-to-world pose in OpenCV's axes (x right, y down, z forward) from eye to target."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, up)  # right = forward x up ... with y down
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, y, z, eye
    return pose


def enclosed(offset=(0.0, 0.0, 0.0)):
    """Shapes all round a point (a room: six walls as boxes, and spheres in it), so that every ray
    from it hits something at varied depths; offset moves the whole scene (and the cameras)."""
    o = np.asarray(offset, np.float64)
    shapes = [pyclray.Sphere(tuple(o + c), r) for c, r in (((0.0, 0.0, 4.0), 1.2), ((2.5, 1.0, 3.0), 0.8),
                                                            ((-2.0, -1.5, 2.5), 0.7), ((0.0, 0.0, -4.0), 1.0))]
    for axis in range(3):
        for side in (-1.0, 1.0):
            center, size = np.zeros(3), np.full(3, 12.0)
            center[axis], size[axis] = side * 6.5, 1.0
            shapes.append(pyclray.Box(tuple(o + center), tuple(size)))
    return tuple(shapes)


def projected_offsets(camera, frame, project):
    """|project(hit) - pixel centre| in pixels over the pixels that hit, and the hit mask."""
    hit = frame["id"] >= 0
    points = np.asarray(frame["position"], np.float64)[hit]
    extrinsic = camera.extrinsic()
    uv = project(points, extrinsic)
    j, i = np.nonzero(hit)
    return np.hypot(uv[:, 0] - i, uv[:, 1] - j), hit


def opencv(distortion):
    def project(points, extrinsic):
        rvec = cv2.Rodrigues(extrinsic[:3, :3])[0]
        uv, _ = cv2.projectPoints(points.reshape(-1, 1, 3), rvec, extrinsic[:3, 3], K, np.asarray(distortion, np.float64))
        return uv.reshape(-1, 2)
    return project


def opencv_fisheye(distortion, camera):
    """cv2.fisheye.projectPoints for points in front of the camera (z > 0); behind it (a 190-degree
    lens's rim) OpenCV's fisheye takes atan(r) of x / z, which folds the point to the front, so
    there the same model is written out here with theta = atan2(|xy|, z), the angle it means."""
    def project(points, extrinsic):
        in_camera = points @ extrinsic[:3, :3].T + extrinsic[:3, 3]
        front = in_camera[:, 2] > 1e-9 * np.linalg.norm(in_camera, axis=1)
        uv = np.empty((len(points), 2))
        rvec = cv2.Rodrigues(extrinsic[:3, :3])[0]
        if front.any():
            found, _ = cv2.fisheye.projectPoints(points[front].reshape(-1, 1, 3), rvec, extrinsic[:3, 3], K,
                                                 np.asarray(distortion, np.float64))
            uv[front] = found.reshape(-1, 2)
        back = in_camera[~front]
        r = np.hypot(back[:, 0], back[:, 1])
        theta_d = lens.fisheye_theta_d(distortion, np.arctan2(r, back[:, 2]))
        uv[~front, 0] = K[0, 0] * theta_d * back[:, 0] / r + K[0, 2]
        uv[~front, 1] = K[1, 1] * theta_d * back[:, 1] / r + K[1, 2]
        return uv
    return project


LENSES = {
    "barrel k1 = -0.4": [-0.4, 0.0, 0.0, 0.0],
    "pincushion k1 = +0.3": [0.3, 0.0, 0.0, 0.0],
    "full model": [-0.28, 0.07, 0.0002, -0.0001, 0.01, 0.05, -0.01, 0.002],
}


@pytest.mark.parametrize("offset", [0.0, 1e5], ids=["origin", "1e5 away"])
@pytest.mark.parametrize("name", list(LENSES))
def test_distorted_hits_project_back_onto_their_pixel_centres_with_opencv(name, offset):
    """fp64 renders (float64 hit points): every hit within 1e-4 px of its pixel's centre, the
    pixels beyond a barrel's fold misses, and the images those of the oracle of the model's rays."""
    needs_fp64()
    shift = (offset, -offset / 2, offset / 3)
    camera = pyclray.Camera.from_intrinsics(K, looking_at(np.add(shift, (0.5, 0.3, 0.0)), np.add(shift, (0.0, 0.0, 4.0))),
                                            WIDTH, HEIGHT, distortion=LENSES[name])
    scene = pyclray.Scene(camera, pyclray.Image(WIDTH, HEIGHT), enclosed(shift))
    frame = pyclray.render(scene, aovs=("depth", "normal", "id", "position"), precision="fp64")
    off, hit = projected_offsets(camera, frame, opencv(LENSES[name]))
    _, field = camera.space_directions(WIDTH, HEIGHT)
    assert np.array_equal(hit, field)  # the room is closed: every pixel in the field hits, the others miss
    assert off.max() < PIXEL, f"{name}: a hit {off.max():.3g} px from its pixel's centre"
    if name.startswith("barrel"):  # its radial map folds at r = 1 / sqrt(1.2): the image's corners are beyond
        assert 0.1 < (~field).mean() < 0.5 and not field[0, 0] and field[HEIGHT // 2, WIDTH // 2]
    origins, directions = camera.rays(WIDTH, HEIGHT)
    mine = field.reshape(-1)
    result = {k: np.asarray(frame[k]).reshape(len(mine), -1).squeeze()[mine] for k in ("depth", "normal", "id")}
    assert_agrees_with_oracle(scene, origins.reshape(-1, 3)[mine], directions.reshape(-1, 3)[mine], result, "fp64",
                              reference_point=np.array(camera.eye))


@pytest.mark.parametrize("lanes,offset", [(None, 0.0), ("1", 0.0), (None, 1e5)], ids=["lanes", "lanes=1", "1e5 away"])
@pytest.mark.parametrize("name", ["barrel k1 = -0.4", "pincushion k1 = +0.3"])
def test_fp32_distorted_renders_meet_opencv_and_the_oracle(name, lanes, offset, monkeypatch):
    """fp32, with the device's lanes and with PYCLRAY_LANES=1: the float32 hit points project within
    1e-4 px (their rounding is ~1e-7 of their distance), the images meet the oracle. 1e5 away a
    float32 position is only good to 2^-7 (0.1 px here), so there the hit point is the eye plus the
    fp32 depth along the model's float64 ray, and the kernel's rays are judged by the oracle."""
    if lanes:
        monkeypatch.setenv("PYCLRAY_LANES", lanes)
        pyclray.clear_cache()
    shift = (offset, -offset / 2, offset / 3)
    camera = pyclray.Camera.from_intrinsics(K, looking_at(np.add(shift, (0.5, 0.3, 0.0)), np.add(shift, (0.0, 0.0, 4.0))),
                                            WIDTH, HEIGHT, distortion=LENSES[name])
    scene = pyclray.Scene(camera, pyclray.Image(WIDTH, HEIGHT), enclosed(shift))
    frame = pyclray.render(scene, aovs=("depth", "normal", "id", "position"))
    origins, directions = camera.rays(WIDTH, HEIGHT)
    if offset:
        frame = dict(frame)
        frame["position"] = origins + np.where(frame["id"] >= 0, frame["depth"], 0.0)[..., None] * directions
    off, hit = projected_offsets(camera, frame, opencv(LENSES[name]))
    assert np.array_equal(hit, camera.space_directions(WIDTH, HEIGHT)[1]) and off.max() < PIXEL
    mine = hit.reshape(-1)
    result = {k: np.asarray(frame[k]).reshape(len(mine), -1).squeeze()[mine] for k in ("depth", "normal", "id")}
    assert_agrees_with_oracle(scene, origins.reshape(-1, 3)[mine], directions.reshape(-1, 3)[mine], result, "fp32",
                              reference_point=np.array(camera.eye))
    if lanes:
        pyclray.clear_cache()


@pytest.mark.parametrize("precision,lanes", [("fp32", None), ("fp64", None), ("fp32", "1")])
def test_a_190_degree_fisheye_reaches_behind_its_plane_and_no_further(precision, lanes, monkeypatch):
    """A circular 190-degree fisheye in the closed room: the pixels within the 95-degree circle hit
    (also the rim behind the camera's plane), the border misses, every hit projects within 1e-4 px
    (fp32 hit points: their float32 rounding, 1e-7 of ~6 units, is ~1e-5 px at f = 25)."""
    if precision == "fp64":
        needs_fp64()
    if lanes:
        monkeypatch.setenv("PYCLRAY_LANES", lanes)
    distortion = [0.02, -0.005, 0.001, -0.0002]
    fisheye_K = np.array([[25.0, 0.0, 47.5], [0.0, 25.0, 35.5], [0.0, 0.0, 1.0]])
    camera = pyclray.Fisheye.from_intrinsics(fisheye_K, looking_at((0.2, 0.1, 0.0), (0.0, 0.0, 4.0)), WIDTH, HEIGHT,
                                             distortion=distortion, fov=190.0)
    scene = pyclray.Scene(camera, pyclray.Image(WIDTH, HEIGHT), enclosed())
    frame = pyclray.render(scene, aovs=("depth", "normal", "id", "position"), precision=precision)
    global K
    saved, K = K, fisheye_K
    try:
        off, hit = projected_offsets(camera, frame, opencv_fisheye(distortion, camera))
    finally:
        K = saved
    _, field = camera.space_directions(WIDTH, HEIGHT)
    assert np.array_equal(hit, field) and off.max() < PIXEL, off.max()
    # the field's edge: theta_d(95 degrees) from the principal point
    j, i = np.mgrid[0:HEIGHT, 0:WIDTH]
    radius = np.hypot(i - 47.5, j - 35.5) / 25.0
    edge = lens.fisheye_theta_d(distortion, math.radians(95.0))
    assert np.array_equal(field, radius <= edge) or np.abs(radius[field != (radius <= edge)] - edge).max() < 1e-12
    in_camera = (np.asarray(frame["position"], np.float64)[hit] - camera.eye) @ camera.pose()[:3, :3]
    assert (in_camera[:, 2] < 0).sum() > 10  # hits behind the camera's plane: beyond 90 degrees
    origins, directions = camera.rays(WIDTH, HEIGHT)
    mine = hit.reshape(-1)
    result = {k: np.asarray(frame[k]).reshape(len(mine), -1).squeeze()[mine] for k in ("depth", "normal", "id")}
    assert_agrees_with_oracle(scene, origins.reshape(-1, 3)[mine], directions.reshape(-1, 3)[mine], result, precision,
                              reference_point=np.array(camera.eye))


def test_a_lens_without_distortion_is_the_pinhole_on_every_ray_they_share():
    """Zero coefficients: the lens's rays are the pinhole's to float64 rounding, so the two fp64
    renders agree on every pixel (ids equal, depths within a few ulps: the two rays differ by the
    rounding of the pinhole kernel's own arithmetic); the principal point's ray is the optical axis
    in both, bit for bit, and so is its depth."""
    needs_fp64()
    pose = looking_at((0.5, 0.3, 0.0), (0.0, 0.0, 4.0))
    centred = K + [[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]]  # the principal point at pixel (36, 48)'s centre
    size = (WIDTH + 1, HEIGHT + 1)
    pinhole = pyclray.Camera.from_intrinsics(centred, pose, *size)
    lensed = pyclray.Camera.from_intrinsics(centred, pose, *size, distortion=[0.0, 0.0, 0.0, 0.0])
    assert np.abs(lensed.rays(*size)[1] - pinhole.rays(*size)[1]).max() < 4e-16
    image = pyclray.Image(*size)
    a = pyclray.render(pyclray.Scene(pinhole, image, enclosed()), aovs=("depth", "id"), precision="fp64")
    b = pyclray.render(pyclray.Scene(lensed, image, enclosed()), aovs=("depth", "id"), precision="fp64")
    assert np.array_equal(a["id"], b["id"]) and np.abs(a["depth"] / b["depth"] - 1).max() < 1e-14
    assert a["depth"][36, 48] == b["depth"][36, 48]
    # and a distorted render agrees with the pinhole on the ray they share, the principal point's, bit for bit
    barrel = pyclray.Camera.from_intrinsics(centred, pose, *size, distortion=[-0.4, 0.0, 0.0, 0.0])
    c = pyclray.render(pyclray.Scene(barrel, image, enclosed()), aovs=("depth", "id"), precision="fp64")
    assert c["depth"][36, 48] == a["depth"][36, 48] and c["id"][36, 48] == a["id"][36, 48]


def needs_fp64():
    from pyclray.engine.opencl.device import context_for, has_fp64

    if not has_fp64(context_for(None).device):
        pytest.skip("device lacks cl_khr_fp64")


@pytest.mark.parametrize("precision,lanes", [("fp32", None), ("fp64", None), ("fp32", "1")])
def test_equirectangular_renders_the_oracles_panorama(precision, lanes, monkeypatch):
    """The whole sphere of directions in the closed room: every pixel hits; the images meet the
    oracle of the model's rays; row 0 looks up, the centre column ahead, longitude grows rightwards."""
    if precision == "fp64":
        needs_fp64()
    if lanes:
        monkeypatch.setenv("PYCLRAY_LANES", lanes)
    camera = pyclray.Equirectangular((0.5, 0.3, 0.0), (0.0, 0.3, 4.0))
    scene = pyclray.Scene(camera, pyclray.Image(WIDTH, HEIGHT // 2 * 2), enclosed())
    frame = pyclray.render(scene, aovs=("depth", "normal", "id"), precision=precision)
    assert (frame["id"] >= 0).all()
    origins, directions = camera.rays(WIDTH, HEIGHT)
    # the contract's pixel centres, for a panorama looking along +z with +y up (its right is -x):
    # longitude -180 + (i + 0.5) 360 / W, latitude 90 - (j + 0.5) 180 / H: row 0 at the top
    straight = pyclray.Equirectangular((0.5, 0.3, 0.0), (0.5, 0.3, 4.0)).rays(WIDTH, HEIGHT)[1]
    j, i = np.mgrid[0:HEIGHT, 0:WIDTH]
    lon, lat = np.radians(-180 + (i + 0.5) * 360 / WIDTH), np.radians(90 - (j + 0.5) * 180 / HEIGHT)
    expected = np.stack([-np.cos(lat) * np.sin(lon), np.sin(lat), np.cos(lat) * np.cos(lon)], axis=-1)
    assert np.abs(straight - expected).max() < 1e-15
    result = {k: np.asarray(frame[k]).reshape(WIDTH * HEIGHT, -1).squeeze() for k in ("depth", "normal", "id")}
    assert_agrees_with_oracle(scene, origins.reshape(-1, 3), directions.reshape(-1, 3), result, precision,
                              reference_point=np.array(camera.eye))


def test_orthographic_renders_the_oracles_parallel_rays():
    """Depth from the plane through the eye, every ray the oracle's."""
    camera = pyclray.Orthographic((0.5, 0.3, 0.0), (0.0, 0.0, 4.0), height=3.0)
    scene = pyclray.Scene(camera, pyclray.Image(WIDTH, HEIGHT), enclosed())
    frame = pyclray.render(scene, aovs=("depth", "normal", "id", "zdepth", "position", "label"))
    origins, directions = camera.rays(WIDTH, HEIGHT)
    result = {k: np.asarray(frame[k]).reshape(WIDTH * HEIGHT, -1).squeeze() for k in ("depth", "normal", "id")}
    assert_agrees_with_oracle(scene, origins.reshape(-1, 3), directions.reshape(-1, 3), result, "fp32")
    assert np.array_equal(frame["zdepth"], frame["depth"]) and (frame["label"] == -1).all()
    assert np.abs(frame["position"] - (origins + frame["depth"][..., None] * directions)).max() < 1e-5
    truth = oracle.trace(scene, origins.reshape(-1, 3), directions.reshape(-1, 3), aovs=("depth",))
    assert np.isfinite(truth["depth"]).all()


@pytest.mark.parametrize("table,key,part", [
    ({"intrinsics": K.tolist(), "pose": np.eye(4).tolist(), "distortion": [0.1, 0.2, 0.3]}, "distortion", "k1, k2, p1, p2"),
    ({"intrinsics": K.tolist(), "pose": np.eye(4).tolist(), "distortion": [0.1, "x", 0.0, 0.0]}, "distortion[1]", "number"),
    ({"intrinsics": K.tolist(), "pose": np.eye(4).tolist(), "pixel_origin": "middle"}, "pixel_origin", "corner"),
    ({"model": "fisheye", "intrinsics": K.tolist(), "pose": np.eye(4).tolist(), "distortion": [0.1, 0.0]}, "distortion",
     "k1, k2, k3, k4"),
    ({"model": "fisheye", "intrinsics": K.tolist(), "pose": np.eye(4).tolist(), "fov": 400.0}, "fov", "0 < fov <= 360"),
    ({"model": "fisheye", "intrinsics": K.tolist(), "pose": np.eye(4).tolist(), "focal": 1.0}, "focal", "unknown key"),
    ({"model": "orthographic", "eye": [0, 0, 1], "target": [0, 0, 0], "height": 0.0}, "height", "> 0"),
    ({"model": "orthographic", "eye": [0, 0, 1], "target": [0, 0, 1]}, "target", "target != eye"),
    ({"model": "equirectangular", "eye": [0, 0, 1], "latitude": [-100.0, 90.0]}, "latitude", "-90 <= min"),
    ({"model": "equirectangular", "eye": [0, 0, 1], "longitude": [10.0, 0.0]}, "longitude", "min < max"),
    ({"model": "equirectangular", "eye": [0, 0, 1], "fov": 90.0}, "fov", "unknown key"),
    ({"eye": [0, 0, 1], "target": [0, 0, 0], "distortion": [-0.3, 0, 0, 0]}, "distortion", "intrinsics and a pose"),
])
def test_bad_keys_and_impossible_lenses_are_one_line_naming_the_key(table, key, part):
    with pytest.raises(pyclray.SceneError) as caught:
        pyclray.scene_from_dict({"camera": table})
    message = str(caught.value)
    assert caught.value.key == key and part in message and "\n" not in message


def test_a_lens_that_folds_before_any_pixel_but_the_centre_still_renders_the_centre():
    """k1 = -5: the fold at r = 0.26 (normalized), reached 18 px from the principal point: the
    pixels beyond are misses, the rest hits."""
    camera = pyclray.Camera.from_intrinsics(K, looking_at((0.5, 0.3, 0.0), (0.0, 0.0, 4.0)), WIDTH, HEIGHT,
                                            distortion=[-5.0, 0.0, 0.0, 0.0])
    frame = pyclray.render(pyclray.Scene(camera, pyclray.Image(WIDTH, HEIGHT), enclosed()), aovs=("id",))
    j, i = np.mgrid[0:HEIGHT, 0:WIDTH]
    r = np.hypot(i - 47.5, j - 35.5) / 70.0
    fold = 1 / math.sqrt(15.0)  # d/dr (r - 5 r^3) = 0
    reach = fold - 5 * fold**3
    assert np.array_equal(frame["id"] >= 0, r < reach) or np.abs(r[(frame["id"] >= 0) != (r < reach)] - reach).max() < 1e-9


def test_poses_and_extrinsics_in_both_conventions():
    """pose("opengl") is pose() with y and z negated; extrinsic() its inverse; from_intrinsics
    takes either convention back to the same camera."""
    pose = looking_at((1.0, 2.0, 3.0), (0.0, 0.5, 0.0))
    for camera in (pyclray.Camera.from_intrinsics(K, pose, WIDTH, HEIGHT),
                   pyclray.Fisheye.from_intrinsics(K, pose, WIDTH, HEIGHT),
                   pyclray.Orthographic((1.0, 2.0, 3.0), (0.0, 0.5, 0.0)),
                   pyclray.Equirectangular((1.0, 2.0, 3.0), (0.0, 0.5, 0.0)),
                   pyclray.Camera((1.0, 2.0, 3.0), (0.0, 0.5, 0.0))):
        assert np.abs(camera.pose() - pose).max() < 1e-15
        assert np.abs(camera.pose(convention="opengl") - pose * [1, -1, -1, 1]).max() < 1e-15
        assert np.abs(camera.extrinsic() @ camera.pose() - np.eye(4)).max() < 1e-15
    gl = pyclray.Camera.from_intrinsics(K, pose * [1, -1, -1, 1], WIDTH, HEIGHT, convention="opengl")
    assert np.abs(gl.pose() - pose).max() < 1e-15
    with pytest.raises(pyclray.SceneError, match="key 'convention'"):
        pyclray.Camera.from_intrinsics(K, pose, convention="blender")
    with pytest.raises(pyclray.RequestError, match="convention"):
        gl.pose(convention="blender")
    assert pyclray.Orthographic((1.0, 2.0, 3.0), (0.0, 0.5, 0.0)).intrinsics(WIDTH, HEIGHT) is None


def test_a_scene_file_with_each_model(tmp_path):
    path = tmp_path / "lens.toml"
    path.write_text("[camera]\nintrinsics = [[70.0, 0.0, 47.5], [0.0, 70.0, 35.5], [0.0, 0.0, 1.0]]\n"
                    "pose = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\ndistortion = [-0.28, 0.07, 0.0002, -0.0001, 0.0]\n"
                    "[image]\nwidth = 96\nheight = 72\n"
                    "[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 4.0]\nradius = 1.0\n")
    scene = pyclray.load_scene(path)
    assert scene.camera.distortion == (-0.28, 0.07, 0.0002, -0.0001, 0.0, 0.0, 0.0, 0.0)
    frame = pyclray.render(scene, aovs=("depth",))
    assert np.isfinite(frame["depth"][36, 48]) and np.array_equal(frame.intrinsics, K)


@pytest.mark.parametrize("camera", [
    pyclray.Fisheye.from_intrinsics(K, looking_at((0.5, 0.3, 0.0), (0.0, 0.0, 4.0)), WIDTH, HEIGHT,
                                    distortion=[0.02, -0.005, 0.001, 0.0], fov=190.0),
    pyclray.Camera.from_intrinsics(K, looking_at((0.5, 0.3, 0.0), (0.0, 0.0, 4.0)), WIDTH, HEIGHT, distortion=[-0.3, 0.0, 0.0, 0.0]),
    pyclray.Orthographic((0.5, 0.3, 0.0), (0.0, 0.0, 4.0), height=3.0),
    pyclray.Equirectangular((0.5, 0.3, 0.0), (0.0, 0.0, 4.0), longitude=(-90.0, 90.0)),
], ids=["fisheye", "distorted", "orthographic", "equirectangular"])
def test_the_views_controls_orbit_every_model_and_copy_it_as_toml(camera):
    """pyclray view's orbit keeps the model (its lens, K, field) and its copied [camera] table loads
    as the same camera."""
    import tomllib

    from pyclray.apps.view.controls import Orbit, camera_toml
    from pyclray.model.loader import camera_from_table

    moved = Orbit.of(camera).orbit(0.1, 0.05).camera()
    assert type(moved) is type(camera) and moved.eye != camera.eye
    assert getattr(moved, "distortion", None) == getattr(camera, "distortion", None)
    loaded = camera_from_table(tomllib.loads(camera_toml(moved))["camera"])
    assert type(loaded) is type(camera) and np.abs(loaded.pose() - moved.pose()).max() < 1e-11
    assert np.abs(loaded.rays(WIDTH, HEIGHT)[1] - moved.rays(WIDTH, HEIGHT)[1]).max() < 1e-11


@pytest.mark.parametrize("camera", [
    pyclray.Camera.from_intrinsics(K, looking_at((0.5, 0.3, 0.0), (0.0, 0.0, 4.0)), WIDTH, HEIGHT, distortion=[-0.4, 0.0, 0.0, 0.0]),
    pyclray.Camera.from_intrinsics(K, looking_at((0.5, 0.3, 0.0), (0.0, 0.0, 4.0)), WIDTH, HEIGHT,
                                   distortion=[0.3, 0.05, 0.002, -0.001, 0.0, 0.1, 0.0, 0.0]),
    pyclray.Fisheye.from_intrinsics(np.array([[25.0, 0.0, 47.5], [0.0, 25.0, 35.5], [0.0, 0.0, 1.0]]),
                                    looking_at((0.5, 0.3, 0.0), (0.0, 0.0, 4.0)), WIDTH, HEIGHT, fov=190.0),
    pyclray.Equirectangular((0.5, 0.3, 0.0), (0.0, 0.0, 4.0)),
], ids=["barrel", "pincushion", "fisheye", "equirectangular"])
def test_tile_lists_of_a_lens_cull_nothing_a_ray_meets(camera):
    """A lens's tiles are culled by the rectangles their rays span on the image plane (a tile with a
    ray behind the eye's plane visits everything): the images through tile lists and through the
    BVH are the same, bit for bit, with many small shapes (so that culling leaves most out)."""
    rng = np.random.default_rng(3)
    spheres = pyclray.Spheres(rng.uniform(-5, 5, (400, 3)), rng.uniform(0.05, 0.3, 400))
    scene = pyclray.Scene(camera, pyclray.Image(WIDTH, HEIGHT), enclosed() + (spheres,))
    tiles = pyclray.render(scene, aovs=("depth", "id"), acceleration="tiles")
    bvh = pyclray.render(scene, aovs=("depth", "id"), acceleration="bvh")
    assert np.array_equal(tiles["id"], bvh["id"]) and np.array_equal(tiles["depth"], bvh["depth"])
    assert (tiles["id"] >= 4).sum() > 100  # the small spheres are seen
    from pyclray.engine.scene import views

    with pyclray.prepare(scene) as tracer:  # and the lists do leave most of them out of most tiles
        kind = tracer.prepared.kinds["spheres"]
        start, _ = views.view_tile_lists(tracer.prepared, kind, scene)
        assert start[-1] < 0.75 * kind.count * (len(start) - 1)


def test_pyclray_check_passes_an_orthographic_scene_against_mitsubas_sensor(tmp_path, capsys):
    """pyclray check: the same rays as Mitsuba's orthographic sensor (its ray origins on the plane
    through the eye, to float32 rounding), the images, the rays and the shaded image (under a point
    light, with the sphere's shadow on the plane) within the error model."""
    from pyclray.apps import cli

    path = tmp_path / "ortho.toml"
    path.write_text('[camera]\nmodel = "orthographic"\neye = [0.5, 3.0, 6.0]\ntarget = [0.0, 0.5, 0.0]\nheight = 4.0\n'
                    "[image]\nwidth = 48\nheight = 36\n"
                    '[[shapes]]\ntype = "sphere"\ncenter = [0.0, 0.5, 0.0]\nradius = 1.0\n'
                    '[[shapes]]\ntype = "box"\ncenter = [1.5, 0.0, 0.5]\nsize = [1.0, 1.0, 1.0]\n'
                    '[[shapes]]\ntype = "plane"\nnormal = [0.0, 1.0, 0.0]\noffset = 0.5\n'
                    '[[lights]]\ntype = "point"\nposition = [-2.0, 5.0, 1.0]\nintensity = 30.0\n')
    status = cli.main(["check", str(path), "--rays", "256"])
    out = capsys.readouterr().out
    assert status == 0, out
    assert "passed: within the tolerance" in out and "both hit the same shape" in out
    # the shaded image too (its shadow rays cast: engine/queries/shade.py) against Mitsuba's direct integrator
    found = re.search(r"judged (\d+) pixels \((\d+) lit, (\d+) in shadow\)", out)
    assert "shaded: not compared" not in out and found and int(found[2]) > 200 and int(found[3]) > 20, out


def test_a_distorted_camera_cannot_be_checked_against_mitsuba_and_says_why(tmp_path, capsys):
    from pyclray.apps import cli

    path = tmp_path / "lens.toml"
    path.write_text("[camera]\nintrinsics = [[70.0, 0.0, 47.5], [0.0, 70.0, 35.5], [0.0, 0.0, 1.0]]\n"
                    "pose = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\ndistortion = [-0.3, 0.0, 0.0, 0.0]\n"
                    "[image]\nwidth = 96\nheight = 72\n"
                    '[[shapes]]\ntype = "sphere"\ncenter = [0.0, 0.0, 4.0]\nradius = 1.0\n')
    assert cli.main(["check", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "key 'distortion'" in err[0] and "no lens distortion" in err[0]


def test_files_of_a_model_without_k_hold_its_pose(tmp_path):
    """An orthographic or panorama render's .npz and EXR hold the pose (no K: the model has none)."""
    from pyclray.apps import cli

    path = tmp_path / "pano.toml"
    path.write_text('[camera]\nmodel = "equirectangular"\neye = [0.0, 1.0, 0.0]\n[image]\nwidth = 32\nheight = 16\n'
                    '[[shapes]]\ntype = "sphere"\ncenter = [0.0, 1.0, -4.0]\nradius = 1.0\n')
    camera = pyclray.load_scene(path).camera
    assert cli.main(["render", str(path), "-o", str(tmp_path / "p.npz")]) == 0
    with np.load(tmp_path / "p.npz") as data:
        assert "K" not in data.files and np.array_equal(data["pose"], camera.pose())
    assert cli.main(["render", str(path), "-o", str(tmp_path / "p.exr")]) == 0
    _, header = pyclray.read_exr(tmp_path / "p.exr", header=True)
    assert "intrinsics" not in header and np.array_equal(header["pose"], camera.pose())


# -- the inverse itself, over random lenses -------------------------------------------------------
coefficient = st.floats(-0.6, 0.6, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(st.tuples(coefficient, coefficient, st.floats(-0.01, 0.01), st.floats(-0.01, 0.01), coefficient,
                 st.floats(0.0, 0.3), st.floats(0.0, 0.1), st.floats(0.0, 0.05)))
def test_the_inverse_maps_back_and_misses_only_what_the_lens_cannot_reach(coefficients):
    """For any lens of OpenCV's radial-tangential model: every pixel kept maps back onto itself
    through cv2.projectPoints (within 1e-7 px), inside the fold; no pixel beyond what the radial map
    reaches before its fold (plus the tangential terms' reach) is kept, and all well inside it are."""
    j, i = np.mgrid[0:HEIGHT:5, 0:WIDTH:5].astype(np.float64)
    xd, yd = (i - K[0, 2]) / K[0, 0], (j - K[1, 2]) / K[1, 1]
    x, y, valid = lens.undistort_pinhole(coefficients, xd, yd)
    if valid.any():
        points = np.stack([x[valid], y[valid], np.ones(valid.sum())], axis=-1)
        uv, _ = cv2.projectPoints(points.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, np.array(coefficients))
        assert np.abs(uv.reshape(-1, 2) - np.stack([i[valid], j[valid]], axis=-1)).max() < 1e-7
        assert np.all(np.hypot(x[valid], y[valid]) < lens.pinhole_fold(coefficients))
    fold = lens.pinhole_fold(coefficients)
    r = np.linspace(0, min(fold, 1e3), 20001)
    factor, _, _ = lens.radial_pinhole(coefficients, r * r)
    reach = (r * factor).max()
    rd = np.hypot(xd, yd)
    # the tangential terms move a pixel by at most ~3 |p| r^2: beyond that margin of the radial reach, all misses
    margin = 3 * (abs(coefficients[2]) + abs(coefficients[3])) * min(fold, 1e3) ** 2
    assert not np.any(valid & (rd > reach * (1 + 1e-9) + margin))
    if margin < 1e-3:  # and well inside the radial reach, every pixel is kept
        assert np.all(valid[rd < 0.5 * reach])


def test_a_moving_lens_camera_solves_its_lens_once(tmp_path):
    """An animation keying a distorted camera's eye: every frame renders through the same lens,
    whose table is solved once (kept by value) and each frame's images are its own view's."""
    lens.pinhole_table.cache_clear()
    pose = looking_at((0.5, 0.3, 0.0), (0.0, 0.0, 4.0))
    cameras = [pyclray.Camera.from_intrinsics(K, pose_shifted(pose, 0.1 * k), WIDTH, HEIGHT, distortion=[-0.3, 0.0, 0.0, 0.0])
               for k in range(4)]
    scene = pyclray.Scene(cameras[0], pyclray.Image(WIDTH, HEIGHT), enclosed())
    frames = list(pyclray.render_views(scene, cameras, aovs=("depth",)))
    assert lens.pinhole_table.cache_info().misses == 1
    for camera, frame in zip(cameras, frames):
        alone = pyclray.render(dataclasses.replace(scene, camera=camera), aovs=("depth",))
        assert np.array_equal(frame["depth"], alone["depth"])


def pose_shifted(pose, dx):
    shifted = pose.copy()
    shifted[0, 3] += dx
    return shifted
