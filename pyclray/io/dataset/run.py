"""A data set run: the output folder, resuming, and writing views as they are rendered.

Resumable. OUT/.pyclray-dataset/ holds the run's settings (settings.json: a rerun with other
settings is refused, naming the first that differs) and one record per complete view
(views/{k:06d}.json). A view's files are written under temporary names and renamed together
(pyclray.io.files.write_together), and its record only after them, so a view is complete exactly
when its record exists: a rerun renders only the views without one and never rewrites a complete
view; the temporaries a killed run left (.NAME.XXXX.tmp) are removed first. The index files (BOP's
scene_*.json, views.json) are made from the records, in view order, at the end of every run: a
resumed run's files are the same bytes as an uninterrupted run's.

Off the render's path. The render loop (here, or the workers of a Dask cluster) hands each view to
a pool of writer threads that encode its PNGs (zlib releases the GIL) and write its files; at most a
few views per writer wait, so memory stays bounded."""
from __future__ import annotations

import json
import os
import re
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from ...model.errors import OutputError, RequestError
from ..files import reason, write_together

STATE = ".pyclray-dataset"
SETTINGS = "settings.json"
TEMPORARY = re.compile(r"^\..+\.[A-Za-z0-9_]+\.(tmp|old)$")  # files.replace_together's temporaries


def _json(content) -> bytes:
    return (json.dumps(content, sort_keys=True, indent=1) + "\n").encode()


def check_output(out: Path, settings: dict) -> bool:
    """Whether OUT is a run to resume (True) or a new one (False); raises for an output that is
    neither: a file, a missing parent folder, a folder with other files, or a run of other settings.
    Nothing is written."""
    if out.exists() and not out.is_dir():
        raise OutputError(f"cannot write the data set {out}: it is a file; nothing was written")
    if not out.exists():
        if not out.parent.is_dir():
            raise OutputError(f"cannot write {out}: the folder {out.parent} does not exist; nothing was written")
        return False
    state = out / STATE / SETTINGS
    if not state.is_file():
        foreign = sorted(p.name for p in out.iterdir())
        if foreign:
            raise OutputError(f"cannot write the data set into {out}: it holds files a data set run did not write "
                              f"(e.g. {foreign[0]}); give a new or empty folder, or the folder of a run to resume")
        return False
    try:
        before = json.loads(state.read_text())
    except (OSError, ValueError) as error:
        raise OutputError(f"cannot resume {out}: its {STATE}/{SETTINGS} is unreadable ({error})") from None
    for key in sorted(set(before) | set(settings)):
        if before.get(key) != settings.get(key):
            raise RequestError(f"cannot resume {out}: it was started with {key} = {json.dumps(before.get(key))}, this "
                               f"run has {json.dumps(settings.get(key))}; give the same options or a new folder")
    return True


def remove_temporaries(out: Path) -> int:
    """Remove the temporary files a killed run left in OUT (any depth); returns how many."""
    removed = 0
    for folder, _, names in os.walk(out):
        for name in names:
            if TEMPORARY.match(name):
                try:
                    os.unlink(os.path.join(folder, name))
                    removed += 1
                except FileNotFoundError:
                    pass
    return removed


def record_path(out: Path, k: int) -> Path:
    return out / STATE / "views" / f"{k:06d}.json"


def complete_views(out: Path, count: int) -> set[int]:
    return {k for k in range(count) if record_path(out, k).is_file()}


def _contents(value) -> bytes:
    return value() if callable(value) else value


def write_files(out: Path, files: dict, keep_existing: bool = False, durable: bool = True) -> None:
    """Files (relative path -> bytes or a callable making them) replaced together; with
    keep_existing, those already there are left as they are; durable: flushed to disk (fsync)."""
    items = [(out / rel, value) for rel, value in files.items() if not (keep_existing and (out / rel).exists())]
    if items:
        write_together([(path, lambda tmp, v=value: Path(tmp).write_bytes(_contents(v))) for path, value in items],
                       durable)


def write_view(out: Path, encoded) -> None:
    """A view's files, then its record (the mark of a complete view). Renamed into place, not
    flushed one by one (a flush per file cost more than the view's render): a killed run leaves
    whole views only; a crash of the machine may need the views of its last seconds again (delete
    their records), the index files are flushed at the end."""
    write_files(out, encoded.files, durable=False)
    write_files(out, {f"{STATE}/views/{encoded.index:06d}.json": _json(encoded.record)}, durable=False)


class ViewWriters:
    """A pool of writer threads: submit(job, *args) runs job(*args) on one of them; at most `depth`
    jobs wait (submit blocks until the oldest is done); an error is raised by the next submit or by
    finish. on_done() is called after each job."""

    def __init__(self, threads: int, on_done=None, depth: int | None = None):
        self.pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="pyclray-dataset-writer")
        self.pending: deque = deque()
        self.depth = depth or 2 * threads
        self.on_done = on_done
        self.lock = threading.Lock()
        self.busy = 0.0

    def _run(self, job, args):
        import time

        start = time.perf_counter()
        job(*args)
        with self.lock:
            self.busy += time.perf_counter() - start
        if self.on_done is not None:
            self.on_done()

    def submit(self, job, *args) -> None:
        self.pending.append(self.pool.submit(self._run, job, args))
        while len(self.pending) > self.depth or (self.pending and self.pending[0].done()):
            self.pending.popleft().result()

    def finish(self) -> None:
        while self.pending:
            self.pending.popleft().result()
        self.pool.shutdown(wait=True)

    def stop(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)


def start_output(out: Path, settings: dict, fmt, scene) -> None:
    """The folders, the settings and the files that depend on the scene alone (kept where a resumed
    run's are there already)."""
    try:
        out.mkdir(exist_ok=True)
        for folder in (f"{STATE}/views", *fmt.folders()):
            (out / folder).mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise OutputError(f"cannot write {out}: {reason(error)}") from None
    write_files(out, {f"{STATE}/{SETTINGS}": _json(settings)}, keep_existing=True)
    write_files(out, fmt.fixed_files(scene), keep_existing=True)


def finish_output(out: Path, fmt, scene, count: int) -> list[Path]:
    """The index files from every view's record, in view order."""
    if hasattr(os, "sync"):
        os.sync()  # the views' files, renamed without a flush each (write_view), to disk at once
    records = [json.loads(record_path(out, k).read_text()) for k in range(count)]
    files = fmt.index_files(scene, records)
    write_files(out, files)
    return [out / rel for rel in files]
