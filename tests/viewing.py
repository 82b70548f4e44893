"""Helpers of the view's tests: `pyclray view` started in a process of its own, its URL read from
its first line, and stopped with SIGINT as Ctrl-C would."""
from __future__ import annotations

import os
import re
import selectors
import shutil
import signal
import subprocess
import sys
import time

URL_LINE = re.compile(r"pyclray view: (http://127\.0\.0\.1:(\d+)/\?token=([A-Za-z0-9_-]{20,}))\n")


class Viewer:
    """A running `pyclray view ... --no-browser`: .url, .port, .token, .origin."""

    def __init__(self, *args, cwd=None):
        self.process = subprocess.Popen([sys.executable, "-m", "pyclray", "view", *map(str, args), "--no-browser"],
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd,
                                        env=dict(os.environ))
        line = _line_within(self.process.stdout, 60)
        match = URL_LINE.fullmatch(line)
        if match is None:
            self.process.kill()
            raise AssertionError(f"expected the URL line, got {line!r}: {self.process.stderr.read()}")
        self.url, self.port, self.token = match[1], int(match[2]), match[3]
        self.origin = f"http://127.0.0.1:{self.port}"

    def interrupt(self, within: float = 5.0) -> tuple[int, float, str]:
        """SIGINT (Ctrl-C): the exit status, the seconds it took and what it wrote on stderr."""
        start = time.monotonic()
        self.process.send_signal(signal.SIGINT)
        try:
            status = self.process.wait(within)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            status = None
        return status, time.monotonic() - start, self.process.stderr.read()

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        self.process.stdout.close()
        self.process.stderr.close()


def _line_within(stream, seconds: float) -> str:
    with selectors.DefaultSelector() as selector:
        selector.register(stream, selectors.EVENT_READ)
        if not selector.select(seconds):
            return ""
    return stream.readline()


# -- the page in Debian's chromium (Playwright) ---------------------------------------------------

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or "/usr/bin/chromium"


def launch_browser(driver):
    """Headless chromium, the machine's own (Debian's, or a real one on the PATH: Playwright
    downloads none)."""
    return driver.chromium.launch(executable_path=CHROMIUM, args=["--headless=new", "--no-sandbox",
                                                                   "--disable-dev-shm-usage"])


def open_page(browser, viewer, timeout: float = 10_000):
    """A new page on the viewer, once its first full image is painted."""
    # bypass_csp: Playwright's wait_for_function evaluates strings, which the page's policy forbids
    context = browser.new_context(bypass_csp=True, viewport={"width": 800, "height": 600})
    context.grant_permissions(["clipboard-read", "clipboard-write"], origin=viewer.origin)
    page = context.new_page()
    page.goto(viewer.url)
    settle(page, 0, timeout)
    return page


def painted(page) -> int:
    """The page's data-frame: the images it has painted."""
    return int(page.locator("#view").get_attribute("data-frame"))


SETTLED = """n => {
    const view = window.pyclrayView;
    return view.painted > n && view.paints.at(-1).lossless && view.paints.at(-1).seq >= view.latest;
}"""


def settle(page, after: int, timeout: float = 10_000) -> int:
    """Wait for a lossless full image painted after the first `after` paints that shows every input
    sent so far (a lossless image of the view before the last inputs, when a busy machine lets the
    motion pause for longer than the server's SETTLE, is not it); the paints then."""
    page.wait_for_function(SETTLED, arg=after, timeout=timeout)
    return painted(page)


def drag(page, dx, dy, button="left", steps=8, shift=False):
    """A drag from the image's centre by (dx, dy) CSS pixels in `steps` moves (shift held if asked)."""
    box = page.locator("#view").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    if shift:
        page.keyboard.down("Shift")
    page.mouse.down(button=button)
    for k in range(1, steps + 1):
        page.mouse.move(x + dx * k / steps, y + dy * k / steps)
    page.mouse.up(button=button)
    if shift:
        page.keyboard.up("Shift")
