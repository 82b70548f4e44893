"""Shared fixtures. With CI set (CI=true), a test that skips fails instead, unless it skips for a
device feature the machine truly lacks (a reason starting with "device lacks")."""
import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SCENES = REPO / "scenes"
ALLOWED_SKIP_PREFIX = "device lacks"


def _in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if report.skipped and _in_ci() and not getattr(item, "_pyclray_allowed_skip", False):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        if not reason.removeprefix("Skipped: ").startswith(ALLOWED_SKIP_PREFIX):
            report.outcome = "failed"
            report.longrepr = f"skipped in CI, which must not skip: {reason}"


@pytest.fixture(autouse=True, scope="session")
def _private_program_cache(tmp_path_factory):
    """Keep the tests' on-disk program cache apart from the user's."""
    if "PYCLRAY_CACHE_DIR" not in os.environ:
        os.environ["PYCLRAY_CACHE_DIR"] = str(tmp_path_factory.mktemp("program-cache"))
    yield


@pytest.fixture(scope="session")
def scenes_dir() -> Path:
    return SCENES
