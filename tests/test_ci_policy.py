"""The CI policy itself: in CI a skip for a missing dependency fails; a device-feature skip does not."""
import subprocess
import sys
import textwrap

from conftest import REPO


def _run(tmp_path, body, ci):
    (tmp_path / "test_x.py").write_text(textwrap.dedent(body))
    (tmp_path / "conftest.py").write_text((REPO / "tests" / "conftest.py").read_text())
    env = {"PATH": "/usr/bin:/bin", "CI": "true" if ci else ""}
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(tmp_path)],
                          capture_output=True, text=True, env=env, cwd=tmp_path)


def test_missing_dependency_skip_fails_in_ci(tmp_path):
    body = """
        import pytest
        def test_it():
            pytest.importorskip("no_such_module_pyclray")
    """
    assert _run(tmp_path, body, ci=True).returncode == 1
    assert _run(tmp_path, body, ci=False).returncode == 0


def test_device_feature_skip_is_allowed_in_ci(tmp_path):
    body = """
        import pytest
        def test_it():
            pytest.skip("device lacks cl_khr_fp64")
    """
    result = _run(tmp_path, body, ci=True)
    assert result.returncode == 0, result.stdout
