"""Issue 42 item 14: the reference says what the code does. Every public name of pyclray is in
docs/python.md; every AOV of the one table (model/aovs.py) is in `render --help`, `animate --help`,
docs/python.md, docs/cli.md and its EXR channels in docs/images.md's table; every page a doc cites
by name exists; every command's help ends with the same exit statuses; `view --help` says it reads
Mitsuba XML too; the [camera] table's fov defaults to 45 as pyclray.Camera's does."""
import re

import pytest

import pyclray
from pyclray.model.aovs import TABLE

from conftest import REPO

DOCS = sorted((REPO / "docs").glob("*.md"))
COMMANDS = ["render", "animate", "devices", "check", "stability", "view", "export", "scan"]


def helps(command) -> str:
    """`pyclray [COMMAND] --help` as one line (argparse's own text, formatted in this process: a
    subprocess per page would cost a second each)."""
    from pyclray.apps.cli import _subparser, build_parser

    parser = build_parser()
    return " ".join((_subparser(parser, command) if command else parser).format_help().split())


def test_every_public_name_is_in_the_python_page():
    text = (REPO / "docs" / "python.md").read_text()
    missing = [name for name in pyclray.__all__ if not re.search(rf"pyclray\.{re.escape(name)}\b", text)]
    assert not missing, missing


def test_mesh_is_documented_with_its_calls():
    text = (REPO / "docs" / "python.md").read_text()
    for call in ("pyclray.Mesh(vertices, faces", "pyclray.Mesh.load(path", "mesh.placed("):
        assert call in text, call


@pytest.mark.parametrize("command", ["render", "animate"])
def test_every_aov_is_in_the_help(command):
    text = helps(command)
    for name in TABLE:
        assert re.search(rf"\b{name}\b", text), (command, name)


@pytest.mark.parametrize("page", ["python.md", "cli.md", "images.md"])
def test_every_aov_is_in_the_docs(page):
    text = (REPO / "docs" / page).read_text()
    for name in TABLE:
        assert re.search(rf"\b{name}\b", text), (page, name)


def test_every_exr_channel_is_in_the_images_table():
    rows = [line for line in (REPO / "docs" / "images.md").read_text().splitlines() if line.startswith("|")]
    for aov in TABLE.values():
        for channel in aov.exr:
            assert any(f"`{channel}`" in row for row in rows), channel


@pytest.mark.parametrize("page", [p.name for p in DOCS] + ["README.md"])
def test_every_page_a_doc_names_exists(page):
    path = REPO / "docs" / page if page != "README.md" else REPO / page
    for name in set(re.findall(r"\b([\w./-]+\.md)\b", path.read_text())):
        if name.startswith(("http", "../shared")):
            continue
        assert (path.parent / name).exists() or (REPO / name).exists() or (REPO / "docs" / name).exists(), (page, name)


@pytest.mark.parametrize("command", [None] + COMMANDS)
def test_every_help_page_ends_with_the_exit_statuses(command):
    from pyclray.apps.cli.texts import EXIT_STATUS_HELP

    assert helps(command).endswith(" ".join(EXIT_STATUS_HELP.split())), command


def test_view_reads_toml_or_mitsuba_xml():
    text = helps("view")
    assert "TOML or Mitsuba 3 XML" in text or "TOML, or Mitsuba 3 XML" in text


def test_the_camera_table_fov_defaults_to_45_like_pyclray_camera(tmp_path):
    path = tmp_path / "nofov.toml"
    path.write_text("[camera]\neye = [0.0, 1.0, 5.0]\ntarget = [0.0, 0.0, 0.0]\n[image]\nwidth = 8\nheight = 8\n"
                    "[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\n")
    scene = pyclray.load_scene(path)
    assert scene.camera == pyclray.Camera((0.0, 1.0, 5.0), (0.0, 0.0, 0.0))
    assert scene.camera.intrinsics(8, 8)[0, 0] == pytest.approx(4 / __import__("math").tan(__import__("math").radians(22.5)))
    scenes = (REPO / "docs" / "scenes.md").read_text()
    assert re.search(r"fov[^\n]*default 45", scenes)
