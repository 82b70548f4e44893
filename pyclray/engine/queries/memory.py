"""Whether a render's images fit in memory, asked before anything is allocated: a render too large
for the machine is one clear RequestError naming the bytes it needs, not a MemoryError (or, where the
system overcommits memory, a process killed later when the pages are touched)."""
from __future__ import annotations

from pathlib import Path

from ...model.aovs import image_bytes
from ...model.errors import RequestError


# Images up to this many bytes are not checked (reading /proc/meminfo costs a share of a warm render;
# docs/benchmarks.md, "Why the engine does what it does"): every machine pyclray runs on has that much
# to spare.
ALWAYS_FITS = 64 << 20


def available_bytes() -> int | None:
    """Memory this process can still get: Linux's MemAvailable, within the control group's limit
    where one is set (a container); None where neither can be read (no check then)."""
    available = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                available = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit != "max":
            room = int(limit) - int(Path("/sys/fs/cgroup/memory.current").read_text())
            available = room if available is None else min(available, room)
    except (OSError, ValueError):
        pass
    return available


def _size(count: int) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if count >= scale:
            return f"{count / scale:.3g} {unit}"
    return f"{count} bytes"


def check_images_fit(aovs, precision: str, cols: int, rows: int) -> None:
    """Raise a RequestError if the images of a cols x rows render would not fit in the memory
    available now; it names the bytes and how to render such an image in parts."""
    needed = image_bytes(aovs, cols * rows, precision)
    if needed <= ALWAYS_FITS:  # no file to read for the usual render
        return
    available = available_bytes()
    if available is None or needed <= available:
        return
    band = max(1, available // 4 // max(1, image_bytes(aovs, cols, precision)))
    raise RequestError(
        f"the images asked for ({', '.join(aovs)}; {cols}x{rows} pixels, {precision}) need {needed:,} bytes "
        f"({_size(needed)}), more than the {_size(max(available, 0))} of memory available; render the image in "
        f"parts with window=(x0, y0, width, height), e.g. bands of rows window=(0, y, {cols}, {min(band, rows)}), "
        f"or write it to a file with `pyclray render`, which renders and writes it in bands")
