"""The view's camera controls (pyclray/apps/view/controls.py) in float64: an orbit keeps the eye's
distance to the target and never passes the pole, a pan carries the point at the target with the
mouse, the wheel scales the distance, and "copy camera" writes a [camera] table that loads back."""
import math
import tomllib

import numpy as np
import pytest

import pyclray
from conftest import REPO
from pyclray.apps.view.controls import DOLLY_PER_NOTCH, POLE_MARGIN, Orbit, camera_toml
from pyclray.model.loader import camera_from_table

TP02 = pyclray.load_scene(REPO / "scenes/tp02.toml").camera
INTRINSICS = pyclray.load_scene(REPO / "scenes/intrinsics.toml").camera


def distance(orbit):
    return math.dist(orbit.eye, orbit.target)


def test_an_orbit_turns_about_the_target_and_a_full_drag_is_a_full_turn():
    start = Orbit.of(TP02)
    turned = start.orbit(0.1, 0.05)
    assert turned.target == start.target and distance(turned) == pytest.approx(distance(start), rel=1e-14)
    assert turned.eye != start.eye
    # a drag across the image's height, sideways, is one turn about the up axis (OrbitControls)
    assert np.allclose(start.orbit(1.0, 0.0).eye, start.eye, atol=1e-12)
    # dragging right moves the eye to the scene's left (-x here: it looks down -z), the scene turns right
    assert start.orbit(0.05, 0.0).eye[0] < 0


@pytest.mark.parametrize("dy", [0.3, -0.3, 5.0, -5.0])
def test_an_orbit_stops_short_of_the_pole(dy):
    """However far the drag, the view direction stays POLE_MARGIN away from the up axis (a camera
    looking along its up is degenerate)."""
    orbit = Orbit.of(TP02)
    for _ in range(3):
        orbit = orbit.orbit(0.0, dy)
        offset = np.subtract(orbit.eye, orbit.target)
        polar = math.acos(offset @ np.array(orbit.up) / np.linalg.norm(offset))
        assert POLE_MARGIN * (1 - 1e-9) <= polar <= math.pi - POLE_MARGIN * (1 - 1e-9)
        orbit.camera().basis()  # a valid camera


@pytest.mark.parametrize("camera, size", [(TP02, (512, 512)), (TP02, (640, 360)), (INTRINSICS, (640, 480))])
def test_a_pan_carries_the_point_at_the_target_with_the_mouse(camera, size):
    """After a pan by (dx, dy) image heights, the old target is seen dx heights right of and dy
    below where it was (OrbitControls' pan), projected with the new camera's K and pose."""
    width, height = size
    start = Orbit.of(camera)

    def pixel(cam, point):
        K, pose = cam.intrinsics(width, height), cam.pose()
        local = pose[:3, :3].T @ (np.asarray(point) - pose[:3, 3])
        return (K @ (local / local[2]))[:2]

    before = pixel(start.camera(), start.target)
    moved = start.pan(0.25, -0.1, width, height)
    assert np.allclose(np.subtract(moved.eye, start.eye), np.subtract(moved.target, start.target), atol=1e-12)
    after = pixel(moved.camera(), start.target)
    assert np.allclose(after - before, [0.25 * height, -0.1 * height], atol=1e-9)


def test_the_wheel_scales_the_distance_by_notches_and_never_reaches_the_target():
    start = Orbit.of(TP02)
    assert distance(start.dolly(-2)) == pytest.approx(distance(start) * DOLLY_PER_NOTCH**2, rel=1e-14)
    assert distance(start.dolly(3)) == pytest.approx(distance(start) / DOLLY_PER_NOTCH**3, rel=1e-14)
    near = start
    for _ in range(100):
        near = near.dolly(-20)
    assert 0 < distance(near) and near.camera().basis() is not None


@pytest.mark.parametrize("camera", [TP02, INTRINSICS, pyclray.Camera((1e-3, 5e6, -2.5), (0, 0, 0.125), (0, 0, 1), 30.5, "y")])
def test_copy_camera_writes_a_table_that_loads_as_the_view(camera):
    """The scene's own camera comes back (to float64 rounding); a moved one to the 12 digits written."""
    start = Orbit.of(camera)
    assert camera_from_table(tomllib.loads(camera_toml(start.camera()))["camera"]).pose() == pytest.approx(camera.pose(), abs=1e-12)
    moved = start.orbit(0.123, 0.0456).camera()
    loaded = camera_from_table(tomllib.loads(camera_toml(moved))["camera"])
    scale = max(1.0, float(np.abs(moved.pose()).max()))
    assert np.allclose(loaded.pose(), moved.pose(), rtol=0, atol=1e-11 * scale)
    assert np.allclose(loaded.intrinsics(640, 480), moved.intrinsics(640, 480), rtol=1e-11)
