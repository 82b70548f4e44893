"""Issue 42 item 8: a cold build of a kernel (PoCL's and pyclray's caches empty) prints nothing on
stderr: clang's "N warnings generated." is not the user's business (a failed build still raises a
BuildError with its log). fp32 and fp64, render (shaded, with shadows) and cast / occluded."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPT = """
import pyclray
scene = pyclray.load_scene({scene!r}).with_size(8, 8)
pyclray.render(scene, precision={precision!r}, aovs=("depth", "shaded"))
pyclray.cast(scene, [[0.0, 1.0, 5.0]], [[0.0, 0.0, -1.0]], precision={precision!r})
pyclray.occluded(scene, [[0.0, 1.0, 5.0]], [[0.0, 0.0, -1.0]], precision={precision!r})
print("done")
"""


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_a_cold_build_prints_nothing(tmp_path, precision):
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"), POCL_CACHE_DIR=str(tmp_path / "pocl"),
               PYTHONPATH=str(REPO))
    env.pop("PYCLRAY_CACHE_DIR", None)
    script = SCRIPT.format(scene=str(REPO / "scenes/mesh.toml"), precision=precision)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert run.returncode == 0 and run.stdout.strip() == "done", run.stderr
    assert run.stderr == "", run.stderr
    assert any((tmp_path / "pocl").iterdir())  # it was a cold build into these caches


def test_a_failed_build_still_raises_with_its_log(tmp_path, monkeypatch):
    """The compiler's log stays in the BuildError (the quiet stderr hides the count line only)."""
    import pyclray
    from pyclray.engine.launch import programs
    from pyclray.engine.opencl.device import context_for

    monkeypatch.setenv("PYCLRAY_CACHE_DIR", "off")
    monkeypatch.setattr(programs.Variant, "source",
                        lambda self, inline_builtins=False: "__kernel void render(__global float *x) { x[0] = y; }\n")
    with pytest.raises(pyclray.BuildError) as error:
        programs._build(context_for(), programs.Variant("render", (), ("depth",), "fp32"))
    assert "'y'" in str(error.value) or "undeclared" in str(error.value), str(error.value)
