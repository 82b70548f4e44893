"""Frames, views and tiles on a Dask cluster: the same images and the same files as a local run, warm
workers, errors raised in the client as they are locally, and a killed worker's tasks run again.

One real LocalCluster of two worker processes serves the module (starting one costs seconds); the
commands reach it with --scheduler, and one test starts its own with --workers. Small images keep the
tasks short. The test that kills a worker runs last, as it changes the cluster's workers."""
import os
import signal
import subprocess
import sys

import dask
import numpy as np
import pytest

import pyclray
from pyclray.apps import cli
from pyclray import cluster
from pyclray.engine.launch import programs
from pyclray.model.errors import DeviceError, SceneError
from pyclray.io.exr import read_exr

from conftest import REPO
from test_animate import SCENE

FPS = 4.0


@pytest.fixture(scope="module")
def client():
    with cluster.connect(workers=2) as client:
        yield client


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "anim.toml"
    path.write_text(SCENE.format(duration=2.0))  # 8 frames of 24x16
    return path


def pyclray_cli(capsys, *args):
    """The command run in this process (no interpreter start-up per run): (status, stdout, stderr)."""
    status = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


def assert_same_images(frame, expected):
    assert sorted(frame) == sorted(expected)
    for aov in expected:
        assert frame[aov].dtype == expected[aov].dtype and np.array_equal(frame[aov], expected[aov]), aov


class Count:
    def __init__(self):
        self.n = 0

    def update(self, n=1):
        self.n += n


def test_connect_starts_two_single_threaded_worker_processes(client):
    assert list(client.nthreads().values()) == [1, 1]
    pids = client.run(os.getpid)
    assert len(set(pids.values())) == 2 and os.getpid() not in pids.values()
    # each worker's PoCL gets its share of the cores (2 workers on N cores: N // 2 threads, at least 1)
    share = str(max(1, cluster._cores() // 2))
    assert set(client.run(lambda: os.environ["POCL_CPU_MAX_CU_COUNT"]).values()) == {share}


def test_animation_frames_are_the_local_frames_in_order_and_programs_stay_warm(client, scene_file):
    """Frame k from the cluster is render(scene.at(k / fps)) bit for bit, the frames come in order, the
    bar advances once per task, and each worker builds (or reads from disk) the programs once, in the
    job's setup: every frame then takes them from the worker's memory."""
    scene = pyclray.load_scene(scene_file)
    builds = lambda: sum(s["compiled"] + s["from_disk"] for s in client.run(lambda: dict(programs.stats)).values())
    fetched = lambda: sum(s["from_memory"] for s in client.run(lambda: dict(programs.stats)).values())
    before_builds, before_fetched = builds(), fetched()
    bar = Count()
    frames = list(cluster.render_animation(client, scene, frames=range(1, 8), progress=bar))
    assert [t for t, _ in frames] == [k / FPS for k in range(1, 8)] and bar.n == 7
    for k, (t, frame) in zip(range(1, 8), frames):
        assert_same_images(frame, pyclray.render(scene.at(t)))
    assert builds() - before_builds <= 2 * 2  # the render's and the per-view pass's, at most once per worker
    assert fetched() - before_fetched >= 7  # every frame's kernel came from memory
    assert not np.array_equal(frames[0][1]["depth"], frames[-1][1]["depth"])  # the camera moves
    # the job is gone from the workers afterwards
    assert all(not any(name.startswith("pyclray-") for name in plugins)
               for plugins in client.run(lambda dask_worker: list(dask_worker.plugins)).values())


def test_views_cameras_and_scenes_are_the_local_renders(client):
    scene = pyclray.load_scene(REPO / "scenes/tp02.toml").with_size(20, 12)
    cameras = [pyclray.Camera(eye=(4.0 * np.sin(a), 2.0, 4.0 * np.cos(a)), target=(0.0, 0.5, 0.0), fov=50.0)
               for a in np.linspace(0, 3, 5)]
    views = cameras + [scene.with_size(9, 7)]  # a whole other scene travels with its task
    results = list(cluster.render_views(client, scene, views, aovs=("depth", "id"), precision="fp64"))
    assert [i for i, _ in results] == list(range(len(views)))
    import dataclasses

    for (_, frame), view in zip(results, views):
        expected_scene = view if isinstance(view, pyclray.Scene) else dataclasses.replace(scene, camera=view)
        assert_same_images(frame, pyclray.render(expected_scene, aovs=("depth", "id"), precision="fp64"))


@pytest.mark.parametrize("rows", [7, 16])
def test_bands_put_together_are_the_whole_image(client, rows):
    """Bands of 7 rows cut the culling tiles (16x16) in the middle; 16 rows match them."""
    scene = pyclray.load_scene(REPO / "scenes/tp02.toml").with_size(37, 23)
    bands = list(cluster.render_bands(client, scene, aovs=("depth", "id"), rows=rows))
    assert [b["depth"].shape for b in bands] == [(min(rows, 23 - top), 37) for top in range(0, 23, rows)]
    assert_same_images(cluster.render_image(client, scene, rows=rows), pyclray.render(scene))


def test_an_error_on_a_worker_is_the_local_error(client):
    """A camera that makes an invalid scene: the worker's SceneError is raised in the client with the
    message a local render gives; the job's other tasks are cancelled and the job removed."""
    import dataclasses

    scene = pyclray.load_scene(REPO / "scenes/tp02.toml").with_size(8, 8)
    narrow = pyclray.Camera(eye=(0.0, 2.0, 6.0), target=(0.0, 0.5, 0.0), fov=1e-300)  # valid alone
    with pytest.raises(SceneError) as local:
        dataclasses.replace(scene, camera=narrow)
    with pytest.raises(SceneError) as remote:
        list(cluster.render_views(client, scene, [scene.camera, narrow, scene.camera]))
    assert "fov" in str(remote.value) and str(remote.value) == str(local.value)
    with pytest.raises(DeviceError, match="no OpenCL device matches 'no-such-device'"):
        list(cluster.render_views(client, scene, [scene.camera], device="no-such-device"))
    assert all(not any(name.startswith("pyclray-") for name in plugins)
               for plugins in client.run(lambda dask_worker: list(dask_worker.plugins)).values())


def test_animate_on_a_cluster_writes_the_local_files_bit_for_bit(client, tmp_path, scene_file, capsys):
    address = client.scheduler.address
    local, remote = tmp_path / "local", tmp_path / "remote"
    assert pyclray_cli(capsys, "animate", scene_file, "-o", f"{local}/")[0] == 0
    status, out, err = pyclray_cli(capsys, "animate", scene_file, "-o", f"{remote}/", "--scheduler", address)
    assert status == 0, err
    assert "2 workers at tcp://" in out and "on the workers" in out
    names = sorted(p.name for p in local.iterdir())
    assert names == sorted(p.name for p in remote.iterdir()) and len(names) == 8 * 4  # exr, depth, normal and id previews
    for name in names:
        assert (local / name).read_bytes() == (remote / name).read_bytes(), name
        assert (local / name).stat().st_mode == (remote / name).stat().st_mode, name
    for kind in ("gif", "mp4"):
        assert pyclray_cli(capsys, "animate", scene_file, "-o", tmp_path / f"local.{kind}")[0] == 0
        status, out, err = pyclray_cli(capsys, "animate", scene_file, "-o", tmp_path / f"remote.{kind}", "--scheduler", address)
        assert status == 0, err
        assert (tmp_path / f"local.{kind}").read_bytes() == (tmp_path / f"remote.{kind}").read_bytes(), kind
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["anim.toml", "local", "remote", "local.gif", "remote.gif", "local.mp4", "remote.mp4"])  # no temporaries


def test_render_with_workers_writes_the_local_exr_bit_for_bit(tmp_path, capsys, monkeypatch):
    """`pyclray render --workers 2` starts its own LocalCluster and renders the image in bands of
    rows (of 7 rows here: tasks of 280 pixels), streamed into the files as they come."""
    monkeypatch.setattr(cluster, "TASK_PIXELS", 40 * 7)
    scene = REPO / "scenes/tp02.toml"
    status, out, err = pyclray_cli(capsys, "render", scene, "-o", tmp_path / "tiled.exr", "--size", "40x30",
                                   "--workers", "2", "--png")
    assert status == 0, err
    assert "5 bands of 7 rows on 2 workers" in out
    assert pyclray_cli(capsys, "render", scene, "-o", tmp_path / "whole.exr", "--size", "40x30", "--png")[0] == 0
    for suffix in (".exr", ".depth.png", ".normal.png", ".id.png"):
        assert (tmp_path / f"tiled{suffix}").read_bytes() == (tmp_path / f"whole{suffix}").read_bytes(), suffix


def test_bad_cluster_input_exits_2_with_one_line_and_writes_nothing(client, tmp_path, scene_file, monkeypatch, capsys):
    # a device no worker has: the job's setup fails on the workers, before any frame
    status, out, err = pyclray_cli(capsys, "animate", scene_file, "-o", tmp_path / "x.gif", "--device", "no-such-device",
                                   "--scheduler", client.scheduler.address)
    assert status == 2 and "no OpenCL device matches 'no-such-device'" in err and len(err.strip().splitlines()) == 1
    # --workers and --scheduler exclude each other; --workers needs a count >= 1 (argparse: exit 2)
    for args in (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], ["--workers", "0"]):
        with pytest.raises(SystemExit) as exit:
            cli.main(["animate", str(scene_file), "-o", str(tmp_path / "x.gif"), *args])
        err = capsys.readouterr().err
        assert exit.value.code == 2 and "--workers" in err
    # nothing listens there (a short connect timeout keeps the test short)
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 1)
    status, out, err = pyclray_cli(capsys, "animate", scene_file, "-o", tmp_path / "x.gif", "--scheduler", "tcp://127.0.0.1:9")
    assert status == 2 and "--scheduler tcp://127.0.0.1:9: cannot connect" in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.toml"]


def test_an_image_too_large_to_put_together_here_is_a_request_error_before_any_task(client):
    """render_image puts the whole image together in the client: too large for its memory is the
    RequestError that pyclray.render raises (issue 27), before any task (render_bands streams)."""
    huge = pyclray.load_scene(REPO / "scenes/tp02.toml").with_size(60000, 60000)
    with pytest.raises(pyclray.RequestError, match="need 172,800,000,000 bytes"):
        cluster.render_image(client, huge, aovs=("depth", "normal", "id", "zdepth", "position", "shaded"))


def test_without_distributed_the_options_say_what_to_install(tmp_path, scene_file):
    code = ("import sys; sys.modules['distributed'] = None; from pyclray.apps.cli import main; "
            f"sys.exit(main(['animate', {str(scene_file)!r}, '-o', {str(tmp_path / 'x.gif')!r}, '--workers', '2']))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 2 and "pip install 'pyclray[cluster]'" in result.stderr, result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.toml"]


def test_a_killed_worker_loses_its_tasks_and_they_run_again(client):
    """SIGKILL one worker process after the first frame arrives: what it was rendering, and the
    results it held that the client had not fetched yet, are computed again (on the other worker, or
    on the one its nanny starts anew), and every frame still equals the local render."""
    scene = pyclray.load_scene(REPO / "scenes/tp02_orbit.toml").with_size(48, 32)
    frames = range(0, 100, 2)
    pids = client.run(os.getpid)
    victim = sorted(pids.values())[0]
    results = []
    # the scheduler may try to fetch a result from the dead worker before it has noticed the death:
    # that connection attempt lasts distributed.comm.timeouts.connect (30 s by default), kept short here
    with dask.config.set({"distributed.comm.timeouts.connect": "3s"}):
        for t, frame in cluster.render_animation(client, scene, aovs=("depth", "id"), frames=frames):
            if not results:
                os.kill(victim, signal.SIGKILL)
            results.append((t, frame))
    assert [t for t, _ in results] == [k / 25.0 for k in frames]
    for t, frame in results:
        assert_same_images(frame, pyclray.render(scene.at(t), aovs=("depth", "id")))
    client.wait_for_workers(2, timeout=60)  # the nanny has started a new worker process
    assert victim not in client.run(os.getpid).values()
