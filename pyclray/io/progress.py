"""Progress bars for long work (renders of large images, writes, checks): tqdm on stderr when it
is a terminal, shown only once the work has taken a second; nothing at all otherwise (pipes,
logs, tests)."""
from __future__ import annotations

import sys

DELAY = 1.0  # seconds of work before a bar appears: quick commands draw nothing


def progress(total: int | None = None, *, desc: str, unit: str = "it"):
    """A tqdm bar (a context manager with update(n)), disabled when stderr is not a terminal."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=not sys.stderr.isatty(), delay=DELAY, leave=False,
                file=sys.stderr, dynamic_ncols=True)


def seconds(value: float) -> str:
    """A duration as people read it: 35.1 ms, 2.41 s, 3 min 12 s."""
    if value < 1:
        return f"{value * 1e3:.1f} ms"
    if value < 120:
        return f"{value:.2f} s"
    return f"{int(value // 60)} min {value % 60:.0f} s"


_steps: list = []  # the step bar of the command running, if any (a stack: commands may nest)


class steps:
    """A bar over the named steps of a long command (e.g. pyclray check: render, Mitsuba, oracle,
    ...): `with steps(5, desc="pyclray check"):` around the work, and `step("oracle")` where each
    step begins. Outside such a block step() does nothing, so library calls stay silent.
    ``times`` holds each step's wall-clock seconds (a name met twice adds up)."""

    def __init__(self, total: int, *, desc: str):
        self.total, self.desc = total, desc
        self.times: dict[str, float] = {}
        self.current: str | None = None

    def __enter__(self):
        self.bar = progress(self.total, desc=self.desc, unit="step")
        self.started = False
        _steps.append(self)
        return self

    def lap(self, name: str | None) -> None:
        """The step running ends (its time is kept) and ``name`` begins."""
        import time

        now = time.perf_counter()
        if self.current is not None:
            self.times[self.current] = self.times.get(self.current, 0.0) + now - self.began
        self.current, self.began = name, now

    def __exit__(self, *exc):
        self.lap(None)
        _steps.remove(self)
        self.bar.close()
        return False


def step(name: str) -> None:
    """The next step of the running command's bar begins (see steps)."""
    if not _steps:
        return
    current = _steps[-1]
    if current.started:
        current.bar.update(1)
    current.started = True
    current.lap(name)
    current.bar.set_postfix_str(name, refresh=True)
