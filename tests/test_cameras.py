"""The camera-model interface (pyclray.model.cameras), over every registered model: its [camera]
keys and the model key's errors, its packed struct, its float64 rays against the kernel's render,
and its Mitsuba sensor as data, read back."""
from __future__ import annotations

import numpy as np
import pytest

import pyclray
from pyclray.model.cameras import CAMERAS, DEFAULT_MODEL, CameraModel
from pyclray.model.cameras.perspective import Camera
from pyclray.model.errors import SceneError
from pyclray.model.layout import layout
from pyclray.model.loader import camera_from_table
from pyclray.model.mitsuba_xml.sensor import SENSORS
from pyclray.reference import mitsuba, mitsuba_export, oracle

# [camera] tables of each registered model (a new model adds its own: the test below asks for them)
EXAMPLES = {
    "perspective": [
        {"eye": [0.5, 2.0, 6.0], "target": [0.0, 0.5, 0.0], "up": [0.0, 1.0, 0.1], "fov": 40.0},
        {"eye": [0.5, 2.0, 6.0], "target": [0.0, 0.5, 0.0], "fov": 30.0, "fov_axis": "y"},
        {"intrinsics": [[40.0, 0.0, 17.5], [0.0, 40.0, 14.25], [0.0, 0.0, 1.0]],
         "pose": [[0.8, 0.168, -0.576, 2.5], [0.0, -0.96, -0.28, 1.8], [-0.6, 0.224, -0.768, 4.2], [0.0, 0.0, 0.0, 1.0]]},
        {"intrinsics": [[30.0, 0.0, 17.5], [0.0, 30.0, 13.5], [0.0, 0.0, 1.0]], "distortion": [-0.4, 0.0, 0.001, -0.002],
         "pose": [[0.8, 0.168, -0.576, 2.5], [0.0, -0.96, -0.28, 1.8], [-0.6, 0.224, -0.768, 4.2], [0.0, 0.0, 0.0, 1.0]]},
        {"intrinsics": [[40.0, 0.0, 18.0], [0.0, 40.0, 14.0], [0.0, 0.0, 1.0]], "pixel_origin": "corner",
         "distortion": [0.3, 0.05, 0.0, 0.0, 0.01, 0.1, 0.0, 0.0],
         "pose": [[0.8, 0.168, -0.576, 2.5], [0.0, -0.96, -0.28, 1.8], [-0.6, 0.224, -0.768, 4.2], [0.0, 0.0, 0.0, 1.0]]},
    ],
    "fisheye": [
        {"intrinsics": [[9.0, 0.0, 17.5], [0.0, 9.0, 13.5], [0.0, 0.0, 1.0]], "distortion": [0.05, -0.01, 0.002, 0.0],
         "fov": 190.0,
         "pose": [[0.8, 0.168, -0.576, 2.5], [0.0, -0.96, -0.28, 1.8], [-0.6, 0.224, -0.768, 4.2], [0.0, 0.0, 0.0, 1.0]]},
    ],
    "orthographic": [
        {"eye": [0.5, 2.0, 6.0], "target": [0.0, 0.5, 0.0], "height": 3.0},
        {"eye": [0.5, 2.0, 6.0], "target": [0.0, 0.5, 0.0], "up": [0.1, 1.0, 0.0]},
    ],
    "equirectangular": [
        {"eye": [0.5, 2.0, 6.0]},
        {"eye": [0.5, 2.0, 6.0], "target": [0.0, 0.5, 0.0], "longitude": [-60.0, 90.0], "latitude": [-30.0, 45.0]},
    ],
}
SIZE = (36, 28)
CASES = [(model, index) for model, tables in EXAMPLES.items() for index in range(len(tables))]


def camera_of(model: str, index: int) -> CameraModel:
    return camera_from_table({"model": model, **EXAMPLES[model][index]})


def test_every_registered_model_has_examples_here_and_its_registry_name():
    assert set(EXAMPLES) == set(CAMERAS) and DEFAULT_MODEL in CAMERAS
    assert CAMERAS["perspective"] is pyclray.Camera is Camera
    for name, model in CAMERAS.items():
        assert issubclass(model, CameraModel) and model.model == name
        for table in EXAMPLES[name]:
            assert set(table) <= set(model.keys)


@pytest.mark.parametrize("model,index", CASES)
def test_the_model_key_selects_the_class_and_its_default_is_perspective(model, index):
    camera = camera_of(model, index)
    assert type(camera) is CAMERAS[model]
    if model == DEFAULT_MODEL:
        assert camera_from_table(dict(EXAMPLES[model][index])) == camera


def write(tmp_path, camera_lines: str):
    path = tmp_path / "scene.toml"
    path.write_text(f"[camera]\n{camera_lines}\neye = [0.0, 2.0, 6.0]\ntarget = [0.0, 0.5, 0.0]\nfov = 45.0\n"
                    "[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.5, 0.0]\nradius = 1.0\n")
    return path


def test_a_scene_file_names_its_model(tmp_path):
    assert pyclray.load_scene(write(tmp_path, 'model = "perspective"')).camera == pyclray.load_scene(write(tmp_path, "")).camera


@pytest.mark.parametrize("line,expected", [
    ('model = "pinhole"', "unknown camera model 'pinhole' (expected one of: perspective, fisheye, orthographic, "
                          "equirectangular)"),
    ("model = 3", "expected a string, got 3"),
])
def test_a_bad_model_names_file_table_and_key(tmp_path, line, expected):
    path = write(tmp_path, line)
    with pytest.raises(SceneError) as caught:
        pyclray.load_scene(path)
    error = caught.value
    assert (error.file, error.table, error.key) == (str(path), "[camera]", "model")
    assert str(error) == f"{path}: table [camera]: key 'model': {expected}"


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("model,index", CASES)
def test_pack_is_one_struct_of_the_models_layout(model, index, precision):
    camera = camera_of(model, index)
    packed = camera.pack(*SIZE, precision, box_origin=(1.0, -2.0, 0.5))
    assert packed.dtype == layout(type(camera).struct, precision).dtype and packed.shape == (1,)
    assert packed.tobytes() != camera.pack(*SIZE, precision).tobytes()  # the box origin is in it


@pytest.mark.parametrize("model,index", CASES)
def test_rays_are_unit_from_the_pose_and_a_window_is_their_part(model, index):
    camera = camera_of(model, index)
    origins, directions = camera.rays(*SIZE)
    assert origins.shape == directions.shape == (SIZE[1], SIZE[0], 3) and directions.dtype == np.float64
    assert np.abs(np.linalg.norm(directions, axis=-1) - 1).max() < 4e-16
    eye, axis = camera.pose()[:3, 3], camera.pose()[:3, 2]
    if camera.rays_from_eye:
        assert np.array_equal(origins, np.broadcast_to(eye, origins.shape))
    else:  # orthographic: from the plane through the eye, along the axis
        assert np.abs((origins - eye) @ axis).max() < 1e-14 and np.array_equal(directions, np.broadcast_to(axis, origins.shape))
    window = (5, 7, 20, 9)  # x0, y0, columns, rows
    part_origins, part = camera.rays(*SIZE, window)
    assert np.array_equal(part, directions[7:16, 5:25]) and np.array_equal(part_origins, origins[7:16, 5:25])
    scene = pyclray.Scene(camera, pyclray.Image(*SIZE), (pyclray.Sphere((0.0, 0.5, 0.0), 1.0),))
    assert np.array_equal(oracle.camera_rays(scene)[1], directions)


@pytest.mark.parametrize("precision,tolerance", [("fp64", 1e-13), ("fp32", 2e-6)])
@pytest.mark.parametrize("model,index", CASES)
def test_rays_are_the_kernels_depth_of_a_plane_at_a_known_distance(model, index, precision, tolerance):
    """A plane across the optical axis at distance 3 from the eye: each pixel's depth is 3 / cos of
    its float64 ray's angle to the axis (from the plane through the eye: its origin's offset along
    the axis is 0), and the hit point lies on that ray. Rays that turn away from the plane (a
    panorama's, a fisheye's beyond 90 degrees) and pixels outside a lens's field miss it."""
    camera = camera_of(model, index)
    pose = camera.pose()
    eye, axis = pose[:3, 3], pose[:3, 2]
    scene = pyclray.Scene(camera, pyclray.Image(*SIZE), (pyclray.Plane(tuple(axis), -float(axis @ (eye + 3.0 * axis))),))
    frame = pyclray.render(scene, aovs=("depth", "position"), precision=precision)
    origins, directions = camera.rays(*SIZE)
    cos = directions @ axis
    field = camera.space_directions(*SIZE)
    reached = (cos > 1e-3) & (np.ones(cos.shape, bool) if field is None else field[1])
    assert reached.mean() > 0.3
    assert np.all(np.isinf(frame["depth"][~reached & (cos < -1e-3)]))
    if field is not None:
        assert np.all(np.isinf(frame["depth"][~field[1]]))
    expected = 3.0 / cos[reached]
    assert np.abs(frame["depth"][reached] / expected - 1).max() < tolerance
    along = np.asarray(frame["position"], np.float64)[reached] - origins[reached]
    assert np.abs(along / np.linalg.norm(along, axis=-1, keepdims=True) - directions[reached]).max() < 4 * tolerance


# -- the Mitsuba sensor as data ---------------------------------------------------------------------
def as_read(sensor):
    """The sensor as the XML reader hands it over: every property the model names, its default where
    the sensor has none, and the matrix of a look-at."""
    from pyclray.model.mitsuba_xml.properties import look_at

    model = next(m for m in CAMERAS.values() if m.mitsuba_plugin == sensor.plugin)
    values = {name: default for name, _, default in model.mitsuba_properties} | sensor.properties
    to_world = sensor.to_world if sensor.look_at is None else look_at(*(np.array(v) for v in sensor.look_at))
    return model, type(sensor)(sensor.plugin, values, sensor.width, sensor.height, to_world, sensor.look_at)


@pytest.mark.parametrize("model,index", CASES)
def test_a_cameras_mitsuba_sensor_reads_back_as_the_same_camera(model, index):
    camera = camera_of(model, index)
    # a model Mitsuba has no sensor of says so, as does a perspective camera with a lens distortion
    if CAMERAS[model].mitsuba_plugin is None or getattr(camera, "distortion", None) is not None:
        with pytest.raises(SceneError, match="no sensor|no lens distortion"):
            camera.mitsuba_sensor(*SIZE)
        return
    sensor = camera.mitsuba_sensor(*SIZE)
    assert (sensor.plugin, sensor.width, sensor.height) == (CAMERAS[model].mitsuba_plugin, *SIZE)
    reader, read = as_read(sensor)
    back = reader.from_mitsuba(read)
    assert type(back) is type(camera)
    if sensor.look_at is not None:
        assert back == camera  # a look-at camera stays the very same camera
    assert np.abs(back.rays(*SIZE)[1] - camera.rays(*SIZE)[1]).max() < 1e-14
    assert np.abs(back.pose() - camera.pose()).max() < 1e-14
    # and through the XML file pyclray export writes, which the reader reads
    scene = pyclray.Scene(camera, pyclray.Image(*SIZE), (pyclray.Sphere((0.0, 0.5, 0.0), 1.0),))
    xml = mitsuba_export.scene_xml(scene)
    from pyclray.model.mitsuba_xml import load_xml

    read_scene = load_xml(xml.encode())
    assert read_scene.image == scene.image
    assert np.abs(read_scene.camera.rays(*SIZE)[1] - camera.rays(*SIZE)[1]).max() < 1e-14


def test_every_mitsuba_plugin_is_read_and_written_as_a_sensor():
    plugins = {model.mitsuba_plugin for model in CAMERAS.values() if model.mitsuba_plugin}
    assert set(SENSORS) == plugins
    assert all(mitsuba_export.TAGS[plugin] == "sensor" for plugin in plugins)


def test_a_model_without_a_mitsuba_sensor_says_so_naming_the_file():
    """The interface's answer for a model Mitsuba has no sensor of (a model registered for this test
    only: the perspective camera's rays under another name)."""
    class Unmatched(Camera):
        model = "unmatched"
        mitsuba_plugin = None
        mitsuba_sensor = CameraModel.mitsuba_sensor

    scene = pyclray.Scene(Unmatched((0.0, 0.0, 5.0), (0.0, 0.0, 0.0)), pyclray.Image(*SIZE), (), source="s.toml")
    with pytest.raises(SceneError) as caught:
        mitsuba.sensor_of(scene)
    assert str(caught.value) == ("s.toml: table [camera]: key 'model': Mitsuba 3 has no sensor of the unmatched camera "
                                 "model, so this camera cannot be checked against Mitsuba or exported for it")
