"""The animation model: tracks, interpolation (linear, step, clamped), frame times, scene.at(t), and
every error of an [animation] table, each naming the file, the table and the key."""
import dataclasses
import math
import tomllib

import pytest

import pyclray
from pyclray import Animation, Camera, Image, Plane, Scene, SceneError, Sphere
from pyclray.model.loader import scene_from_dict

from conftest import SCENES

BASE = """
[camera]
eye = [0.0, 2.0, 6.0]
target = [0.0, 0.5, 0.0]
fov = 45.0

[image]
width = 16
height = 16

[[shapes]]
type = "plane"
name = "ground"
normal = [0.0, 1.0, 0.0]
offset = 0.0

[[shapes]]
type = "sphere"
name = "ball"
center = [0.0, 1.0, 0.0]
radius = 1.0
"""


def load(tmp_path, animation: str):
    path = tmp_path / "scene.toml"
    path.write_text(BASE + animation)
    return pyclray.load_scene(path), str(path)


def error_of(tmp_path, animation: str) -> SceneError:
    with pytest.raises(SceneError) as caught:
        load(tmp_path, animation)
    return caught.value


def keys(*entries, fps=4.0, duration=2.0, interpolation="linear"):
    return Animation(fps, duration, tuple(entries), interpolation)


def scene(animation=None):
    return Scene(Camera((0.0, 2.0, 6.0), (0.0, 0.5, 0.0)), Image(16, 16),
                 (Plane((0.0, 1.0, 0.0), 0.0, "ground"), Sphere((0.0, 1.0, 0.0), 1.0, "ball")), animation=animation)


# -- semantics -------------------------------------------------------------------------------
def test_linear_interpolation_meets_every_key_exactly_and_clamps_outside():
    animated = scene(keys(
        {"target": "ball", "time": 0.5, "radius": 0.1},
        {"target": "ball", "time": 1.0, "radius": 0.7},
        {"target": "ball", "time": 1.5, "radius": 0.3},
    ))
    radius = lambda t: animated.at(t).shapes[1].radius
    # every key's value exactly at its time (no a + (b - a) * 1 rounding: 0.1 + (0.7 - 0.1) != 0.7)
    assert (radius(0.5), radius(1.0), radius(1.5)) == (0.1, 0.7, 0.3)
    assert radius(0.0) == radius(0.25) == 0.1  # before the first key: its value
    assert radius(1.75) == radius(100.0) == 0.3  # after the last key: its value
    assert radius(0.75) == pytest.approx(0.4, abs=1e-15)  # halfway between 0.1 and 0.7
    assert radius(1.125) == pytest.approx(0.6, abs=1e-15)  # a quarter of the way from 0.7 to 0.3


def test_vectors_interpolate_component_wise_and_constants_stay_exact():
    animated = scene(keys(
        {"target": "camera", "time": 0.0, "eye": [0.0, 2.0, 6.0], "up": [0.1, 1.0, 0.0]},
        {"target": "camera", "time": 2.0, "eye": [4.0, 2.0, 2.0], "up": [0.1, 1.0, 0.0]},
    ))
    camera = animated.at(0.5).camera
    assert camera.eye == (1.0, 2.0, 5.0)  # exact: a + s (b - a) with s = 1/4 and these values
    for t in (0.3, 0.7, 1.9):
        assert animated.at(t).camera.up == (0.1, 1.0, 0.0)  # a constant track is exactly constant
        assert animated.at(t).camera.eye[1] == 2.0  # so is a constant component


def test_step_holds_the_last_key_at_or_before_t():
    animated = scene(keys(
        {"target": "ball", "time": 0.5, "center": [0.0, 1.0, 0.0]},
        {"target": "ball", "time": 1.0, "center": [0.0, 2.0, 0.0]},
        interpolation="step",
    ))
    center = lambda t: animated.at(t).shapes[1].center
    assert center(0.0) == center(0.5) == center(0.999) == (0.0, 1.0, 0.0)
    assert center(1.0) == center(1.5) == (0.0, 2.0, 0.0)


def test_keys_not_animated_keep_their_values_and_the_frame_is_static():
    animated = scene(keys({"target": "ball", "time": 0.0, "radius": 0.5}, {"target": "ball", "time": 1.0, "radius": 0.9}))
    frame = animated.at(0.5)
    assert frame.animation is None
    assert frame.camera == animated.camera and frame.shapes[0] == animated.shapes[0] and frame.image == animated.image
    assert frame.shapes[1] == Sphere((0.0, 1.0, 0.0), 0.7, "ball")
    assert frame.at(3.0) is frame  # a static scene is itself at every time


def test_frame_times_are_k_over_fps():
    animation = keys(fps=24.0, duration=2.0)
    assert animation.frame_count() == 48
    assert animation.frame_times() == [k / 24.0 for k in range(48)]
    assert keys(fps=30.0, duration=0.51).frame_count() == 15  # round(15.3)
    assert keys(fps=10.0, duration=0.06).frame_count() == 1  # round(0.6)


def test_the_animation_in_a_file_matches_the_same_animation_in_code(tmp_path):
    loaded, _ = load(tmp_path, """
[animation]
fps = 4.0
duration = 2.0
[[animation.keys]]
target = "camera"
time = 0.0
eye = [0.0, 2.0, 6.0]
[[animation.keys]]
target = "camera"
time = 2.0
eye = [4.0, 2.0, 2.0]
""")
    built = scene(keys({"target": "camera", "time": 0, "eye": [0, 2, 6]}, {"target": "camera", "time": 2, "eye": [4, 2, 2]}))
    for t in loaded.animation.frame_times():
        assert dataclasses.replace(loaded.at(t), source=None) == built.at(t)


def test_the_cameras_target_is_keyed_in_a_values_table(tmp_path):
    loaded, _ = load(tmp_path, ANIMATION + key("camera", 0.0, values="{ target = [0.0, 0.5, 0.0] }", fov=45.0)
                     + key("camera", 1.0, values="{ target = [1.0, 0.5, 0.0] }", fov=30.0))
    assert loaded.at(0.5).camera.target == (0.5, 0.5, 0.0) and loaded.at(0.5).camera.fov == 37.5
    error = error_of(tmp_path, ANIMATION + key("camera", 0.0, values="{ fov = 40.0 }", fov=45.0))
    assert error.key == "fov" and "twice" in str(error)
    error = error_of(tmp_path, ANIMATION + key("camera", 0.0, values="[1.0]"))
    assert error.key == "values" and error.table == "[[animation.keys]] #0"


def test_with_size_keeps_the_animation():
    animated = scene(keys({"target": "ball", "time": 0.0, "radius": 0.5}, {"target": "ball", "time": 1.0, "radius": 0.9}))
    assert animated.with_size(8, 4).at(0.5).shapes[1].radius == animated.at(0.5).shapes[1].radius
    assert animated.with_size(8, 4).at(0.5).image == Image(8, 4)


@pytest.mark.parametrize("path", sorted(SCENES.glob("*.toml")), ids=lambda p: p.name)
def test_every_number_or_vector_key_of_every_shape_and_the_camera_can_be_animated(path):
    """Through the targets' own dataclasses, so any shape type in scenes/ is covered, no list here:
    each animatable key keyed to its own value at two times gives the same scene at every time."""
    with open(path, "rb") as handle:
        data = tomllib.load(handle)
    data.pop("animation", None)
    base = scene_from_dict(data, str(path))  # its folder: where a mesh's file is
    entries = []
    for thing, target in [(base.camera, "camera")] + [(s, s.name) for s in base.shapes]:
        if target != "camera" and sum(s.name == target for s in base.shapes) > 1:
            continue  # a name used twice cannot be a target
        for f in dataclasses.fields(thing):
            value = getattr(thing, f.name)
            if isinstance(value, float) or (isinstance(value, tuple) and value and all(isinstance(c, float) for c in value)):
                for time in (0.0, 1.0):
                    # in values = {...}: the camera's own key "target" cannot sit beside the entry's target
                    entries.append({"target": target, "time": time,
                                    "values": {f.name: list(value) if isinstance(value, tuple) else value}})
            elif f.name != "name" or target != "camera":
                # strings and booleans (name, fov_axis, caps, ...) cannot be animated
                bad = {"target": target, "time": 0.0, "values": {f.name: value}}
                with pytest.raises(SceneError, match="cannot be animated"):
                    dataclasses.replace(base, animation=keys(bad))
    assert entries
    animated = dataclasses.replace(base, animation=keys(*entries))
    for t in (0.0, 0.5, 1.0, 1.5):
        assert animated.at(t) == base


# -- errors ----------------------------------------------------------------------------------
ANIMATION = """
[animation]
fps = 4.0
duration = 2.0
"""


def key(target, time, **values):
    body = "".join(f"{k} = {v}\n" for k, v in values.items())
    return f'[[animation.keys]]\ntarget = "{target}"\ntime = {time}\n{body}'


@pytest.mark.parametrize(
    "animation,table,key_name,words",
    [
        (ANIMATION + key("bal", 0.0, radius=1.0), "[[animation.keys]] #0", "target", ["unknown target 'bal'", "ball", "ground"]),
        (ANIMATION + key("camera", 0.0, fov_axis='"y"'), "[[animation.keys]] #0", "fov_axis", ["cannot", "eye", "fov"]),
        (ANIMATION + key("ball", 0.0, name='"x"'), "[[animation.keys]] #0", "name", ["cannot"]),
        (ANIMATION + key("ball", 0.0, type='"plane"'), "[[animation.keys]] #0", "type", ["cannot"]),
        (ANIMATION + key("ball", 0.0, colour=1.0), "[[animation.keys]] #0", "colour", ["center", "radius"]),
        (ANIMATION + key("ground", 0.0, point="[0.0, 1.0, 0.0]"), "[[animation.keys]] #0", "point", ["normal", "offset"]),
        (ANIMATION + key("ball", 0.0, radius=1.0) + key("ball", 0.0, radius=2.0), "[[animation.keys]] #1", "radius",
         ["two keys at time 0.0", "#0 and #1", "distinct"]),
        (ANIMATION + key("ball", 0.0, radius="[1.0, 2.0]"), "[[animation.keys]] #0", "radius", ["expected a number"]),
        (ANIMATION + key("ball", 0.0, center=1.0), "[[animation.keys]] #0", "center", ["expected 3 numbers"]),
        (ANIMATION + key("ball", 0.0, center="[1.0, 2.0]"), "[[animation.keys]] #0", "center", ["expected 3 numbers"]),
        (ANIMATION + key("ball", 0.0, center='"up"'), "[[animation.keys]] #0", "center", ["expected 3 numbers", "'up'"]),
        (ANIMATION + key("ball", 0.0, radius="true"), "[[animation.keys]] #0", "radius", ["expected a number"]),
        (ANIMATION + key("ball", 0.0, radius="inf"), "[[animation.keys]] #0", "radius", ["finite"]),
        (ANIMATION + key("ball", 0.0, center="[0.0, nan, 0.0]"), "[[animation.keys]] #0", "center", ["finite"]),
        (ANIMATION + key("ball", -1.0, radius=1.0), "[[animation.keys]] #0", "time", [">= 0"]),
        (ANIMATION + key("ball", 0.0), "[[animation.keys]] #0", None, ["at least one keyed value"]),
        (ANIMATION + '[[animation.keys]]\ntime = 0.0\nradius = 1.0\n', "[[animation.keys]] #0", "target", ["missing"]),
        (ANIMATION + '[[animation.keys]]\ntarget = "ball"\nradius = 1.0\n', "[[animation.keys]] #0", "time", ["missing"]),
        ("[animation]\nduration = 2.0\n", "[animation]", "fps", ["missing"]),
        ("[animation]\nfps = 0.0\nduration = 2.0\n", "[animation]", "fps", ["> 0"]),
        ("[animation]\nfps = 4.0\nduration = 0.1\n", "[animation]", "duration", ["no frame"]),
        ("[animation]\nfps = 1000.0\nduration = 1e4\n", "[animation]", "duration", ["more than 1,000,000"]),
        ("[animation]\nfps = 4.0\nduration = 1.0\nloop = true\n", "[animation]", "loop", ["unknown key"]),
        ('[animation]\nfps = 4.0\nduration = 1.0\ninterpolation = "cubic"\n', "[animation]", "interpolation", ["linear", "step"]),
        ("[animation]\nfps = 4.0\nduration = 1.0\nkeys = 3\n", "[animation]", "keys", ["array of tables"]),
    ],
)
def test_bad_animation_tables_name_the_file_table_and_key(tmp_path, animation, table, key_name, words):
    error = error_of(tmp_path, animation)
    assert error.file == str(tmp_path / "scene.toml") and error.table == table and error.key == key_name, str(error)
    for word in words:
        assert word in str(error), (word, str(error))


def test_a_target_name_used_by_two_shapes_is_ambiguous(tmp_path):
    """A scene file cannot name two shapes alike (issue 27: a SceneError at the second one's name);
    a Scene built in Python can (unnamed shapes share their type's default name), and keying such
    a name is ambiguous."""
    path = tmp_path / "scene.toml"
    path.write_text(BASE + '[[shapes]]\ntype = "sphere"\nname = "ball"\ncenter = [2.0, 1.0, 0.0]\nradius = 0.5\n')
    with pytest.raises(SceneError) as caught:
        pyclray.load_scene(path)
    assert caught.value.table == "[[shapes]] #2 (sphere)" and caught.value.key == "name"
    assert "'ball' is already used by [[shapes]] #1" in str(caught.value)
    base = scene()
    twice = dataclasses.replace(base, shapes=base.shapes + (Sphere((2.0, 1.0, 0.0), 0.5, "ball"),))
    with pytest.raises(SceneError) as caught:
        dataclasses.replace(twice, animation=keys({"target": "ball", "time": 0.0, "radius": 1.0}))
    error = caught.value
    assert error.table == "[[animation.keys]] #0" and error.key == "target"
    assert "ambiguous" in str(error) and "#1" in str(error) and "#2" in str(error)
    # an untargeted duplicate name is fine in Python
    assert dataclasses.replace(twice, animation=keys({"target": "camera", "time": 0.0, "fov": 40.0})).at(0.0).camera.fov == 40.0


def test_the_first_bad_frame_is_named_by_key_target_and_time(tmp_path):
    # radius 1 at t = 0 to -1 at t = 1: it reaches 0 at t = 0.5 (frame 2 at 4 fps), which is not > 0
    error = error_of(tmp_path, ANIMATION + key("ball", 0.0, radius=1.0) + key("ball", 1.0, radius=-1.0))
    assert error.key == "radius" and error.table == "[[animation.keys]] (target 'ball')"
    assert "at t = 0.5 s (frame 2)" in str(error) and "> 0" in str(error)
    assert str(error).startswith(str(tmp_path / "scene.toml") + ": ")


def test_a_camera_that_degenerates_at_some_frame_is_named(tmp_path):
    # the eye moves straight through the target (0, 0.5, 0): at t = 1 (frame 4) eye == target
    error = error_of(tmp_path, ANIMATION + key("camera", 0.0, eye="[0.0, 0.5, 4.0]") + key("camera", 2.0, eye="[0.0, 0.5, -4.0]"))
    assert error.table == "[[animation.keys]] (target 'camera')" and error.key == "target"
    assert "at t = 1 s (frame 4)" in str(error) and "eye animated" in str(error)


def test_scene_at_a_time_between_frames_is_checked_too():
    # valid at every frame time (0, 0.25, 0.5, 0.75 at 4 fps); between them the radius dips to -1 at t = 0.2
    animated = scene(keys({"target": "ball", "time": 0.0, "radius": 1.0}, {"target": "ball", "time": 0.2, "radius": -1.0},
                          {"target": "ball", "time": 0.25, "radius": 1.0}, fps=4.0, duration=1.0))
    assert animated.at(0.25).shapes[1].radius == 1.0
    with pytest.raises(SceneError) as caught:
        animated.at(0.1)
    assert caught.value.key == "radius" and "at t = 0.1 s," in str(caught.value)
    with pytest.raises(pyclray.RequestError, match="expected a time in seconds >= 0"):  # issue 27
        animated.at(math.nan)
