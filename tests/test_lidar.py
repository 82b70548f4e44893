"""LiDAR: pyclray.Lidar's presets against the makers' tables, its axes and azimuth convention, scans
against the float64 oracle (a scan casts float64 rays from the sensor's origin, so its ranges meet
cast's error model: tests/oracle_checks.py), range limits, sweeping scans against static scans at each
column's time (bit for bit: a ray's result depends on nothing but the ray and the shapes, and a
handle updated to a frame is the handle prepared for it), the TOML keys and their errors, the CLI
and the PLY files read back with trimesh."""
import dataclasses
import math

import numpy as np
import pytest
import trimesh

import pyclray
from pyclray.apps.cli import main as cli_main
from pyclray.model.lidar import PRESETS

from oracle_checks import assert_agrees_with_oracle


def scene_of(shapes, lidars=(), animation=None):
    return pyclray.Scene(pyclray.Camera((0.0, -8.0, 3.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)), pyclray.Image(8, 8),
                         tuple(shapes), lidars=tuple(lidars), animation=animation)


def run_cli(*args):
    """(status, stdout, stderr) of `pyclray ARGS` run in this process."""
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = cli_main([str(a) for a in args])
        except SystemExit as stop:  # argparse's own errors
            status = stop.code
    return status, out.getvalue(), err.getvalue()


# -- the presets -----------------------------------------------------------------------------------
def test_vlp16_is_the_manuals_table():
    """VLP-16 User Manual: laser IDs 0..15 at -15, 1, -13, 3, ..., -1, 15 degrees; rows from the top down."""
    lidar = pyclray.Lidar(preset="VLP-16")
    assert (lidar.beams, lidar.columns) == (16, 1800)
    assert PRESETS["VLP-16"].elevations == tuple(float(v) for pair in zip(range(-15, 0, 2), range(1, 16, 2)) for v in pair)
    assert np.array_equal(lidar.elevation_angles, np.arange(15.0, -16.0, -2.0))
    assert lidar.elevations == tuple(np.arange(15.0, -16.0, -2.0))  # the preset's table, as rows
    assert dataclasses.replace(lidar, position=(1.0, 0.0, 0.0)).elevations == lidar.elevations
    # each row's maker's laser number: its angle in the maker's table
    assert np.array_equal(np.array(PRESETS["VLP-16"].elevations)[lidar.lasers], lidar.elevation_angles)
    assert lidar.lasers[0] == 15 and lidar.lasers[-1] == 0


def test_hdl32e_is_the_manuals_table():
    lidar = pyclray.Lidar(preset="HDL-32E")
    assert lidar.beams == 32
    table = PRESETS["HDL-32E"].elevations
    assert table[:4] == (-30.67, -9.33, -29.33, -8.00) and table[-2:] == (-10.67, 10.67)
    # 4/3 degrees apart, printed to two decimals
    assert np.allclose(np.sort(table), (-23 + np.arange(32)) * 4.0 / 3.0, rtol=0, atol=0.005)
    assert lidar.elevation_angles[0] == 10.67 and lidar.elevation_angles[-1] == -30.67


def test_hdl64e_is_the_design_table_of_its_two_blocks():
    lidar = pyclray.Lidar(preset="HDL-64E")
    assert lidar.beams == 64
    upper, lower = np.array(PRESETS["HDL-64E"].elevations[:32]), np.array(PRESETS["HDL-64E"].elevations[32:])
    assert upper[0] == 2.0 and np.allclose(np.diff(upper), -1.0 / 3.0) and round(upper[-1], 2) == -8.33
    assert round(lower[0], 2) == -8.83 and np.allclose(np.diff(lower), -0.5) and round(lower[-1], 2) == -24.33


def test_os1_64_is_ouster_metadata():
    """Ouster's beam_altitude_angles: channel 0 at the top, 16.611 down to -16.611, about 0.527 apart."""
    lidar = pyclray.Lidar(preset="OS1-64")
    assert (lidar.beams, lidar.columns) == (64, 1024)
    assert np.array_equal(lidar.lasers, np.arange(64))  # already from the top down
    assert lidar.elevation_angles[0] == 16.611 and lidar.elevation_angles[-1] == -16.611
    assert np.allclose(np.diff(lidar.elevation_angles), -0.527, atol=0.001)
    for name, preset in PRESETS.items():
        assert preset.source and len(preset.elevations) == pyclray.Lidar(preset=name).beams


# -- axes and the azimuth convention -------------------------------------------------------------------
def four_balls(distance=5.0):
    """Balls ahead (+x, id 0), to the left (+y, 1), behind (-x, 2), to the right (-y, 3) of the origin."""
    return [pyclray.Sphere((distance, 0.0, 0.0), 1.0), pyclray.Sphere((0.0, distance, 0.0), 1.0),
            pyclray.Sphere((-distance, 0.0, 0.0), 1.0), pyclray.Sphere((0.0, -distance, 0.0), 1.0)]


def test_column_zero_looks_back_and_the_columns_turn_clockwise_seen_from_above():
    lidar = pyclray.Lidar(elevations=[0.0], columns=8)
    scan = pyclray.scan(scene_of(four_balls()), lidar)
    # columns 0, 2, 4, 6: behind, left, ahead, right (azimuths 180, 90, 0, -90 degrees)
    assert scan["id"][0, ::2].tolist() == [2, 1, 0, 3]
    assert np.array_equal(scan["azimuth"], 180.0 - 45.0 * np.arange(8))
    assert np.allclose(scan["range"][0, ::2], 4.0, rtol=1e-6)
    assert np.allclose(lidar.directions()[0, 4], (1.0, 0.0, 0.0)) and np.allclose(lidar.directions()[0, 2], (0.0, 1.0, 0.0))


def test_elevation_is_up_and_rows_follow_the_beams():
    shapes = [pyclray.Sphere((5.0, 0.0, 5.0 * math.tan(math.radians(20.0))), 0.3)]
    lidar = pyclray.Lidar(elevations=[20.0, 0.0, -20.0], columns=4)
    scan = pyclray.scan(scene_of(shapes), lidar)
    assert scan["id"][:, 2].tolist() == [0, -1, -1]  # column 2 of 4 looks ahead


def test_pose_is_sensor_to_world():
    """A sensor at (0, 0, 0) turned 90 degrees about z (x forward -> world +y): straight ahead it sees the ball
    to the world's left; placed with position/axis/angle, the same pose."""
    yaw = np.array([[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    for lidar in (pyclray.Lidar(elevations=[0.0], columns=4, pose=yaw),
                  pyclray.Lidar(elevations=[0.0], columns=4, position=(0.0, 0.0, 0.0), axis=(0, 0, 1), angle=90.0)):
        scan = pyclray.scan(scene_of(four_balls()), lidar)
        assert scan["id"][0].tolist() == [3, 2, 1, 0]  # behind the sensor is the world's -y
        assert np.allclose(lidar.world_from_sensor, yaw, atol=1e-15)
    moved = pyclray.Lidar(elevations=[0.0], columns=4, position=(2.0, 0.0, 0.0))
    assert pyclray.scan(scene_of(four_balls()), moved)["range"][0, 2] == pytest.approx(2.0, rel=1e-6)


# -- exactness: ranges against the float64 oracle ----------------------------------------------------
def oracle_check(scene, lidar, precision="fp32", min_judged=0.1):
    """The scan's ranges, ids and normals against the oracle on the sensor's float64 rays (within the
    error model, silhouettes and edges explained), and its points from those ranges."""
    scan = pyclray.scan(scene, lidar, precision=precision)
    origin, directions = lidar.rays()
    directions = directions.reshape(-1, 3)
    result = {"depth": scan["range"].reshape(-1), "normal": scan["normal"].reshape(-1, 3), "id": scan["id"].reshape(-1)}
    assert_agrees_with_oracle(scene, np.tile(origin, (len(directions), 1)), directions, result, precision,
                              min_judged=min_judged)
    return scan


def test_ranges_of_a_plane_meet_the_oracle_and_the_exact_formula():
    """On the ground 1.7 below the sensor a beam of elevation e < 0 returns 1.7 / sin(-e)."""
    lidar = pyclray.Lidar(preset="VLP-16", columns=360)
    scan = oracle_check(scene_of([pyclray.Plane((0.0, 0.0, 1.0), 1.7)]), lidar, min_judged=0.4)
    down = lidar.elevation_angles < 0
    exact = 1.7 / np.sin(np.radians(-lidar.elevation_angles[down]))
    error = np.abs(scan["range"][down].astype(np.float64) - exact[:, None]) / exact[:, None]
    assert error.max() < 4 * np.finfo(np.float32).eps
    assert np.all(scan["id"][~down] == -1)


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_ranges_of_spheres_far_from_the_origin_meet_the_oracle(precision):
    rng = np.random.default_rng(7)
    shift = np.array([1.0e5, -2.0e5, 50.0])
    shapes = [pyclray.Sphere(tuple(shift + rng.uniform(-20, 20, 3) * (1, 1, 0.2)), float(rng.uniform(0.5, 4)))
              for _ in range(12)]
    shapes.append(pyclray.Plane((0.0, 0.0, 1.0), float(-(shift[2] - 2.0))))
    lidar = pyclray.Lidar(preset="HDL-32E", columns=400, position=tuple(shift), axis=(0.2, 0.1, 1.0), angle=33.0)
    oracle_check(scene_of(shapes), lidar, precision)


def test_ranges_of_a_mesh_meet_the_oracle():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=2.0)
    mesh = pyclray.Mesh(sphere.vertices, sphere.faces, translate=(6.0, 1.0, 0.5))
    box = trimesh.creation.box((3.0, 3.0, 3.0))
    other = pyclray.Mesh(box.vertices, box.faces, translate=(-5.0, -4.0, 0.0), axis=(0, 0, 1), angle=20.0)
    lidar = pyclray.Lidar(preset="OS1-64", columns=512)
    scan = oracle_check(scene_of([mesh, other, pyclray.Plane((0.0, 0.0, 1.0), 2.0)]), lidar)
    assert {0, 1, 2} <= set(np.unique(scan["id"]).tolist())


def test_points_are_the_ranges_along_the_beams():
    lidar = pyclray.Lidar(preset="VLP-16", columns=90, position=(1.0, 2.0, 3.0), axis=(0, 0, 1), angle=30.0)
    scene = scene_of([pyclray.Plane((0.0, 0.0, 1.0), 0.0), pyclray.Sphere((5.0, 5.0, 3.0), 1.5, label=4)], [lidar])
    scan = pyclray.scan(scene)
    ring, column = scan["ring"], scan["column"]
    hit = scan["id"] >= 0
    assert np.array_equal(np.stack(np.nonzero(hit)), np.stack([ring, column]))  # row-major order
    r = scan["range"][ring, column].astype(np.float64)
    assert np.array_equal(scan["point_range"], scan["range"][ring, column])
    assert np.allclose(scan["points"], r[:, None] * lidar.directions()[ring, column], rtol=0, atol=1e-12)
    pose = lidar.world_from_sensor
    assert np.allclose(scan["points_world"], scan["points"] @ pose[:3, :3].T + pose[:3, 3], rtol=0, atol=1e-12)
    assert np.array_equal(scan["position"][ring, column], scan["points_world"])
    assert np.all(scan["position"][~hit] == 0) and np.all(scan["normal"][~hit] == 0)
    assert set(np.unique(scan["label"][hit]).tolist()) == {-1, 4} and np.all(scan["label"][~hit] == -1)
    assert np.allclose(scan.pose, pose) and scan.lidar.name == "lidar0"


# -- range limits ----------------------------------------------------------------------------------------
def test_returns_outside_the_range_are_misses_and_a_near_one_hides_what_is_behind():
    shapes = [pyclray.Sphere((3.0, 0.0, 0.0), 1.0), pyclray.Plane((1.0, 0.0, 0.0), -10.0)]  # ball 2 away, wall 10
    base = pyclray.Lidar(elevations=[0.0], columns=4)
    ahead = lambda lidar: pyclray.scan(scene_of(shapes), lidar)  # noqa: E731
    assert ahead(base)["id"][0, 2] == 0
    far = ahead(dataclasses.replace(base, range=(0.0, 1.9)))
    assert far["id"][0, 2] == -1 and far["range"][0, 2] == np.inf and far["label"][0, 2] == -1
    # nearer than min: a miss, the wall behind the ball is not seen through it
    near = ahead(dataclasses.replace(base, range=(2.5, 100.0)))
    assert near["id"][0, 2] == -1 and np.all(near["normal"][0, 2] == 0)
    assert ahead(dataclasses.replace(base, range=(1.5, 2.5)))["range"][0, 2] == pytest.approx(2.0, rel=1e-6)
    assert ahead(dataclasses.replace(base, range=(0.0, 9.0)))["id"][0, 0] == -1  # the wall behind, 10 away
    assert len(near["ring"]) == int((near["id"] >= 0).sum())


# -- sweeping scans ---------------------------------------------------------------------------------------
SWEEP_SCENE = """
[[shapes]]
type = "plane"
normal = [0.0, 0.0, 1.0]
offset = 1.5

[[shapes]]
type = "box"
name = "car"
center = [6.0, -3.0, 0.0]
size = [2.0, 1.0, 1.5]
label = 1

[lidar]
name = "roof"
elevations = [2.0, 0.0, -2.0, -10.0]
columns = 120
range = [0.5, 80.0]
sweep = true
rate = 10.0
{extra}

[animation]
fps = 10.0
duration = 1.0

[[animation.keys]]
target = "car"
time = 0.0
center = [6.0, -3.0, 0.0]

[[animation.keys]]
target = "car"
time = 0.1
center = [6.0, 3.0, 0.0]
{keys}
"""


def sweep_scene(tmp_path, extra="", keys=""):
    path = tmp_path / "sweep.toml"
    path.write_text(SWEEP_SCENE.format(extra=extra, keys=keys))
    return pyclray.load_scene(path)


def car_columns(scan):
    return np.unique(scan["column"][scan["id"][scan["ring"], scan["column"]] == 1])


def assert_columns_are_static_scans(scene, scan, columns):
    """Each column of a sweeping scan equals, bit for bit, that column of a static scan of the scene (and
    the sensor) at the column's time, on a handle prepared for that scene alone (not one updated to it)."""
    for c in columns:
        at = scene.at(float(scan["time"][c]))
        lidar = dataclasses.replace(at.lidars[0], sweep=False)
        with pyclray.prepare(at) as tracer:
            static = tracer.scan(lidar)
        for key in ("range", "id", "normal", "position"):
            assert np.array_equal(static[key][:, c], scan[key][:, c]), (key, c)


def test_a_sweep_shows_a_moving_object_skewed_and_each_column_is_the_scene_at_its_time(tmp_path):
    scene = sweep_scene(tmp_path)
    scan = pyclray.scan(scene)
    lidar = scene.lidars[0]
    assert np.array_equal(scan["time"], np.arange(120) / (120 * 10.0))  # one revolution in 1 / rate
    assert lidar.rate == 10.0
    faster = dataclasses.replace(lidar, frequency=20.0)  # frequency: another name of rate
    assert faster.rate == 20.0 and pyclray.scan(scene, faster)["time"][60] == 60 / (120 * 20.0)
    assert dataclasses.replace(lidar, rate=5.0).rate == 5.0
    # the car drives left (+y) at 60 units/s while the beams turn right: it shows in fewer columns, earlier
    still = pyclray.scan(scene.at(0.0), dataclasses.replace(lidar, sweep=False))
    swept, static = car_columns(scan), car_columns(still)
    assert len(swept) < len(static) and swept.max() < static.min()
    assert_columns_are_static_scans(scene, scan, range(120))  # every column, those cast together included
    # a scan starting later: the car stands still at its last key, and the sweep is a static scan
    parked = pyclray.scan(scene, time=0.5)
    assert np.array_equal(parked["range"], pyclray.scan(scene.at(0.5), dataclasses.replace(lidar, sweep=False))["range"])
    assert car_columns(parked).min() < 60  # to the left, ahead of column 60


def test_a_moving_sensor_sweeps_and_steps_share_a_time(tmp_path):
    keys = """
[[animation.keys]]
target = "roof"
time = 0.0
position = [0.0, 0.0, 0.0]

[[animation.keys]]
target = "roof"
time = 0.1
position = [0.0, -3.0, 0.5]
"""
    scene = sweep_scene(tmp_path, extra="position = [0.0, 0.0, 0.0]\nsteps = 12", keys=keys)
    scan = pyclray.scan(scene)
    assert np.array_equal(scan["time"], np.repeat(np.arange(12) / 120.0, 10))  # 12 slices of 10 columns
    assert_columns_are_static_scans(scene, scan, range(0, 120, 3))
    assert np.allclose(scan.pose[:3, 3], 0.0) and scan.lidar.position == (0.0, 0.0, 0.0)


def test_without_sweep_the_whole_revolution_is_the_scene_at_one_time(tmp_path):
    scene = sweep_scene(tmp_path)
    lidar = dataclasses.replace(scene.lidars[0], sweep=False)
    scan = pyclray.scan(scene, lidar, time=0.05)
    assert np.all(scan["time"] == 0.05)
    assert np.array_equal(scan["range"], pyclray.scan(scene.at(0.05), lidar)["range"])


def test_a_handles_scan_is_the_functions_and_leaves_the_handle_as_it_was(tmp_path):
    scene = sweep_scene(tmp_path)
    with pyclray.prepare(scene) as tracer:
        scan = tracer.scan()
        assert np.array_equal(scan["range"], pyclray.scan(scene)["range"])
        assert tracer.scene is scene
        origins = np.zeros((1, 3))
        hit = tracer.cast(origins, [[6.0, -3.0, 0.0]])  # the car as written in its table
        assert hit["id"][0] == 1
        again = tracer.scan("roof")
        assert np.array_equal(again["id"], scan["id"])


# -- scene files ---------------------------------------------------------------------------------------
def load_text(tmp_path, text):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return pyclray.load_scene(path)


def test_lidars_tables_name_their_sensors(tmp_path):
    scene = load_text(tmp_path, """
[[shapes]]
type = "sphere"
center = [4.0, 0.0, 0.0]
radius = 1.0

[[lidars]]
name = "front"
preset = "HDL-64E"
pose = [[1,0,0,0],[0,1,0,0],[0,0,1,1.8],[0,0,0,1]]

[[lidars]]
elevations = [0.0]
columns = 4
""")
    assert [lidar.name for lidar in scene.lidars] == ["front", "lidar1"]
    assert scene.lidars[0].world_from_sensor[2, 3] == 1.8
    assert pyclray.scan(scene, "lidar1")["id"][0, 2] == 0
    assert pyclray.scan(scene)["range"].shape == (64, 2083)
    assert scene.camera.eye == (0.0, 0.0, 1.8)  # no [camera]: the first sensor's view


@pytest.mark.parametrize("table, key, words", [
    ('preset = "VLP-32"', "preset", "unknown preset 'VLP-32'"),
    ('preset = "VLP-16"\nelevations = [0.0]', "elevations", "not both"),
    ("elevations = [0.0, 1.0]", "columns", "number of columns"),
    ("elevations = []\ncolumns = 4", "elevations", "non-empty"),
    ('elevations = [0.0, "x"]\ncolumns = 4', "elevations", "beam 1"),
    ("elevations = [0.0, 95.0]\ncolumns = 4", "elevations", "beam 1"),
    ('preset = "VLP-16"\ncolumns = 0', "columns", ">= 1"),
    ('preset = "VLP-16"\ncolumns = 10.5', "columns", "whole number"),
    ('preset = "OS1-64"\ncolumns = 1048576', "columns", "rays per scan"),
    ('preset = "VLP-16"\nrange = [5.0, 1.0]', "range", "min < max"),
    ('preset = "VLP-16"\nrange = [-1.0, 1.0]', "range", "0 <= min"),
    ('preset = "VLP-16"\nrange = 3.0', "range", "[min, max]"),
    ('preset = "VLP-16"\npose = [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]', "pose", "rigid"),
    ('preset = "VLP-16"\npose = [[1,0,0],[0,1,0],[0,0,1]]', "pose", "4x4"),
    ('preset = "VLP-16"\npose = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\nposition = [0,0,0]', "position", "not both"),
    ('preset = "VLP-16"\nrate = 0.0', "rate", "> 0"),
    ('preset = "VLP-16"\nsweep = 1', "sweep", "true or false"),
    ('preset = "VLP-16"\nsteps = 5000', "steps", "<= 1800"),
    ('preset = "VLP-16"\nangle = 10.0', "angle", "axis"),
    ('preset = "VLP-16"\nrate = 10.0\nhz = 10.0', "hz", "unknown key"),
    ('preset = "VLP-16"\nrate = 5.0\nfrequency = 20.0', "frequency", "not both"),
])
def test_bad_lidar_keys_are_one_line_naming_the_key(tmp_path, table, key, words):
    with pytest.raises(pyclray.SceneError) as caught:
        load_text(tmp_path, f'[[shapes]]\ntype = "sphere"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\n\n[lidar]\n{table}\n')
    message = str(caught.value)
    assert "\n" not in message and "table [lidar]" in message and f"key {key!r}" in message and words in message


def test_bad_scene_level_lidar_tables(tmp_path):
    both = '[lidar]\npreset = "VLP-16"\n\n[[lidars]]\npreset = "VLP-16"\n'
    with pytest.raises(pyclray.SceneError, match="not both"):
        load_text(tmp_path, both)
    twice = '[[lidars]]\nname = "a"\npreset = "VLP-16"\n\n[[lidars]]\nname = "a"\npreset = "OS1-64"\n'
    with pytest.raises(pyclray.SceneError, match=r"\[\[lidars\]\] #1.*'name'.*already used"):
        load_text(tmp_path, twice)
    with pytest.raises(pyclray.SceneError, match=r"\[\[lidars\]\] #0.*'preset'"):
        load_text(tmp_path, "[[lidars]]\ncolumns = 4\n")


def test_bad_scan_requests_are_request_errors(tmp_path):
    scene = scene_of(four_balls(), [pyclray.Lidar(elevations=[0.0], columns=4, name="a")])
    with pytest.raises(pyclray.RequestError, match="no sensor named 'b'.*'a'"):
        pyclray.scan(scene, "b")
    with pytest.raises(pyclray.RequestError, match="lidar: expected a pyclray.Lidar"):
        pyclray.scan(scene, 3)
    with pytest.raises(pyclray.RequestError, match="time: the scene has no"):
        pyclray.scan(scene, time=1.0)
    with pytest.raises(pyclray.RequestError, match="no \\[lidar\\]"):
        pyclray.scan(scene_of(four_balls()))
    with pytest.raises(pyclray.RequestError, match="time: expected a time"):
        pyclray.scan(sweep_scene(tmp_path), time=-1.0)
    with pytest.raises(pyclray.SceneError, match="'preset'"):
        pyclray.Lidar()


# -- files and the command line -------------------------------------------------------------------------
def ply_vertices(path):
    """(points (M, 3), the vertex element's properties as a numpy structured array), read by trimesh."""
    cloud = trimesh.load(path)
    return np.asarray(cloud.vertices), cloud.metadata["_ply_raw"]["vertex"]["data"]


def test_scan_command_writes_npz_and_ply(tmp_path):
    scene = sweep_scene(tmp_path)
    path = tmp_path / "sweep.toml"
    status, out, err = run_cli("scan", path, "-o", tmp_path / "scan.npz", "--time", "0.02")
    assert status == 0 and "wrote" in out and not err
    expected = pyclray.scan(scene, time=0.02)
    with np.load(tmp_path / "scan.npz") as saved:
        for key in ("range", "id", "label", "normal", "position", "points", "points_world", "ring", "column", "time"):
            assert np.array_equal(saved[key], expected[key]), key
        assert saved["pose"].shape == (4, 4) and float(saved["t"]) == 0.02
    assert run_cli("scan", path, "-o", tmp_path / "scan.ply", "--lidar", "roof")[0] == 0
    points, vertex = ply_vertices(tmp_path / "scan.ply")
    scan = pyclray.scan(scene)
    assert np.array_equal(points, scan["points_world"])  # doubles: the world's digits kept
    assert vertex.dtype.names == ("x", "y", "z", "nx", "ny", "nz", "id", "label", "ring", "column", "range")
    for key in ("ring", "column"):
        assert np.array_equal(vertex[key], scan[key])
    assert np.array_equal(vertex["range"], scan["point_range"])
    assert np.array_equal(vertex["label"], scan["label"][scan["ring"], scan["column"]])
    assert np.array_equal(np.stack([vertex["nx"], vertex["ny"], vertex["nz"]], 1), scan["normal"][scan["ring"], scan["column"]])


def test_render_writes_the_hit_pixels_as_a_ply(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text('[camera]\neye = [0.0, -6.0, 2.0]\ntarget = [0.0, 0.0, 0.0]\nup = [0.0, 0.0, 1.0]\nfov = 50.0\n'
                    '[image]\nwidth = 40\nheight = 30\n[[shapes]]\ntype = "sphere"\ncenter = [0.0, 0.0, 0.0]\n'
                    'radius = 1.0\nlabel = 7\n')
    status, out, _ = run_cli("render", path, "-o", tmp_path / "cloud.ply")
    assert status == 0
    frame = pyclray.render(pyclray.load_scene(path), aovs=("position", "normal", "id", "label"))
    hit = frame["id"] >= 0
    points, vertex = ply_vertices(tmp_path / "cloud.ply")
    assert np.array_equal(points, frame["position"][hit].astype(np.float64))
    assert np.all(vertex["label"] == 7) and np.all(vertex["id"] == 0)
    assert np.array_equal(np.stack([vertex["row"], vertex["column"]]), np.stack(np.nonzero(hit)))


@pytest.mark.parametrize("args, words", [
    (["-o", "{tmp}/scan.txt"], "expected OUT.npz"),
    (["-o", "{tmp}/scan.npz", "--lidar", "nope"], "--lidar nope: no such sensor"),
    (["-o", "{tmp}/scan.npz", "--time", "-1"], "--time"),
    (["-o", "{tmp}/missing/scan.npz"], "does not exist"),
])
def test_bad_scan_options_exit_2_with_one_line_and_no_file(tmp_path, args, words):
    sweep_scene(tmp_path)
    status, out, err = run_cli("scan", tmp_path / "sweep.toml", *[a.format(tmp=tmp_path) for a in args])
    assert status == 2 and words in err and len(err.strip().splitlines()) == 1
    assert not list(tmp_path.glob("scan.*")) and not list(tmp_path.glob(".scan*"))


def test_a_scene_without_a_lidar_or_animation_is_bad_input_for_scan(tmp_path):
    path = tmp_path / "plain.toml"
    path.write_text('[camera]\neye = [0.0, 0.0, 5.0]\ntarget = [0.0, 0.0, 0.0]\nfov = 40.0\n')
    status, _, err = run_cli("scan", path, "-o", tmp_path / "scan.npz")
    assert status == 2 and "no [lidar]" in err
    sweep_scene(tmp_path)
    bad = tmp_path / "static.toml"
    bad.write_text('[lidar]\npreset = "VLP-16"\n')
    status, _, err = run_cli("scan", bad, "-o", tmp_path / "scan.npz", "--time", "1")
    assert status == 2 and "no [animation]" in err and not (tmp_path / "scan.npz").exists()


def test_an_animated_sensor_placed_by_a_pose_cannot_key_its_position(tmp_path):
    """A sensor given by a pose moves by position keys only if placed by position: the frame's sensor
    names the key, as every frame's scene is checked at load."""
    text = ('[lidar]\nname = "a"\npreset = "VLP-16"\npose = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n'
            '[animation]\nfps = 10.0\nduration = 1.0\n[[animation.keys]]\ntarget = "a"\ntime = 0.0\n'
            'position = [1.0, 0.0, 0.0]\n')
    with pytest.raises(pyclray.SceneError) as caught:
        load_text(tmp_path, text)
    assert "'position'" in str(caught.value) and "not both" in str(caught.value)


def test_numpy_inputs_and_a_frame_without_positions(tmp_path):
    lidar = pyclray.Lidar(elevations=np.array([1.0, -1.0]), columns=np.int64(8), pose=np.eye(4), steps=np.int32(4))
    assert (lidar.beams, lidar.columns, lidar.steps) == (2, 8, 4) and lidar.pose[0] == (1.0, 0.0, 0.0, 0.0)
    frame = pyclray.render(scene_of(four_balls()), aovs=("depth", "id"))
    with pytest.raises(pyclray.RequestError, match="position image"):
        pyclray.write_ply(tmp_path / "cloud.ply", frame)
    assert not list(tmp_path.iterdir())


def test_render_ply_refuses_previews_and_clusters(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text('[camera]\neye = [0.0, 0.0, 5.0]\ntarget = [0.0, 0.0, 0.0]\nfov = 40.0\n[[shapes]]\ntype = "sphere"\n'
                    'center = [0.0, 0.0, 0.0]\nradius = 1.0\n')
    for extra, words in ((["--png"], "--png"), (["--workers", "2"], "--workers")):
        status, _, err = run_cli("render", path, "-o", tmp_path / "cloud.ply", *extra)
        assert status == 2 and words in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "cloud.ply").exists()


def test_a_sweep_through_an_axis_of_zero_names_the_key_and_time(tmp_path):
    """Every frame (k / fps) is checked at load; a sweep's times between them are checked as they are met."""
    keys = """
[[animation.keys]]
target = "roof"
time = 0.0
axis = [0.0, 0.0, 1.0]

[[animation.keys]]
target = "roof"
time = 0.1
axis = [0.0, 0.0, -1.0]
"""
    scene = sweep_scene(tmp_path, extra="position = [0.0, 0.0, 0.0]\naxis = [0.0, 0.0, 1.0]\nangle = 30.0", keys=keys)
    with pytest.raises(pyclray.SceneError, match=r"key 'axis': at t = 0.05 s the animated axis is \[0, 0, 0\]"):
        pyclray.scan(scene)


def test_a_scene_file_path_and_a_closed_handle(tmp_path):
    sweep_scene(tmp_path)
    path = tmp_path / "sweep.toml"
    assert pyclray.scan(str(path), "roof", time=0.0)["range"].shape == (4, 120)
    tracer = pyclray.prepare(path)
    tracer.close()
    with pytest.raises(pyclray.RequestError, match="closed"):
        tracer.scan()


def test_a_sweep_of_a_moving_mesh_a_moving_sphere_and_a_batch_of_spheres(tmp_path):
    """Meshes keep shared vertices on the device: a handle updated to a frame casts the moved triangles."""
    ico = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    mesh = pyclray.Mesh(ico.vertices, ico.faces, translate=(5.0, -3.0, 0.0), name="ball")
    balls = pyclray.Spheres(np.array([[4.0, 4.0, 0.0], [-4.0, 3.0, 0.5]]), np.array([0.8, 0.6]), name="batch")
    lidar = pyclray.Lidar(elevations=[3.0, 0.0, -3.0], columns=90, sweep=True, name="s", position=(0.0, 0.0, 0.0))
    animation = pyclray.Animation(10.0, 1.0, (
        {"target": "ball", "time": 0.0, "translate": [5.0, -3.0, 0.0]},
        {"target": "ball", "time": 0.1, "translate": [5.0, 3.0, 0.0]},
        {"target": "bead", "time": 0.0, "center": [-3.0, 3.0, 0.0]},
        {"target": "bead", "time": 0.1, "center": [-3.0, -3.0, 0.0]},
        {"target": "s", "time": 0.0, "position": [0.0, 0.0, 0.0]},
        {"target": "s", "time": 0.1, "position": [0.5, 0.0, 0.0]},
    ))
    bead = pyclray.Sphere((-3.0, 3.0, 0.0), 0.7, name="bead")
    scene = scene_of([mesh, balls, pyclray.Plane((0.0, 0.0, 1.0), 1.0), bead], [lidar], animation)
    scan = pyclray.scan(scene)
    assert (scan["id"] == 0).sum() > 5 and (scan["id"] == 1).sum() > 5 and (scan["id"] == 3).sum() > 3
    assert_columns_are_static_scans(scene, scan, range(0, 90, 2))
