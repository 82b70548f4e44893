"""Issue 42 item 9: a pose given in OpenGL's convention (y up, z backwards) renders an all-miss
image; pyclray then warns, in one line, suggesting the convention (a PyclrayWarning; on the command
line one stderr line), where no pixel hits and every shape's bounds lie behind the camera. An
all-miss view of shapes in front of the camera (looking beside them), or a view that hits, is not
warned about."""
import subprocess
import sys
import warnings

import numpy as np
import pytest

import pyclray

K = [[100.0, 0.0, 32.0], [0.0, 100.0, 24.0], [0.0, 0.0, 1.0]]
SHAPES = (pyclray.Sphere((0.0, 0.0, 0.0), 1.0), pyclray.Box((1.5, 0.0, 0.0), (0.5, 0.5, 0.5)),
          pyclray.Mesh([[0, 0, -2], [1, 0, -2], [0, 1, -2]], [[0, 1, 2]]))
# the camera at z = 6 looking at the origin: OpenCV's pose (x right, y down, z forward: world -z)
OPENCV = np.array([[1.0, 0, 0, 0], [0, -1.0, 0, 0], [0, 0, -1.0, 6.0], [0, 0, 0, 1]])
OPENGL = OPENCV @ np.diag([1.0, -1.0, -1.0, 1.0])  # the same camera written in OpenGL's convention


def scene_with(pose, shapes=SHAPES):
    return pyclray.Scene(pyclray.Camera.from_intrinsics(K, pose, 64, 48), pyclray.Image(64, 48), shapes)


def warned(call) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    return [str(w.message) for w in caught if issubclass(w.category, pyclray.PyclrayWarning)]


def test_an_opengl_pose_is_warned_about_in_one_line():
    messages = warned(lambda: pyclray.render(scene_with(OPENGL), aovs=("depth", "id")))
    assert len(messages) == 1 and "\n" not in messages[0], messages
    assert "OpenGL" in messages[0] and "OpenCV" in messages[0] and "behind the camera" in messages[0]


@pytest.mark.parametrize("aovs", [("id",), ("depth",), ("shaded", "zdepth"), ("primitive",)])
def test_any_image_that_tells_a_miss_is_enough(aovs):
    assert len(warned(lambda: pyclray.render(scene_with(OPENGL), aovs=aovs))) == 1


def test_the_right_pose_and_a_look_beside_the_shapes_are_not_warned_about():
    assert warned(lambda: pyclray.render(scene_with(OPENCV))) == []
    beside = OPENCV.copy()
    beside[:3, 3] = (40.0, 0.0, 6.0)  # looking along -z, the shapes 40 to the left, in front: all miss
    frame = pyclray.render(scene_with(beside))
    assert (frame["id"] == -1).all()
    assert warned(lambda: pyclray.render(scene_with(beside))) == []
    plane_only = (pyclray.Plane((0.0, 1.0, 0.0), 5.0),)  # no bounds to be behind: nothing said
    assert warned(lambda: pyclray.render(scene_with(OPENGL, plane_only))) == []


def test_one_primitive_in_front_among_thousands_behind_is_not_warned_about():
    """A mesh of 3,000 triangles behind the camera but one (not among every 997th, the sample
    looked at first) in front of it, beside the view: all miss, and not every shape lies behind."""
    behind = np.array([[0.0, 0.0, 8.0], [0.1, 0.0, 8.0], [0.0, 0.1, 8.0]])  # z = 8: behind the eye at z = 6
    vertices = np.concatenate([behind + [0.0, 0.0, 0.01 * i] for i in range(3000)])
    vertices[3:6] += [40.0, 0.0, -8.0]  # triangle 1 at z = 0, 40 to the left: in front, beside the view
    mesh = pyclray.Mesh(vertices, np.arange(len(vertices)).reshape(-1, 3))
    assert (pyclray.render(scene_with(OPENCV, (mesh,)), aovs=("id",))["id"] == -1).all()
    assert warned(lambda: pyclray.render(scene_with(OPENCV, (mesh,)), aovs=("id",))) == []
    far = pyclray.Mesh(vertices[6:], np.arange(len(vertices) - 6).reshape(-1, 3))  # without the two first
    assert len(warned(lambda: pyclray.render(scene_with(OPENCV, (far,)), aovs=("id",)))) == 1


def test_render_views_warns_for_the_view_that_looks_away():
    scene = scene_with(OPENCV)
    cameras = [scene.camera, pyclray.Camera.from_intrinsics(K, OPENGL, 64, 48)]
    messages = warned(lambda: list(pyclray.render_views(scene, cameras, aovs=("id",))))
    assert len(messages) == 1


def test_the_command_line_says_it_on_one_stderr_line(tmp_path):
    path = tmp_path / "gl.toml"
    pose = ", ".join("[" + ", ".join(map(repr, row)) + "]" for row in OPENGL.tolist())
    path.write_text(f"[camera]\nintrinsics = {K!r}\npose = [{pose}]\n[image]\nwidth = 64\nheight = 48\n"
                    "[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\n")
    run = subprocess.run([sys.executable, "-m", "pyclray", "render", str(path), "-o", str(tmp_path / "gl.exr")],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pyclray render: warning:") and "OpenGL" in lines[0], run.stderr
