"""`pyclray dataset`: resuming after a kill (no half-written view, complete views never rewritten,
the same bytes as an uninterrupted run), camera placement, --poses, the npz and exr formats, ids in
image files, Dask workers, and bad options (one line, exit status 2, nothing written)."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import pyclray
import pyclray.io.dataset as dataset
from pyclray.io.dataset import Placement, id_image, make_format, view_cameras, write_dataset
from pyclray.io.dataset.placement import labelled_centre
from tests.dataset_scene import read_png, write_scene


def cli(*args, **kwargs):
    return subprocess.run([sys.executable, "-m", "pyclray", *map(str, args)], capture_output=True, text=True,
                          env=dict(os.environ), **kwargs)


def tree(folder: Path) -> dict:
    """Relative path -> bytes of every file under folder."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def scene_path(tmp_path_factory):
    return write_scene(tmp_path_factory.mktemp("scene"))


def run_views(scene_path, out, fmt, count=5, **kwargs):
    scene = pyclray.load_scene(scene_path)
    cameras = view_cameras(scene, Placement("hemisphere", seed=11), count)
    return write_dataset(scene, out, cameras, fmt, settings={"test": 1}, **kwargs)


# -- resuming ---------------------------------------------------------------------------------------
def test_resume_after_a_kill_is_byte_identical(tmp_path, scene_path, monkeypatch):
    """A run killed while writing view 2 (its files half-written under temporary names, no record)
    leaves views 0 and 1 complete; the rerun removes the temporaries, renders views 2.., does not
    touch views 0 and 1, and ends with exactly the files of an uninterrupted run."""
    whole = tmp_path / "whole"
    run_views(scene_path, whole, make_format("bop"))
    killed = tmp_path / "killed"
    real_write_view = dataset.write_view

    def dying(out, encoded):
        if encoded.index == 2:
            (out / "train/000000/rgb/.000002.png.k1ll3d.tmp").write_bytes(b"\x89PNG half")
            raise KeyboardInterrupt
        real_write_view(out, encoded)

    monkeypatch.setattr(dataset, "write_view", dying)
    with pytest.raises(KeyboardInterrupt):
        run_views(scene_path, killed, make_format("bop"), writers=1)
    monkeypatch.setattr(dataset, "write_view", real_write_view)
    records = sorted(p.name for p in (killed / ".pyclray-dataset/views").iterdir())
    assert "000002.json" not in records and {"000000.json", "000001.json"} <= set(records)
    assert not (killed / "train/000000/scene_gt.json").exists()  # the index comes at the end
    done = {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in killed.rglob("000000*") if p.is_file()}
    written = run_views(scene_path, killed, make_format("bop"))
    assert written.skipped == len(records) and written.rendered == 5 - len(records)
    assert {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in done} == done  # complete views untouched
    assert tree(killed) == tree(whole)
    again = run_views(scene_path, killed, make_format("bop"))
    assert again.rendered == 0 and tree(killed) == tree(whole)


def test_cli_killed_and_rerun(tmp_path, scene_path):
    """The command killed with SIGKILL partway, then run again: the same files as one whole run."""
    args = ("dataset", scene_path, "--views", 40, "--seed", 4, "--format", "npz", "--aov", "depth,id")
    whole = tmp_path / "whole"
    assert cli(*args, "-o", whole).returncode == 0
    killed = tmp_path / "killed"
    process = subprocess.Popen([sys.executable, "-m", "pyclray", *map(str, args), "-o", str(killed)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    records = killed / ".pyclray-dataset/views"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if records.is_dir() and len(list(records.iterdir())) >= 2:
            process.send_signal(signal.SIGKILL)
            break
        time.sleep(0.01)
    assert process.wait() == -signal.SIGKILL  # killed partway: some views complete, not all
    assert 2 <= len(list(records.iterdir())) < 40
    assert not (killed / "views.json").exists()
    result = cli(*args, "-o", killed)
    assert result.returncode == 0, result.stderr
    assert tree(killed) == tree(whole)


# -- placement ----------------------------------------------------------------------------------------
def test_views_look_at_the_labelled_centre(scene_path):
    scene = pyclray.load_scene(scene_path)
    centre = labelled_centre(scene)
    for placement in (Placement("orbit", (2.0, 2.0), (30.0, 30.0)), Placement("hemisphere", (1.5, 3.0), (5.0, 85.0), 9)):
        cameras = view_cameras(scene, placement, 8)
        for camera in cameras:
            pose = camera.pose()
            to_centre = centre - pose[:3, 3]
            np.testing.assert_allclose(pose[:3, 2], to_centre / np.linalg.norm(to_centre), atol=1e-12)
            assert placement.radius[0] - 1e-9 <= np.linalg.norm(to_centre) <= placement.radius[1] + 1e-9
            elevation = np.degrees(np.arcsin(-pose[1, 2]))  # the scene's up is +y
            assert placement.elevation[0] - 1e-9 <= elevation <= placement.elevation[1] + 1e-9
            assert np.array_equal(camera.intrinsics(64, 48), scene.camera.intrinsics(64, 48))
            assert pose[1, 0] == pytest.approx(0.0, abs=1e-12)  # no roll: the image's x is horizontal
    # a hemisphere's view k does not depend on how many views are asked
    few = view_cameras(scene, Placement("hemisphere", seed=2), 3)
    many = view_cameras(scene, Placement("hemisphere", seed=2), 7)
    assert all(np.array_equal(a.pose(), b.pose()) for a, b in zip(few, many))
    top = dataset.look_pose(centre, np.array([0.0, 1.0, 0.0]), 2.0, 90.0, 0.0)  # straight above: still a frame
    np.testing.assert_allclose(top[:3, :3].T @ top[:3, :3], np.eye(3), atol=1e-12)


def test_poses_file_forms(tmp_path, scene_path):
    scene = pyclray.load_scene(scene_path)
    pose = dataset.look_pose(labelled_centre(scene), np.array([0.0, 1.0, 0.0]), 3.0, 20.0, 10.0)
    K = [[60.0, 0.0, 30.0], [0.0, 60.0, 25.0], [0.0, 0.0, 1.0]]
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps([pose.tolist(), {"K": K, "pose": pose.tolist()}]))
    cameras = view_cameras(scene, Placement("poses", poses=str(poses)), 2)
    assert np.array_equal(cameras[0].pose(), pose) and np.array_equal(cameras[1].pose(), pose)
    assert np.array_equal(cameras[0].intrinsics(64, 48), scene.camera.intrinsics(64, 48))
    assert np.array_equal(cameras[1].intrinsics(64, 48), np.array(K))
    out = tmp_path / "out"
    result = cli("dataset", scene_path, "-o", out, "--poses", poses, "--format", "npz", "--aov", "depth")
    assert result.returncode == 0, result.stderr
    index = json.loads((out / "views.json").read_text())
    assert [v["file"] for v in index["views"]] == ["000000.npz", "000001.npz"]
    assert index["views"][1]["K"] == K


# -- npz and exr ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["npz", "exr"])
def test_array_formats(tmp_path, scene_path, kind):
    out = tmp_path / "out"
    aovs = ("depth", "normal", "id", "zdepth", "label")
    written = run_views(scene_path, out, make_format(kind, aovs), count=3)
    assert written.rendered == 3
    scene = pyclray.load_scene(scene_path)
    cameras = view_cameras(scene, Placement("hemisphere", seed=11), 3)
    index = json.loads((out / "views.json").read_text())
    assert index["format"] == kind and index["aovs"] == list(aovs) and (index["width"], index["height"]) == (64, 48)
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == sorted(
        ["views.json"] + [f"{k:06d}.{kind}" for k in range(3)] + [f"{k:06d}.id.png" for k in range(3)])
    for k, camera in enumerate(cameras):
        expected = pyclray.render(scene, aovs=aovs, camera=camera)
        entry = index["views"][k]
        pose = camera.pose()
        assert np.array_equal(entry["K"], camera.intrinsics(64, 48)) and np.array_equal(entry["pose"], pose)
        np.testing.assert_allclose(np.array(entry["extrinsic"]) @ pose, np.eye(4), atol=1e-12)
        if kind == "npz":
            arrays = np.load(out / entry["file"])
            assert sorted(arrays.files) == sorted(aovs + ("K", "pose", "extrinsic"))
            assert np.array_equal(arrays["K"], entry["K"]) and np.array_equal(arrays["extrinsic"], entry["extrinsic"])
        else:
            from pyclray.io.exr import read_exr

            arrays, header = read_exr(out / entry["file"], header=True)
            assert np.array_equal(header["intrinsics"], entry["K"]) and np.array_equal(header["pose"], pose)
        for aov in aovs:
            assert np.array_equal(arrays[aov], expected[aov]), aov
        # the id image of image files: 0 background, id + 1 per shape (the raw id is -1 on a miss)
        ids = read_png(out / entry["id_png"])
        assert ids.dtype == np.uint16 and np.array_equal(ids.astype(np.int64) - 1, expected["id"])


def test_id_image():
    ids = np.array([[-1, 0], [5, 254]], np.int32)
    assert id_image(ids, 8).tolist() == [[0, 1], [6, 255]] and id_image(ids, 8).dtype == np.uint8
    assert id_image(ids, 16).dtype == np.uint16
    with pytest.raises(ValueError, match="255"):
        id_image(np.array([255]), 8)


# -- Dask ------------------------------------------------------------------------------------------------
def test_workers_write_the_same_files(tmp_path, scene_path):
    args = ("dataset", scene_path, "--views", 4, "--seed", 6)
    here, there = tmp_path / "here", tmp_path / "there"
    assert cli(*args, "-o", here).returncode == 0
    result = cli(*args, "-o", there, "--workers", 2)
    assert result.returncode == 0, result.stderr
    assert "2 workers" in result.stdout
    assert tree(here) == tree(there)


# -- bad options ----------------------------------------------------------------------------------------
def bad_cases(tmp_path, scene_path):
    scene = Path(scene_path)
    a_file = tmp_path / "file"
    a_file.write_text("x")
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    bad_poses = tmp_path / "bad_poses.json"
    bad_poses.write_text(json.dumps([np.eye(4).tolist(), [[1, 0, 0], [0, 1, 0]]]))
    labelled_sphere = tmp_path / "labelled_sphere.toml"
    labelled_sphere.write_text(scene.read_text().replace('radius = 0.25', 'radius = 0.25\nlabel = 3'))
    out = tmp_path / "out"
    return [
        (("--views", "0", "-o", out), "--views"),
        (("-o", out), "--views"),
        (("--views", "2", "--format", "bop", "--aov", "depth", "-o", out), "--aov"),
        (("--views", "2", "--elevation", "80:10", "-o", out), "--elevation"),
        (("--views", "2", "--elevation", "0:95", "-o", out), "--elevation"),
        (("--views", "2", "--radius", "-1", "-o", out), "--radius"),
        (("--views", "2", "--unit", "0", "-o", out), "--unit"),
        (("--views", "2", "--format", "png", "-o", out), "--format"),
        (("--views", "2", "--orbit", "--hemisphere", "-o", out), "--hemisphere"),
        (("--views", "2", "--format", "npz", "--unit", "2", "-o", out), "--unit"),
        (("--poses", tmp_path / "missing.json", "-o", out), "missing.json"),
        (("--poses", bad_poses, "-o", out), "entry 1: pose"),
        (("--views", "5", "--poses", bad_poses, "-o", out), "entry 1"),
        (("--views", "2", "-o", a_file), "is a file"),
        (("--views", "2", "-o", foreign), "notes.txt"),
        (("--views", "2", "-o", tmp_path / "no" / "such"), "does not exist"),
        (("--views", "2", "--workers", "0", "-o", out), "--workers"),
        (("--views", "2", "--scheduler", "nowhere", "-o", out), "--scheduler"),
    ], labelled_sphere


def test_bad_options(tmp_path, scene_path):
    cases, labelled_sphere = bad_cases(tmp_path, scene_path)
    before = tree(tmp_path)
    for args, named in cases:
        result = cli("dataset", scene_path, *args)
        assert result.returncode == 2, (args, result.stderr)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("pyclray dataset: error: ") and named in lines[0], (args, lines)
        assert tree(tmp_path) == before and not (tmp_path / "out").exists(), args
    result = cli("dataset", labelled_sphere, "--views", "2", "-o", tmp_path / "out")
    assert result.returncode == 2 and "sphere 'ball' has label 3 but no triangle model" in result.stderr
    assert not (tmp_path / "out").exists()


def test_resume_with_other_options_is_refused(tmp_path, scene_path):
    out = tmp_path / "out"
    assert cli("dataset", scene_path, "--views", 2, "-o", out, "--format", "npz").returncode == 0
    before = tree(out)
    result = cli("dataset", scene_path, "--views", 3, "-o", out, "--format", "npz")
    assert result.returncode == 2 and "cannot resume" in result.stderr and "views" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert tree(out) == before
