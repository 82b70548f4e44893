"""Helpers of the view's tests: `pyclray view` started in a process of its own, its URL read from
its first line, and stopped with SIGINT as Ctrl-C would."""
from __future__ import annotations

import os
import re
import selectors
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
