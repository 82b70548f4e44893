"""The README teaches (issue 27, item 12): its Python examples run as written, its two commands stay
exactly as .ci/run uses them, and every page and picture it links to exists (the reference lives in
docs/)."""
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from conftest import REPO

README = REPO / "README.md"
INSTALL = ('python3 -m venv .venv && .venv/bin/pip install -e ".[test]" && '
           '.venv/bin/pyclray render scenes/tp02.toml -o tp02.exr --png')
# Debian's chromium (the view's page tests drive it), installed when missing, then the tests
CHROMIUM = "command -v chromium >/dev/null || $(command -v sudo) sh -c 'apt-get update -q && apt-get install -y -q chromium'"
TESTS = f'({CHROMIUM}) && python3 -m venv .venv && .venv/bin/pip install -q -e ".[test]" && .venv/bin/python -m pytest'


def code_blocks(text: str, language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", text, flags=re.S)


def test_the_readme_keeps_its_two_commands_and_ci_runs_the_test_command():
    blocks = [block.strip() for block in code_blocks(README.read_text(), "sh")]
    assert INSTALL in blocks and TESTS in blocks
    ci = (REPO / ".ci" / "run").read_text().strip().splitlines()
    assert ci[-1] == TESTS


def test_the_readme_is_a_page_that_reads_in_minutes():
    lines = README.read_text().splitlines()
    assert len(lines) < 230  # (the sensors issue asks for a distorted camera with its picture and a migration note)
    for heading in ("## Install and render", "## Two commands", "## From Python", "## A data set of views",
                    "## Triangle meshes"):
        assert heading in lines, heading


@pytest.mark.parametrize("page", ["README.md", *sorted(p.relative_to(REPO).as_posix() for p in (REPO / "docs").glob("*.md"))])
def test_every_link_and_picture_of_the_docs_exists(page):
    path = REPO / page
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", path.read_text()):
        if re.match(r"[a-z]+://", target):
            continue
        assert (path.parent / target).exists(), f"{page}: {target}"


def test_the_readme_python_examples_run_as_written(tmp_path):
    """In a folder of their own (scenes/ linked in): the ten-line example, the data set of views and
    the meshes (one file placed three times)."""
    (tmp_path / "scenes").symlink_to(REPO / "scenes")
    blocks = code_blocks(README.read_text(), "python")
    assert len(blocks) == 3
    outputs = []
    for number, block in enumerate(blocks):
        (tmp_path / f"example{number}.py").write_text(block)
        result = subprocess.run([sys.executable, f"example{number}.py"], cwd=tmp_path, capture_output=True,
                                text=True, env=dict(os.environ))
        assert result.returncode == 0, block + result.stderr
        outputs.append(result.stdout)
    # the middle bunny (id 1) at the image's centre: a triangle index and its (u, v)
    assert re.fullmatch(r"1 \d+ \[ *[-0-9.e]+ +[-0-9.e]+ *\]", outputs[2].strip()), outputs[2]
    assert (tmp_path / "tp02.exr").is_file()
    views = sorted((tmp_path / "views").iterdir())
    assert len(views) == 24
    with np.load(views[5]) as view:
        assert view.files == ["depth", "id", "label", "K", "pose"]
        assert view["label"].dtype == np.int32 and {1, 2, 3} <= set(np.unique(view["label"]).tolist())
