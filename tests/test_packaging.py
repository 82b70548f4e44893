"""A non-editable install works: the wheel carries the kernels, and pyclray renders from it when
run outside the repository (so nothing is found by accident in the working tree)."""
import os
import subprocess
import sys
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def test_wheel_ships_the_kernels_and_renders_from_outside_the_repo(tmp_path):
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"), str(REPO)],
                   check=True, capture_output=True, cwd=tmp_path)
    wheel = next((tmp_path / "dist").glob("pyclray-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    for kernel in sorted(p.name for p in (REPO / "pyclray" / "engine" / "kernels").iterdir() if p.suffix in (".cl", ".h")):
        assert f"pyclray/engine/kernels/{kernel}" in names
    assert "pyclray/model/shapes/sphere.py" in names
    for page in ("index.html", "view.js", "controls.js", "view.css"):  # pyclray view's page (package data)
        assert f"pyclray/apps/view/page/{page}" in names
    assert not any(n.startswith(("tests/", "bench/", "scenes/")) for n in names)
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    code = (
        "import pyclray, sys, numpy as np;"
        "assert pyclray.__file__.startswith(sys.argv[1]), pyclray.__file__;"
        f"s = pyclray.load_scene({str(REPO / 'scenes/tp02.toml')!r}).with_size(8, 8);"
        "f = pyclray.render(s); assert (f['id'] >= 0).any(); print('ok')"
    )
    env = dict(os.environ, PYTHONPATH=str(site))
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    result = subprocess.run([sys.executable, "-c", code, str(site)], env=env, cwd=outside, capture_output=True, text=True)
    assert result.returncode == 0 and "ok" in result.stdout, result.stderr


def test_rendering_does_not_import_mitsuba():
    code = (
        "import sys, pyclray;"
        f"pyclray.render(pyclray.load_scene({str(REPO / 'scenes/tp02.toml')!r}).with_size(8, 8));"
        "from pyclray.apps import cli; cli.build_parser();"
        "print('mitsuba' in sys.modules, 'drjit' in sys.modules)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.split() == ["False", "False"]
