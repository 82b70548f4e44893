"""Issue 27, a user's first hour: every bad option of every command is one line and exit status 2,
at once (before the scene is read, Dask imported or anything connects); the help names every shape;
read_exr's errors; a render too large for memory; unique shape names, --time and scene.at; the
output's format by extension. Labels, .npz files, the benchmarks and the README have files of their
own (test_labels.py, test_npz.py, test_bench_policy.py, test_docs.py)."""
import argparse
import os
import subprocess
import sys
import time

import pytest

from conftest import REPO

TP02 = REPO / "scenes" / "tp02.toml"


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "pyclray", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=dict(os.environ))


def the_one_line(result, command) -> str:
    """The single stderr line of a bad-input exit: `pyclray <command>: error: ...`, no usage, no traceback."""
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"pyclray{' ' + command if command else ''}: error: "), lines[0]
    assert "usage:" not in result.stderr and "Traceback" not in result.stderr
    return lines[0]


# -- item 3: argparse's errors are one line too -------------------------------------------------
@pytest.mark.parametrize("command,args,needle", [
    ("render", ["render"], "required: SCENE"),  # -o is optional: SCENE's name .exr here (issue 42)
    ("render", ["render", TP02, "-o"], "-o/--output: expected one argument"),
    ("render", ["render", TP02, "-o", "x.exr", "--bogus"], "unrecognized arguments: --bogus"),
    ("render", ["render", TP02, "-o", "x.exr", "--precision", "fp16"], "--precision"),
    ("render", ["render", TP02, "-o", "x.exr", "--size", "12"], "--size"),
    ("animate", ["animate", TP02, "-o", "x.gif", "--workers", "0"], "--workers"),
    ("animate", ["animate", TP02, "-o", "x.gif", "--workers", "2", "--scheduler", "tcp://h:1"], "not allowed"),
    ("check", ["check", TP02, "--variant", "cuda"], "--variant"),
    ("stability", ["stability", "--case", "no-such-case"], "--case"),
    ("devices", ["devices", "--bogus"], "unrecognized arguments"),
    ("", ["bogus"], "invalid choice: 'bogus'"),
    ("", [], "required: COMMAND"),
])
def test_a_bad_option_is_one_line_naming_the_command(tmp_path, command, args, needle):
    line = the_one_line(cli(*args, cwd=tmp_path), command)
    assert needle in line
    assert list(tmp_path.iterdir()) == []


# -- item 2: fail fast ----------------------------------------------------------------------------
def test_a_malformed_scheduler_address_fails_before_dask_and_the_scene(tmp_path):
    """--scheduler banana: one line at once; the scene (here a missing file) is never read and Dask
    never imported (it took 20.7 s and a traceback)."""
    code = ("import sys\nfrom pyclray.apps.cli import main\n"
            "try:\n    main(sys.argv[1:])\nexcept SystemExit as exit:\n"
            "    print(exit.code, 'distributed' in sys.modules)\n")
    start = time.perf_counter()
    result = subprocess.run([sys.executable, "-c", code, "animate", tmp_path / "missing.toml", "-o", tmp_path / "x.gif",
                             "--scheduler", "banana"], capture_output=True, text=True)
    assert time.perf_counter() - start < 10
    assert result.stdout.split() == ["2", "False"]
    line = result.stderr.strip()
    assert line.startswith("pyclray animate: error: argument --scheduler: expected a Dask scheduler's address") and "'banana'" in line
    assert "\n" not in line and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("address,good", [
    ("tcp://10.0.0.5:8786", True), ("tls://scheduler.example.org:8786", True), ("ws://h:1", True),
    ("tcp://[::1]:8786", True), ("127.0.0.1:8786", True), ("inproc://10.0.0.5/1234/1", True),
    ("banana", False), ("tcp://host", False), ("tcp://host:0", False), ("tcp://host:70000", False),
    ("http://host:8786", False), ("tcp://:8786", False), ("tcp://host:87x6", False), ("", False),
])
def test_scheduler_addresses(address, good):
    from pyclray.apps.cli.options import scheduler_address

    if good:
        assert scheduler_address(address) == address
    else:
        with pytest.raises(argparse.ArgumentTypeError, match="PROTOCOL://HOST:PORT"):
            scheduler_address(address)


def test_a_scheduler_that_cannot_be_reached_is_one_line_without_waiting(tmp_path):
    """A well-formed address Dask still refuses at once (TLS without its configuration): one line,
    exit 2, and no 20 s wait for the failed Client's clean-up with a traceback at exit."""
    start = time.perf_counter()
    result = cli("animate", REPO / "scenes" / "tp02_orbit.toml", "-o", tmp_path / "x.gif", "--size", "8x8",
                 "--scheduler", "tls://127.0.0.1:9")
    assert time.perf_counter() - start < 10
    line = the_one_line(result, "animate")
    assert "--scheduler tls://127.0.0.1:9: cannot connect to a Dask scheduler there" in line
    assert list(tmp_path.iterdir()) == []


def test_animate_checks_its_options_before_reading_the_scene(tmp_path):
    """--aov and --frames of the wrong form are named even when the scene file is missing."""
    missing = tmp_path / "missing.toml"
    line = the_one_line(cli("animate", missing, "-o", tmp_path / "x.gif", "--aov", "depth,normal"), "animate")
    assert "--aov: a gif shows one image" in line
    line = the_one_line(cli("animate", missing, "-o", tmp_path / "frames/", "--frames", "a:b"), "animate")
    assert "--frames: expected A:B" in line
    assert list(tmp_path.iterdir()) == []


# -- item 4: the help names every shape type ------------------------------------------------------
def test_the_help_names_every_shape_type():
    from pyclray.model.shapes import REGISTRY

    result = cli("--help")
    text = " ".join(result.stdout.split())
    assert result.returncode == 0
    for kind in REGISTRY:
        assert f"{kind}s" in text or f"{kind}es" in text or f"batches of {kind}" in text, kind


# -- item 6: read_exr on a bad file ---------------------------------------------------------------
def test_read_exr_of_a_bad_file_is_one_output_error_and_prints_nothing(tmp_path, capfd):
    """A missing file, a folder, a file of another kind and a damaged EXR: pyclray.OutputError (an
    OSError) of one line naming the file; OpenEXR's own messages (its C library writes them to the
    process's stdout and stderr) do not reach the terminal."""
    import pyclray

    good = tmp_path / "good.exr"
    pyclray.write_exr(good, pyclray.render(pyclray.load_scene(TP02).with_size(32, 32)))
    (tmp_path / "text.exr").write_text("not an image\n")
    (tmp_path / "cut.exr").write_bytes(good.read_bytes()[:600])  # the header, and a chunk cut short
    capfd.readouterr()
    cases = {"missing.exr": "no such file or directory", ".": "is a directory", "text.exr": "not an OpenEXR file",
             "cut.exr": "a damaged OpenEXR file"}
    for name, reason in cases.items():
        with pytest.raises(pyclray.OutputError) as error:
            pyclray.read_exr(tmp_path / name)
        message = str(error.value)
        assert message.startswith(f"cannot read {tmp_path / name}: {reason}") and "\n" not in message, message
        assert isinstance(error.value, OSError)
    assert capfd.readouterr() == ("", "")
    assert sorted(pyclray.read_exr(good)) == ["depth", "id", "normal"]  # and a good one still reads


# -- item 8: names, --time, scene.at ---------------------------------------------------------------
TWO_BALLS = """
[camera]
eye = [0.0, 2.0, 6.0]
target = [0.0, 0.5, 0.0]
fov = 45.0

[[shapes]]
type = "sphere"
name = "ball"
center = [0.0, 1.0, 0.0]
radius = 1.0

[[shapes]]
type = "box"
name = "ball"
center = [2.0, 0.5, 0.0]
size = [1.0, 1.0, 1.0]
"""


def test_two_shapes_of_one_name_are_a_scene_error_naming_file_table_and_key(tmp_path):
    import pyclray

    path = tmp_path / "twice.toml"
    path.write_text(TWO_BALLS)
    with pytest.raises(pyclray.SceneError) as caught:
        pyclray.load_scene(path)
    assert str(caught.value) == (f"{path}: table [[shapes]] #1 (box): key 'name': the name 'ball' is already used "
                                 "by [[shapes]] #0")
    line = the_one_line(cli("render", path, "-o", tmp_path / "x.exr"), "render")
    assert line.endswith("the name 'ball' is already used by [[shapes]] #0")
    path.write_text(TWO_BALLS.replace('name = "ball"\ncenter = [2.0', 'center = [2.0'))  # the default name: box1
    assert [s.name for s in pyclray.load_scene(path).shapes] == ["ball", "box1"]


def test_time_on_a_scene_without_animation_is_an_option_error_and_writes_nothing(tmp_path):
    line = the_one_line(cli("render", TP02, "-o", tmp_path / "x.exr", "--time", "1.5", "--size", "8x8"), "render")
    assert line == f"pyclray render: error: --time: {TP02} has no [animation] table; --time renders a time of an animated scene"
    assert list(tmp_path.iterdir()) == []
    result = cli("render", REPO / "scenes" / "tp02_orbit.toml", "-o", tmp_path / "x.exr", "--time", "1.5", "--size", "8x8")
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("t", [-1, -1e-9, float("nan"), float("inf"), "1.0", True, None])
def test_scene_at_a_negative_or_non_time_is_a_request_error(t):
    import pyclray

    for path in (TP02, REPO / "scenes" / "tp02_orbit.toml"):  # static or animated alike
        with pytest.raises(pyclray.RequestError, match=r"^t: expected a time in seconds >= 0 .* got "):
            pyclray.load_scene(path).at(t)


def test_scene_at_any_time_from_zero_on_holds_the_last_keys_past_the_end():
    import pyclray

    scene = pyclray.load_scene(REPO / "scenes" / "tp02_orbit.toml")
    end = scene.animation.duration
    assert scene.at(0) == scene.at(0.0) and scene.at(end + 100.0) == scene.at(end * 10)


# -- item 7: a render too large for memory ---------------------------------------------------------
def test_a_render_too_large_for_memory_is_a_request_error_naming_the_bytes():
    """60000x60000, every AOV: 172.8 GB of arrays. A RequestError saying so and how to render it in
    parts, before anything is allocated (it was a MemoryError)."""
    import pyclray

    scene = pyclray.load_scene(TP02).with_size(60000, 60000)
    every = ("depth", "normal", "id", "zdepth", "position", "shaded")
    with pytest.raises(pyclray.RequestError) as caught:
        pyclray.render(scene, aovs=every)
    message = str(caught.value)
    assert "need 172,800,000,000 bytes (173 GB)" in message and "60000x60000" in message
    assert "window=(x0, y0, width, height)" in message and "pyclray render" in message and "\n" not in message
    # a window of it is a render of that many pixels, and fits
    assert pyclray.render(scene, aovs=every, window=(0, 30000, 64, 2))["id"].shape == (2, 64)


def test_the_memory_check_uses_what_is_available(monkeypatch):
    import pyclray
    from pyclray.engine.queries import memory
    from pyclray.model.aovs import image_bytes

    scene = pyclray.load_scene(TP02).with_size(64, 32)
    need = image_bytes(("depth", "normal", "id"), 64 * 32)
    assert need == 64 * 32 * (4 + 12 + 4)
    monkeypatch.setattr(memory, "ALWAYS_FITS", 0)  # (images below 64 MiB are not checked)
    monkeypatch.setattr(memory, "available_bytes", lambda: need - 1)
    with pytest.raises(pyclray.RequestError, match=f"need {need:,} bytes"):
        pyclray.render(scene)
    assert pyclray.render(scene, aovs=("depth",))["depth"].shape == (32, 64)  # a third of it fits
    monkeypatch.setattr(memory, "available_bytes", lambda: None)  # unknown: no check
    assert pyclray.render(scene)["depth"].shape == (32, 64)


def test_available_memory_is_read_on_linux():
    from pyclray.engine.queries.memory import available_bytes

    if sys.platform.startswith("linux"):
        assert available_bytes() > 0


# -- items 1 and 10: the output's format follows its extension ---------------------------------------
def test_o_png_writes_the_preview_of_the_first_aov_asked(tmp_path):
    """-o out.png was an OpenEXR file named out.png: it is now a PNG, the preview of the first AOV
    asked (depth by default), and only that AOV is rendered."""
    import numpy as np

    import pyclray
    from pyclray.io import png
    from test_output import read_png

    result = cli("render", TP02, "-o", tmp_path / "out.png", "--size", "40x30")
    assert result.returncode == 0, result.stderr
    whole = pyclray.render(pyclray.load_scene(TP02).with_size(40, 30), aovs=("depth", "shaded"))
    assert np.array_equal(read_png(tmp_path / "out.png"), png.preview("depth", whole["depth"]))
    result = cli("render", TP02, "-o", tmp_path / "lit.PNG", "--size", "40x30", "--aov", "shaded,depth")
    assert result.returncode == 0 and result.stdout.strip().endswith("[the shaded preview]"), result.stdout
    assert np.array_equal(read_png(tmp_path / "lit.PNG"), png.srgb_preview(whole["shaded"]))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lit.PNG", "out.png"]


def test_o_exr_still_writes_exr_and_previews(tmp_path):
    import pyclray

    result = cli("render", TP02, "-o", tmp_path / "o.exr", "--png", "--size", "16x16")
    assert result.returncode == 0, result.stderr
    assert sorted(pyclray.read_exr(tmp_path / "o.exr")) == ["depth", "id", "normal"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.depth.png", "o.exr", "o.id.png", "o.normal.png"]


@pytest.mark.parametrize("output,extra,needle", [
    ("out.tiff", [], "-o {out}: expected OUT.exr (OpenEXR channels), OUT.npz (numpy arrays, with the camera's K and "
                     "pose), OUT.png (the preview of one image) or OUT.ply (the hit pixels as a point cloud); the format "
                     "follows the extension"),
    ("out", [], "expected OUT.exr"),
    ("out.exr.bak", [], "expected OUT.exr"),
    ("out.png", ["--png"], "--png: -o {out} is itself a preview"),
    ("out.png", ["--aov", "position,depth"], "position has none"),
])
def test_another_extension_is_one_line_before_anything_is_read(tmp_path, output, extra, needle):
    """Checked before the scene is read (a missing scene file is not what is reported)."""
    out = tmp_path / output
    line = the_one_line(cli("render", tmp_path / "missing.toml", "-o", out, *extra), "render")
    assert needle.format(out=out) in line
    assert list(tmp_path.iterdir()) == []


def test_the_scene_file_is_never_an_output(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_bytes(TP02.read_bytes())
    os.link(scene, tmp_path / "linked.png")  # the same file under another name
    (tmp_path / "o.depth.png").symlink_to(scene)
    for output, extra in ((scene, []), (tmp_path / "." / "scene.toml", []), (tmp_path / "linked.png", []),
                          (tmp_path / "o.exr", ["--png"])):
        line = the_one_line(cli("render", scene, "-o", output, *extra), "render")
        assert "is the scene file itself; give another output path" in line
    assert scene.read_bytes() == TP02.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["linked.png", "o.depth.png", "scene.toml"]
