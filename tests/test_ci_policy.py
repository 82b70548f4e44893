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



def test_ci_installs_chromium_only_when_it_is_missing(tmp_path):
    """The test command's first line (README, .ci/run; tests/test_docs.py holds them equal): with
    chromium on the PATH nothing runs; without it apt-get installs it, through sudo where there is
    one. The PATH holds only sh and stand-ins for sudo, apt-get and chromium that log their arguments."""
    from test_docs import CHROMIUM

    bin_, log = tmp_path / "bin", tmp_path / "log"
    bin_.mkdir()
    (bin_ / "sh").symlink_to("/bin/sh")

    def stub(name, body):
        (bin_ / name).write_text(f"#!/bin/sh\n{body}\n")
        (bin_ / name).chmod(0o755)

    def run():
        log.write_text("")
        subprocess.run(["/bin/bash", "-c", CHROMIUM], env={"PATH": str(bin_)}, check=True)
        return log.read_text().splitlines()

    stub("apt-get", f'echo "apt-get $*" >> {log}')
    assert run() == ["apt-get update -q", "apt-get install -y -q chromium"]  # root without sudo
    stub("sudo", f'echo "sudo $*" >> {log}; exec "$@"')
    assert run() == ["sudo sh -c apt-get update -q && apt-get install -y -q chromium",
                     "apt-get update -q", "apt-get install -y -q chromium"]
    stub("chromium", "")
    assert run() == []
