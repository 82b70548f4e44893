"""The command line: a good render writes readable EXR channels and previews; bad input gets one
line, exit status 2, and no file left behind."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import pyclray
from pyclray.io.exr import read_exr

REPO = Path(__file__).resolve().parent.parent


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "pyclray", *map(str, args)], capture_output=True, text=True, cwd=cwd,
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
    assert len(lines) == 1 and lines[0].startswith("pyclray render: error: "), result.stderr  # argparse's too
    assert needle in lines[0]
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


# -- hardening (issue 14) ---------------------------------------------------------------------------
def one_error_line(result) -> str:
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    return lines[0]


def test_a_preview_path_that_is_a_folder_replaces_nothing(tmp_path):
    """Defect 1: OUT.depth.png is a folder: one line, exit 2, OUT.exr and OUT.normal.png keep their
    old contents (before: a traceback, OUT.normal.png replaced and OUT.exr old)."""
    (tmp_path / "o.depth.png").mkdir()
    for name in ("o.exr", "o.normal.png"):
        (tmp_path / name).write_bytes(b"old")
    result = cli("render", REPO / "scenes/tp02.toml", "-o", tmp_path / "o.exr", "--png", "--size", "16x16")
    assert result.returncode == 2
    assert "o.depth.png: it is a folder" in one_error_line(result)
    assert (tmp_path / "o.exr").read_bytes() == b"old" and (tmp_path / "o.normal.png").read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.depth.png", "o.exr", "o.normal.png"]


WRAPPER = """
import os, signal, sys
{patch}
sys.argv[0] = os.path.join(os.path.dirname(sys.executable), "pyclray")  # as the console script runs
from pyclray.apps.cli import main
sys.exit(main())
"""


def wrapped(patch, *args):
    """Run the command line as the console script does, with a fault injected by ``patch``."""
    return subprocess.run([sys.executable, "-c", WRAPPER.format(patch=patch), *map(str, args)],
                          capture_output=True, text=True, env=dict(os.environ))


def test_a_full_disk_is_one_line_exit_2_and_old_files_kept(tmp_path):
    """Defect 2: ENOSPC while writing (injected in the EXR writer after its first band)."""
    patch = (
        "import errno, pyclray.io.exr as o\n"
        "real = o.ExrWriter.write\n"
        "def full(self, band):\n"
        "    real(self, band)\n"
        "    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))\n"
        "o.ExrWriter.write = full\n"
    )
    (tmp_path / "o.exr").write_bytes(b"old")
    result = wrapped(patch, "render", REPO / "scenes/tp02.toml", "-o", tmp_path / "o.exr", "--png", "--size", "16x16")
    assert result.returncode == 2
    written = ", ".join(str(tmp_path / n) for n in ("o.exr", "o.depth.png", "o.normal.png", "o.id.png"))
    assert one_error_line(result) == f"pyclray render: error: cannot write {written}: no space left on device; nothing was replaced"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.exr"] and (tmp_path / "o.exr").read_bytes() == b"old"


@pytest.mark.parametrize("where", ["import numpy", "import pyopencl", "writing"])
def test_ctrl_c_exits_quietly_with_130_and_replaces_nothing(tmp_path, where):
    """Defect 5: Ctrl-C while the package's modules are imported, or while the outputs are being
    written (after the EXR, before the previews), exits with 130, no traceback, old files kept."""
    if where == "writing":
        patch = ("import pyclray.io.png as o\n"
                 "o.PngWriter.close = lambda self: os.kill(os.getpid(), signal.SIGINT)\n")
    else:  # SIGINT as the module starts to load
        module = where.split()[1]
        patch = (
            "import importlib.abc\n"
            "class Interrupt(importlib.abc.MetaPathFinder):\n"
            "    def find_spec(self, name, path, target=None):\n"
            f"        if name == {module!r}:\n"
            "            os.kill(os.getpid(), signal.SIGINT)\n"
            "        return None\n"
            "sys.meta_path.insert(0, Interrupt())\n"
        )
    (tmp_path / "o.exr").write_bytes(b"old")
    result = wrapped(patch, "render", REPO / "scenes/tp02.toml", "-o", tmp_path / "o.exr", "--png", "--size", "16x16")
    assert result.returncode == 130, result.stderr
    assert result.stderr == "" and result.stdout == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.exr"] and (tmp_path / "o.exr").read_bytes() == b"old"


def test_repeated_aov_and_oversized_size_are_option_errors(tmp_path):
    """Defect 5: --aov depth,depth (was exit 1 with a Python tuple) and --size 100000x100000 (was
    blamed on the TOML key 'width') name the option and exit 2."""
    result = cli("render", REPO / "scenes/tp02.toml", "-o", tmp_path / "o.exr", "--aov", "depth,depth")
    assert result.returncode == 2
    last = result.stderr.strip().splitlines()[-1]
    assert "--aov" in last and "depth more than once" in last and "(" + "'depth'" not in last
    result = cli("render", REPO / "scenes/tp02.toml", "-o", tmp_path / "o.exr", "--size", "100000x100000")
    assert result.returncode == 2
    last = result.stderr.strip().splitlines()[-1]
    assert "--size" in last and "65536" in last and "width" not in last
    assert list(tmp_path.iterdir()) == []


def test_a_scene_file_with_a_byte_order_mark_and_no_shapes(tmp_path):
    """Defect 5: a UTF-8 BOM is not an 'Invalid statement'; a scene with no shapes renders with one
    warning line (every pixel is a miss)."""
    scene = tmp_path / "bom.toml"
    scene.write_bytes(b"\xef\xbb\xbf" + b'[camera]\neye = [0.0, 0.0, 0.0]\ntarget = [0.0, 0.0, -1.0]\nfov = 40.0\n')
    result = cli("render", scene, "-o", tmp_path / "o.exr", "--size", "8x8")
    assert result.returncode == 0, result.stderr
    assert one_error_line(result) == f"pyclray render: warning: {scene}: no [[shapes]]: every pixel is a miss"
    assert (read_exr(tmp_path / "o.exr")["id"] == -1).all()


def test_the_final_line_reports_the_phases(tmp_path):
    """Progress and timing: the last line says how long rendering and writing took (writing was
    left out before); no progress bar when stderr is not a terminal."""
    result = cli("render", REPO / "scenes/tp02.toml", "-o", tmp_path / "o.exr", "--png", "--size", "32x32")
    assert result.returncode == 0 and result.stderr == ""
    last = result.stdout.strip().splitlines()[-1]
    assert " (render " in last and ", write " in last and "wrote" in last


def test_version_and_python_dash_m():
    """Defect 7: pyclray --version and python -m pyclray."""
    from importlib.metadata import version

    result = subprocess.run([sys.executable, "-m", "pyclray", "--version"], capture_output=True, text=True)
    assert result.returncode == 0 and result.stdout.strip() == f"pyclray {version('pyclray')}"
    assert version("pyclray") == pyclray.__version__
    result = subprocess.run([sys.executable, "-m", "pyclray", "render", "--help"], capture_output=True, text=True)
    assert result.returncode == 0
    text = " ".join(result.stdout.split())
    assert "32-bit FLOAT channels also for --precision fp64" in text and "no 64-bit float channel" in text
    assert "Exit status" in text


def test_the_readme_command_block_lists_every_command():
    """Defect 7: the command-line reference's block (docs/cli.md, linked from the README) names
    every subcommand the parser has."""
    from pyclray.apps.cli import build_parser

    readme = (REPO / "docs" / "cli.md").read_text()
    block = readme.split("# Command line", 1)[1].split("```", 2)[1]
    listed = {line.split()[1] for line in block.strip().splitlines() if line.startswith("pyclray ")}
    commands = next(a for a in build_parser()._actions if isinstance(a, __import__("argparse")._SubParsersAction))
    assert listed == set(commands.choices) | {"--version"}, listed


def test_a_render_in_many_bands_is_the_whole_render(tmp_path, monkeypatch, capsys):
    """Defect 4: pyclray render renders and writes bands of rows (bounded memory); cut into bands
    of 16 rows here (4 Mpx in real use), the EXR holds exactly the whole image's pixels and the
    previews are those of the whole image."""
    from pyclray.apps import cli
    from pyclray.io import png

    from test_output import read_png

    from pyclray.io import bands

    monkeypatch.setattr(bands, "band_rows", lambda width: 16)
    out = tmp_path / "b.exr"
    assert cli.main(["render", str(REPO / "scenes/tp02.toml"), "-o", str(out), "--png", "--size", "40x70"]) == 0
    whole = pyclray.render(pyclray.load_scene(REPO / "scenes/tp02.toml").with_size(40, 70))
    images = read_exr(out)
    for name in ("depth", "normal", "id"):
        assert np.array_equal(images[name], whole[name]), name
    assert np.array_equal(read_png(tmp_path / "b.depth.png"), png.preview("depth", whole["depth"]))
    assert np.array_equal(read_png(tmp_path / "b.normal.png"), png.preview("normal", whole["normal"]))
    assert "wrote" in capsys.readouterr().out


def test_a_progress_bar_on_a_terminal_only(tmp_path):
    """Progress: on a terminal (stderr a pty) a tqdm bar counts the rows (shown from the start
    here: the delay of 1 s is set to 0); the stdout's last line is the same as without one."""
    patch = "import pyclray.io.progress as p\np.DELAY = 0\nimport pyclray.io.bands as o\no.band_rows = lambda width: 16\n"
    import fcntl
    import struct
    import termios

    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal 100 columns wide
    process = subprocess.Popen([sys.executable, "-c", WRAPPER.format(patch=patch), "render", str(REPO / "scenes/tp02.toml"),
                                "-o", str(tmp_path / "o.exr"), "--size", "64x64"],
                               stdout=subprocess.PIPE, stderr=slave, env=dict(os.environ))
    os.close(slave)
    drawn = b""
    while True:
        try:
            data = os.read(master, 4096)
        except OSError:  # EIO: the other end is closed
            break
        if not data:
            break
        drawn += data
    os.close(master)
    stdout = process.stdout.read().decode()
    assert process.wait() == 0
    assert b"pyclray render" in drawn and b"/64 [" in drawn and b"row" in drawn, drawn
    assert stdout.strip().splitlines()[-1].startswith("rendered ")


def test_render_without_o_writes_the_scene_stem_exr_in_the_current_folder(tmp_path):
    """Issue 42 item 11: `pyclray render scenes/tp02.toml` writes ./tp02.exr (not an error)."""
    scene = Path(__file__).resolve().parents[1] / "scenes" / "tp02.toml"
    result = cli("render", str(scene), "--size", "16x12", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tp02.exr"]
    assert read_exr(tmp_path / "tp02.exr")["depth"].shape == (12, 16)
    assert "tp02.exr" in result.stdout
    help_text = cli("render", "--help").stdout
    assert "default: SCENE's name" in " ".join(help_text.split())
