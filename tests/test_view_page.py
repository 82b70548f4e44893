"""`pyclray view`'s page in a real browser (issue 24, item 6; scene-format.md, "Interactive view"):
Debian's chromium driven by Playwright. The settled images are the previews `pyclray render` makes
of the same view, pixel for pixel (PNG, lossless); moving, reloading, the error banner, the time
slider and Ctrl-C are checked as a user would see them."""
import os
import subprocess
import sys
import time
import tomllib

import numpy as np
import pytest

import pyclray
from conftest import REPO
from pyclray.io.png import preview
from viewing import Viewer, drag, launch_browser, open_page, painted, settle

playwright = pytest.importorskip("playwright.sync_api", reason="the view's page tests need playwright (the test extra)")

SIZE = (96, 64)  # not square: a mix-up of width and height shows
TP02 = (REPO / "scenes/tp02.toml").read_text()


@pytest.fixture(scope="module")
def browser():
    with playwright.sync_playwright() as driver:
        browser = launch_browser(driver)
        yield browser
        browser.close()


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("view") / "scene.toml"
    path.write_text(TP02)
    return path


@pytest.fixture(scope="module")
def viewer(scene_file):
    viewer = Viewer(scene_file, "--size", f"{SIZE[0]}x{SIZE[1]}")
    yield viewer
    viewer.close()


@pytest.fixture(scope="module")
def page(browser, viewer):
    page = open_page(browser, viewer)
    yield page
    page.context.close()


def shown(page) -> np.ndarray:
    """The canvas's pixels, (height, width, 3) uint8."""
    import base64
    import io

    from PIL import Image

    url = page.evaluate("document.getElementById('view').toDataURL('image/png')")
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB"))


def expected(path, aov="shaded", t=None, text=None) -> np.ndarray:
    """The preview `pyclray render --png` writes of this view of the scene file."""
    scene = pyclray.load_scene(path).with_size(*SIZE)
    scene = scene if t is None else scene.at(t)
    return preview(aov, pyclray.render(scene, aovs=(aov,))[aov])


def camera_shown(page) -> str:
    """The eye and target the page shows."""
    return page.locator("#info").text_content().split(" · ", 1)[1]


def test_first_paint_is_the_render_of_the_scene(page, scene_file):
    assert painted(page) >= 1
    assert np.array_equal(shown(page), expected(scene_file))
    assert page.locator("#aov").input_value() == "shaded"
    assert page.locator("#time").count() == 0 and page.locator("#clock").is_hidden()  # a static scene has no clock


def test_orbit_and_pan_change_the_image_and_r_restores_it(page, scene_file):
    first = shown(page)
    for button in ("left", "right"):
        n = painted(page)
        drag(page, 40, 15, button=button)
        n = settle(page, n)
        assert not np.array_equal(shown(page), first), button
    assert "eye [0.000, 2.000, 6.000]" not in page.locator("#info").text_content()
    page.keyboard.press("r")
    settle(page, n)
    assert np.array_equal(shown(page), first)
    page.keyboard.press("h")  # the keys, shown and hidden
    assert page.locator("#help").is_visible() and "restore the scene file's camera" in page.locator("#help").text_content()
    page.keyboard.press("h")
    assert page.locator("#help").is_hidden()
    assert "eye [0.000, 2.000, 6.000] · target [0.000, 0.500, 0.000]" in page.locator("#info").text_content()


def test_the_wheel_dollies_and_copy_camera_gives_the_view_as_toml(page, scene_file):
    n = painted(page)
    box = page.locator("#view").bounding_box()
    page.mouse.move(box["x"] + 10, box["y"] + 10)
    page.mouse.wheel(0, -300)  # three notches toward the user: 0.95^3 of the distance
    n = settle(page, n)
    page.click("#copy")
    table = tomllib.loads(page.evaluate("navigator.clipboard.readText()"))["camera"]
    eye = np.array(table["eye"])
    assert np.allclose(eye - table["target"], 0.95**3 * np.subtract((0, 2, 6), (0, 0.5, 0)), rtol=1e-9)
    # the copied table, back in the scene file, renders what the page shows (12 digits: a pixel may differ)
    scene = pyclray.load_scene(scene_file).with_size(*SIZE)
    camera = pyclray.Camera(**table)
    again = preview("shaded", pyclray.render(scene, aovs=("shaded",), camera=camera)["shaded"])
    assert np.mean(np.any(again != shown(page), axis=-1)) < 0.01
    page.keyboard.press("r")
    settle(page, n)


def test_the_aov_selector_switches_the_image(page, scene_file):
    options = page.locator("#aov option").all_text_contents()
    assert options[:5] == ["shaded", "depth", "zdepth", "normal", "id"]
    for aov in ("depth", "normal", "id", "shaded"):
        n = painted(page)
        page.select_option("#aov", aov)
        settle(page, n)
        assert np.array_equal(shown(page), expected(scene_file, aov)), aov


def test_nothing_is_painted_while_idle(page):
    n = painted(page)
    time.sleep(1.0)
    assert painted(page) == n


def test_an_edit_shows_keeping_the_users_camera_unless_the_files_camera_changed(page, scene_file):
    n = painted(page)
    drag(page, -30, 0)
    n = settle(page, n)
    first = shown(page)
    moved = camera_shown(page)
    # in place: the green ball smaller
    scene_file.write_text(TP02.replace("radius = 1.0", "radius = 0.6"))
    n = settle(page, n, timeout=5000)
    assert camera_shown(page) == moved  # the user's camera kept
    assert not np.array_equal(shown(page), first)
    page.keyboard.press("r")
    n = settle(page, n)
    assert np.array_equal(shown(page), expected(scene_file))
    # written beside and renamed over it (vim, VS Code): a new camera in the file is shown
    drag(page, 30, 0)
    n = settle(page, n)
    temporary = scene_file.with_name(".scene.toml.swp")
    temporary.write_text(TP02.replace("eye    = [0.0, 2.0, 6.0]", "eye    = [0.0, 3.0, 7.0]"))
    os.replace(temporary, scene_file)
    n = settle(page, n, timeout=5000)
    assert np.array_equal(shown(page), expected(scene_file))
    assert "eye [0.000, 3.000, 7.000]" in page.locator("#info").text_content()


def test_a_bad_edit_shows_the_renders_error_line_and_keeps_the_image(page, scene_file, tmp_path):
    scene_file.write_text(TP02)
    n = settle(page, painted(page), timeout=5000)
    good = shown(page)
    scene_file.write_text(TP02.replace("radius = 0.5", "radius = -0.5"))
    page.wait_for_function("document.getElementById('error').textContent !== ''", timeout=5000)
    banner = page.locator("#error")
    assert banner.is_visible()
    result = subprocess.run([sys.executable, "-m", "pyclray", "render", str(scene_file), "-o", str(tmp_path / "x.exr")],
                            capture_output=True, text=True)
    assert result.returncode == 2
    assert result.stderr == f"pyclray render: error: {banner.text_content()}\n"
    assert "key 'radius'" in banner.text_content()
    assert painted(page) == n and np.array_equal(shown(page), good)  # the last good image stays
    scene_file.write_text(TP02)
    page.wait_for_function("document.getElementById('error').textContent === ''", timeout=5000)
    assert banner.is_hidden()


def test_the_time_slider_shows_the_animation_at_that_time(browser):
    scene = REPO / "scenes/tp02_orbit.toml"
    viewer = Viewer(scene, "--size", f"{SIZE[0]}x{SIZE[1]}", "--aov", "depth")
    try:
        page = open_page(browser, viewer)
        animation = pyclray.load_scene(scene).animation
        slider = page.locator("#time")
        assert slider.is_visible() and page.locator("#aov").input_value() == "depth"
        assert float(slider.get_attribute("max")) == animation.duration
        assert float(slider.get_attribute("step")) == pytest.approx(1 / animation.fps)
        first = shown(page)
        assert np.array_equal(first, expected(scene, "depth", t=0.0))
        t = round(animation.duration / 3 * animation.fps) / animation.fps
        n = painted(page)
        slider.fill(str(t))  # sets the value and fires its input event
        settle(page, n)
        assert np.array_equal(shown(page), expected(scene, "depth", t=float(slider.input_value())))
        assert not np.array_equal(shown(page), first)
        # play: the clock advances by 1 / fps at the animation's rate and the images follow; pause stops it
        n, t = painted(page), float(slider.input_value())
        page.click("#play")
        page.wait_for_function("n => window.pyclrayView.painted >= n + 3", arg=n, timeout=5000)
        page.click("#play")
        assert float(slider.input_value()) != t and page.locator("#play").text_content() == "play"
        settle(page, painted(page) - 1)
        n = painted(page)
        time.sleep(0.5)
        assert painted(page) == n  # paused: nothing more
        page.context.close()
    finally:
        viewer.close()


def test_ctrl_c_with_a_page_connected(page, viewer):
    status, seconds, stderr = viewer.interrupt()
    assert status in (130, 0) and seconds < 5 and "Traceback" not in stderr, (status, seconds, stderr)
    page.wait_for_function("document.getElementById('info').textContent === 'the server has stopped'", timeout=5000)
