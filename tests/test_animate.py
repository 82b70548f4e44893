"""Rendering an animation: frame k is render(scene.at(k / fps)) exactly, one program serves every
frame, and `pyclray animate` writes complete videos, GIFs and folders or nothing at all (errors,
Ctrl-C). Small images and few frames keep it fast."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import pyclray
from pyclray.apps import cli
from pyclray.engine.launch import programs
from pyclray.io import png
from pyclray.io.exr import read_exr

from conftest import REPO

SCENE = """
[camera]
eye = [0.0, 2.0, 6.0]
target = [0.0, 0.5, 0.0]
fov = 45.0

[image]
width = 24
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

[animation]
fps = 4.0
duration = {duration}

[[animation.keys]]
target = "camera"
time = 0.0
eye = [0.0, 2.0, 6.0]

[[animation.keys]]
target = "camera"
time = 1.0
eye = [6.0, 2.0, 0.0]

[[animation.keys]]
target = "ball"
time = 0.25
center = [0.0, 1.0, 0.0]

[[animation.keys]]
target = "ball"
time = 0.75
center = [1.0, 2.0, 0.0]
"""
FRAMES = 5  # duration 1.25 s at 4 fps


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "anim.toml"
    path.write_text(SCENE.format(duration=1.25))
    return path


def animate(*args):
    return subprocess.run([sys.executable, "-m", "pyclray", "animate", *map(str, args)],
                          capture_output=True, text=True, env=dict(os.environ))


def test_frame_k_is_the_render_of_the_scene_at_k_over_fps(scene_file):
    scene = pyclray.load_scene(scene_file)
    frames = list(pyclray.render_animation(scene))
    assert [t for t, _ in frames] == [k / 4.0 for k in range(FRAMES)]
    for k, (t, frame) in enumerate(frames):
        expected = pyclray.render(scene.at(k / 4.0))
        for aov in pyclray.AOVS:
            assert np.array_equal(frame[aov], expected[aov]), (k, aov)
    # the frames differ (the camera moves): the equality above is not that of one image
    assert not np.array_equal(frames[0][1]["depth"], frames[-1][1]["depth"])


def test_one_program_serves_every_frame():
    """Builds (compiled or read from the disk cache) happen for the first frame only; each later
    frame of the orbiting camera fetches two kernels from memory: the per-view pass's (into the moved
    camera's frame, on the device: pyclray.engine.scene.prepared) and the render's."""
    scene = pyclray.load_scene(REPO / "scenes/tp02_orbit.toml").with_size(32, 32)
    builds = lambda: programs.stats["compiled"] + programs.stats["from_disk"]
    counts, fetched = [], []
    for _ in pyclray.render_animation(scene, aovs=("depth", "id"), frames=range(0, 100, 10)):
        counts.append(builds())
        fetched.append(programs.stats["from_memory"])
    assert counts[1:] == [counts[0]] * 9, counts
    assert np.diff(fetched).tolist() == [2] * 9, fetched


def test_folder_holds_every_frame_as_exr_and_png(tmp_path, scene_file):
    out = tmp_path / "frames"
    result = animate(scene_file, "-o", f"{out}/")
    assert result.returncode == 0, result.stderr
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(f"frame_{k:05d}{ext}" for k in range(FRAMES) for ext in (".exr", ".depth.png", ".normal.png", ".id.png"))
    scene = pyclray.load_scene(scene_file)
    for k in range(FRAMES):
        images = read_exr(out / f"frame_{k:05d}.exr")
        expected = pyclray.render(scene.at(k / 4.0))
        for aov in pyclray.AOVS:
            assert np.array_equal(images[aov], expected[aov]), (k, aov)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.toml", "frames"]  # no temporaries
    assert "render" in result.stdout and "write" in result.stdout and f"{FRAMES} frames" in result.stdout
    assert result.stderr == ""  # no progress bar when stderr is not a terminal


def test_a_progress_bar_is_drawn_on_a_terminal(tmp_path, scene_file):
    """On a terminal (stderr a pty) a tqdm bar counts the frames (from the start here: pyclray's
    one-second delay before a bar appears is set to 0)."""
    import fcntl
    import pty
    import struct
    import termios

    run = ("import sys, pyclray.io.progress as p\np.DELAY = 0\nfrom pyclray.apps.cli import main\nsys.exit(main())")
    controller, terminal = pty.openpty()
    fcntl.ioctl(terminal, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # 100 columns, as a terminal has
    try:
        result = subprocess.run([sys.executable, "-c", run, "animate", str(scene_file), "-o", str(tmp_path / "x.gif")],
                                stdout=subprocess.PIPE, stderr=terminal, text=True, timeout=120)
        os.close(terminal)
        drawn = b""
        while True:
            try:
                chunk = os.read(controller, 4096)
            except OSError:  # the terminal's other end is closed: all read
                break
            if not chunk:
                break
            drawn += chunk
    finally:
        os.close(controller)
    assert result.returncode == 0
    assert b"pyclray animate" in drawn and f"/{FRAMES} [".encode() in drawn and b"frame" in drawn, drawn


def test_frames_option_renders_a_range_and_replaces_an_earlier_folder(tmp_path, scene_file):
    out = tmp_path / "frames"
    assert animate(scene_file, "-o", out, "--aov", "depth").returncode == 0
    result = animate(scene_file, "-o", out, "--aov", "depth", "--frames", "2:4")
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in out.iterdir()) == [
        "frame_00002.depth.png", "frame_00002.exr", "frame_00003.depth.png", "frame_00003.exr"]
    expected = pyclray.render(pyclray.load_scene(scene_file).at(3 / 4.0), aovs=("depth",))
    assert np.array_equal(read_exr(out / "frame_00003.exr")["depth"], expected["depth"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.toml", "frames"]


def test_gif_has_every_frame_and_each_is_the_depth_preview(tmp_path, scene_file):
    from PIL import Image

    out = tmp_path / "anim.gif"
    result = animate(scene_file, "-o", out, "--aov", "depth")
    assert result.returncode == 0, result.stderr
    scene = pyclray.load_scene(scene_file)
    with Image.open(out) as gif:
        assert gif.n_frames == FRAMES and gif.size == (24, 16)
        assert gif.info["duration"] == 250 and gif.info["loop"] == 0
        for k in range(FRAMES):
            gif.seek(k)
            # grey previews go into the GIF exactly (256 grey levels)
            expected = png.preview("depth", pyclray.render(scene.at(k / 4.0), aovs=("depth",))["depth"])
            assert np.array_equal(np.asarray(gif.convert("RGB")), expected), k
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.gif", "anim.toml"]


def test_a_video_shows_the_shaded_image_by_default(tmp_path, scene_file):
    """The contract's default image of a video or GIF is `shaded`: the same file as --aov shaded."""
    default, shaded = tmp_path / "default" / "anim.gif", tmp_path / "shaded" / "anim.gif"
    default.parent.mkdir(), shaded.parent.mkdir()
    assert animate(scene_file, "-o", default).returncode == 0
    assert animate(scene_file, "-o", shaded, "--aov", "shaded").returncode == 0
    depth = tmp_path / "depth.gif"
    assert animate(scene_file, "-o", depth, "--aov", "depth").returncode == 0
    assert default.read_bytes() == shaded.read_bytes() != depth.read_bytes()


def test_mp4_decodes_to_every_frame_at_the_image_size(tmp_path, scene_file):
    import imageio_ffmpeg

    out = tmp_path / "anim.mp4"
    result = animate(scene_file, "-o", out, "--aov", "normal")
    assert result.returncode == 0, result.stderr
    reader = imageio_ffmpeg.read_frames(str(out))
    meta = reader.__next__()
    decoded = [np.frombuffer(f, np.uint8).reshape(16, 24, 3) for f in reader]
    assert meta["size"] == (24, 16) and meta["fps"] == 4.0 and len(decoded) == FRAMES
    # lossy (H.264, 4:2:0) but close: the mean error of frame k's preview is a few grey levels
    scene = pyclray.load_scene(scene_file)
    for k, frame in enumerate(decoded):
        expected = png.preview("normal", pyclray.render(scene.at(k / 4.0), aovs=("normal",))["normal"])
        assert np.abs(frame.astype(int) - expected).mean() < 12, k
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.mp4", "anim.toml"]


def test_render_time_renders_the_scene_at_that_time(tmp_path, scene_file):
    out = tmp_path / "t.exr"
    result = subprocess.run([sys.executable, "-m", "pyclray", "render", scene_file, "-o", out, "--time", "0.6"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    expected = pyclray.render(pyclray.load_scene(scene_file).at(0.6))
    assert np.array_equal(read_exr(out)["depth"], expected["depth"])


@pytest.mark.parametrize(
    "args,needle",
    [
        (["-o", "{tmp}/x.avi"], "expected OUT.mp4, OUT.gif or a folder"),
        (["-o", "{tmp}/nowhere/x.mp4"], "does not exist"),
        (["-o", "{tmp}/x.gif", "--aov", "depth,normal"], "one image"),
        (["-o", "{tmp}/x.gif", "--frames", "3:9"], "--frames"),
        (["-o", "{tmp}/x.gif", "--frames", "2:2"], "--frames"),
        (["-o", "{tmp}/x.gif", "--frames", "a:b"], "--frames"),
        (["-o", "{tmp}/keep/"], "holds files animate did not write"),
        (["-o", "{tmp}/anim.toml/"], "is a file"),
    ],
)
def test_bad_options_exit_2_with_one_line_and_touch_nothing(tmp_path, scene_file, args, needle):
    (tmp_path / "keep").mkdir()
    (tmp_path / "keep" / "notes.txt").write_text("mine")
    before = sorted(p.name for p in tmp_path.rglob("*"))
    result = animate(scene_file, *[a.format(tmp=tmp_path) for a in args])
    assert result.returncode == 2 and needle in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.rglob("*")) == before


def test_a_scene_without_animation_or_with_a_bad_one_exits_2(tmp_path, scene_file):
    result = animate(REPO / "scenes/tp02.toml", "-o", tmp_path / "x.gif")
    assert result.returncode == 2 and "no [animation]" in result.stderr
    bad = tmp_path / "bad.toml"
    bad.write_text(SCENE.format(duration=1.25).replace("center = [1.0, 2.0, 0.0]", "center = [1.0, 2.0]"))
    result = animate(bad, "-o", tmp_path / "x.gif")
    assert result.returncode == 2 and "'center'" in result.stderr and "[[animation.keys]] #3" in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.toml", "bad.toml"]


@pytest.mark.parametrize("name", ["out.mp4", "out.gif", "out"])
def test_ctrl_c_or_a_failure_mid_sequence_leaves_the_old_output_and_no_temporaries(tmp_path, scene_file, monkeypatch, capsys, name):
    """Frame 3's render is interrupted (KeyboardInterrupt, as Ctrl-C raises it) or fails: animate
    exits 130 (quietly) or 1, the earlier output is untouched and nothing else is left."""
    render_module = sys.modules["pyclray.engine.api"]  # the module (pyclray.render is the function)

    out = tmp_path / name
    if name == "out":
        out.mkdir()
        (out / "frame_00000.exr").write_bytes(b"earlier")
    else:
        out.write_bytes(b"earlier")
    real_render = render_module.render
    for error, status in ((KeyboardInterrupt(), 130), (pyclray.PyclrayError("device lost"), 1)):
        calls = []

        def failing_render(scene, *args, **kwargs):
            calls.append(scene)
            if len(calls) == 3:
                raise error
            return real_render(scene, *args, **kwargs)

        monkeypatch.setattr(render_module, "render", failing_render)
        assert cli.main(["animate", str(scene_file), "-o", str(out)]) == status
        assert len(calls) == 3
        captured = capsys.readouterr()
        assert captured.out == "" and (captured.err == "" if status == 130 else "device lost" in captured.err)
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["anim.toml", name])
        if name == "out":
            assert [p.name for p in out.iterdir()] == ["frame_00000.exr"]
        else:
            assert out.read_bytes() == b"earlier"


def test_sigint_during_animate_exits_130_and_leaves_no_partial_video(tmp_path):
    """A real Ctrl-C (SIGINT) while frames are being rendered and encoded."""
    long = tmp_path / "long.toml"
    long.write_text(SCENE.format(duration=500.0))  # 2000 frames: far longer than the test waits
    out = tmp_path / "long.mp4"
    process = subprocess.Popen([sys.executable, "-m", "pyclray", "animate", str(long), "-o", str(out)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        # wait until the temporary video exists and is growing: ffmpeg is encoding frames
        while not any(p.name.startswith(".long.mp4.") and p.stat().st_size > 0 for p in tmp_path.iterdir()):
            assert process.poll() is None and time.monotonic() < deadline, process.communicate()
            time.sleep(0.02)
        process.send_signal(signal.SIGINT)
        stdout, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, stderr
    assert stdout == "" and "Traceback" not in stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.toml"]
