"""The command line: a good render writes readable EXR channels and previews; bad input gets one
line, exit status 2, and no file left behind."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import pyclray
from pyclray.output import read_exr

REPO = Path(__file__).resolve().parent.parent


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "pyclray.cli", *map(str, args)], capture_output=True, text=True, cwd=cwd,
                          env=dict(os.environ))


def test_render_writes_exr_and_previews(tmp_path):
    out = tmp_path / "tp02.exr"
    result = cli("render", REPO / "scenes/tp02.toml", "-o", out, "--png", "--size", "64x48")
    assert result.returncode == 0, result.stderr
    assert out.is_file() and (tmp_path / "tp02.depth.png").is_file() and (tmp_path / "tp02.normal.png").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tp02.depth.png", "tp02.exr", "tp02.id.png", "tp02.normal.png"]  # no temporaries
    images = read_exr(out)
    expected = pyclray.render(pyclray.load_scene(REPO / "scenes/tp02.toml").with_size(64, 48))
    for name in ("depth", "normal", "id"):
        assert np.array_equal(images[name], expected[name]), name
    assert (images["id"] == -1).any()  # the sky round-trips as -1
    for png in ("tp02.depth.png", "tp02.normal.png", "tp02.id.png"):
        data = (tmp_path / png).read_bytes()
        assert data.startswith(b"\x89PNG\r\n\x1a\n") and b"IEND" in data[-12:]


def test_exr_channel_names_and_types(tmp_path):
    import OpenEXR

    out = tmp_path / "x.exr"
    assert cli("render", REPO / "scenes/tp02.toml", "-o", out, "--size", "8x8").returncode == 0
    with OpenEXR.File(str(out), separate_channels=True) as exr:
        channels = exr.channels()
        assert set(channels) == {"Z", "N.X", "N.Y", "N.Z", "id"}
        assert channels["Z"].pixels.dtype == np.float32 and channels["id"].pixels.dtype == np.uint32


def test_depth_only_exr(tmp_path):
    out = tmp_path / "d.exr"
    result = cli("render", REPO / "scenes/tp02.toml", "-o", out, "--aov", "depth", "--png", "--size", "16x16")
    assert result.returncode == 0, result.stderr
    assert set(read_exr(out)) == {"depth"}
    assert (tmp_path / "d.depth.png").is_file() and not (tmp_path / "d.normal.png").exists()


def test_fp64_render(tmp_path):
    out = tmp_path / "d.exr"
    result = cli("render", REPO / "scenes/tp02.toml", "-o", out, "--precision", "fp64", "--size", "16x16")
    assert result.returncode == 0, result.stderr
    assert "fp64" in result.stdout


BAD_SCENE = """
[camera]
eye = [0.0, 2.0, 6.0]
target = [0.0, 0.5, 0.0]
fov = 45.0

[[shapes]]
type = "sphere"
center = [0.0, 1.0, 0.0]
radius = -1.0
"""


@pytest.mark.parametrize(
    "args,needle",
    [
        (["render", "{bad}", "-o", "{out}"], "radius"),
        (["render", "{missing}", "-o", "{out}"], "cannot read"),
        (["render", "{good}", "-o", "{out}", "--aov", "depth,colour"], "--aov"),
        (["render", "{good}", "-o", "{out}", "--size", "0x5"], "--size"),
        (["render", "{good}", "-o", "{out}", "--precision", "fp16"], "--precision"),
        (["render", "{good}", "-o", "{out}", "--device", "7:7"], "no OpenCL device"),
        (["render", "{good}", "-o", "{tmp}/no/such/folder/x.exr"], "does not exist"),
    ],
)
def test_bad_input_exits_2_with_one_line_and_leaves_no_file(tmp_path, args, needle):
    bad = tmp_path / "bad.toml"
    bad.write_text(BAD_SCENE)
    out = tmp_path / "out.exr"
    names = dict(bad=bad, missing=tmp_path / "missing.toml", good=REPO / "scenes/tp02.toml", out=out, tmp=tmp_path)
    result = cli(*[a.format(**names) for a in args], "--png")
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert needle in lines[-1]
    if "usage:" not in result.stderr:  # our own errors are exactly one line
        assert len(lines) == 1, result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_bad_scene_message_names_file_table_and_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(BAD_SCENE)
    result = cli("render", bad, "-o", tmp_path / "o.exr")
    assert result.returncode == 2
    assert str(bad) in result.stderr and "[[shapes]] #0 (sphere)" in result.stderr and "'radius'" in result.stderr


def test_an_existing_output_is_not_clobbered_by_a_failed_render(tmp_path):
    out = tmp_path / "keep.exr"
    out.write_bytes(b"precious")
    bad = tmp_path / "bad.toml"
    bad.write_text(BAD_SCENE)
    assert cli("render", bad, "-o", out).returncode == 2
    assert out.read_bytes() == b"precious"


def test_help_and_devices():
    top = cli("--help")
    assert top.returncode == 0 and "render" in top.stdout and "devices" in top.stdout
    render_help = cli("render", "--help")
    assert render_help.returncode == 0
    for word in ("--aov", "--png", "--precision", "--device", "N.X", "Z"):
        assert word in render_help.stdout
    devices = cli("devices")
    assert devices.returncode == 0 and "*" in devices.stdout and "0:0" in devices.stdout


def test_console_script_is_installed():
    script = Path(sys.executable).parent / "pyclray"
    assert script.is_file(), "the console script pyclray is not installed beside this Python"
    result = subprocess.run([str(script), "--help"], capture_output=True, text=True)
    assert result.returncode == 0 and "render" in result.stdout
