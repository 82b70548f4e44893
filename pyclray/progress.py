"""Progress bars for long work (renders of large images, writes, checks): tqdm on stderr when it
is a terminal, shown only once the work has taken a second; nothing at all otherwise (pipes,
logs, tests)."""
from __future__ import annotations

import sys


def progress(total: int | None = None, *, desc: str, unit: str = "it"):
    """A tqdm bar (a context manager with update(n)), disabled when stderr is not a terminal."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=not sys.stderr.isatty(), delay=1.0, leave=False,
                file=sys.stderr, dynamic_ncols=True)


def seconds(value: float) -> str:
    """A duration as people read it: 35.1 ms, 2.41 s, 3 min 12 s."""
    if value < 1:
        return f"{value * 1e3:.1f} ms"
    if value < 120:
        return f"{value:.2f} s"
    return f"{int(value // 60)} min {value % 60:.0f} s"
