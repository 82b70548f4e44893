"""The one place that replaces the files of a command together: every file is written to a
temporary file beside its target, flushed to disk, and renamed only once every file of the command
is written, so a failure (or Ctrl-C) never leaves a partial, clobbered or mixed set of outputs."""
from __future__ import annotations

import os
import signal
import tempfile
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable, Iterator

from ..model.errors import OutputError


def reason(error: OSError) -> str:
    return (error.strerror or str(error)).lower() if isinstance(error, OSError) else str(error)


def check_target(path) -> None:
    """Raise OutputError if path cannot be an output file (its folder is missing, or it is a folder)."""
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        raise OutputError(f"cannot write {path}: the folder {folder} does not exist; nothing was replaced")
    if path.is_dir():
        raise OutputError(f"cannot write {path}: it is a folder; nothing was replaced")


def _fsync(path, *, folder: bool = False) -> None:
    fd = os.open(path, os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if folder else 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextmanager
def _interrupts_deferred():
    """Hold Ctrl-C (SIGINT) back while the block runs, then raise it: the renames of
    replace_together are all done or none, never half."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught = []
    previous = signal.signal(signal.SIGINT, lambda number, frame: caught.append(number))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt


@contextmanager
def replace_together(paths: Iterable, durable: bool = True) -> Iterator[list[str]]:
    """Replace the files ``paths`` together or not at all.

    Yields one temporary path per target (same folder, hidden name, in the order given); the block
    writes each temporary (in any order, by any means: a numpy tofile, an encoder, a video writer
    given the path). When the block ends normally, every temporary is flushed to disk (fsync) and
    then all are renamed onto their targets; old files of the same names are replaced only then.
    If the block raises (or Ctrl-C arrives), or a flush or a rename fails, the temporaries are
    removed, targets already renamed get their old file back, and the old files stay as they were.
    Write failures (OSError: read-only folder, full disk, a target that is a folder, a missing
    folder) are raised as OutputError naming the path and the reason; other exceptions pass
    through after the clean-up.

    For a folder of frames, give one path per frame file (the folder must exist). Writers with a
    callback per file use write_together. durable=False leaves out the flushes (fsync): the renames
    still make the files appear complete or not at all to any reader and after a killed process, but
    not after a crash of the machine (a data set's many small files: pyclray.io.dataset.run).
    """
    targets = [Path(p) for p in paths]
    if len({os.path.abspath(t) for t in targets}) != len(targets):
        raise OutputError("cannot write the same file twice in one command: " + ", ".join(map(str, targets)))
    for target in targets:
        check_target(target)
    temporaries: list[str] = []
    current = targets[0] if targets else None
    try:
        for target in targets:
            current = target
            handle, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
            os.close(handle)
            temporaries.append(tmp)
        current = None
        yield list(temporaries)
        umask = os.umask(0)
        os.umask(umask)
        for target, tmp in zip(targets, temporaries):
            current = target
            os.chmod(tmp, 0o666 & ~umask)  # as an ordinary new file, not mkstemp's 0600
            if durable:
                _fsync(tmp)
        with _interrupts_deferred():
            _rename_all(targets, temporaries)
            temporaries = []
        current = None
    except OSError as error:
        name = error.filename if current is None and getattr(error, "filename", None) else current
        if name is not None and str(name) in temporaries:  # a temporary's name means nothing to the user
            name = targets[temporaries.index(str(name))]
        what = f"cannot write {name if name is not None else ', '.join(map(str, targets))}"
        raise OutputError(f"{what}: {reason(error)}; nothing was replaced") from None
    finally:
        for tmp in temporaries:
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass
    for folder in {t.parent for t in targets} if durable else ():  # the renames themselves to disk
        try:
            _fsync(folder, folder=True)
        except OSError:
            pass


def _rename_all(targets, temporaries) -> None:
    """Rename every temporary onto its target; if one rename fails, undo the ones done (each old
    file is kept under a hard link until all renames are through)."""
    backups: dict[Path, str | None] = {}
    done: list[Path] = []
    try:
        for target in targets:
            backups[target] = None
            if target.exists():
                backup = tempfile.mktemp(dir=target.parent, prefix=f".{target.name}.", suffix=".old")
                try:
                    os.link(target, backup)
                    backups[target] = backup
                except OSError:
                    pass  # no hard links here: a failed rename cannot restore this one
        for target, tmp in zip(targets, temporaries):
            os.replace(tmp, target)
            done.append(target)
    except BaseException:
        for target in reversed(done):
            try:
                if backups[target] is not None:
                    os.replace(backups[target], target)
                    backups[target] = None
                else:
                    os.unlink(target)
            except OSError:
                pass
        raise
    finally:
        for backup in backups.values():
            if backup is not None:
                try:
                    os.unlink(backup)
                except OSError:
                    pass


def write_together(outputs: Iterable[tuple[object, Callable[[str], None]]], durable: bool = True) -> list[Path]:
    """Write the files of one command, replaced together or not at all (see replace_together).

    outputs: (final path, write) pairs; write(tmp) writes the complete file at the temporary path
    tmp (a str in the target's folder). Returns the final paths. Raises OutputError when a file
    cannot be written; then no target has changed.
    """
    outputs = list(outputs)
    with replace_together([path for path, _ in outputs], durable) as temporaries:
        for tmp, (_, write) in zip(temporaries, outputs):
            write(tmp)
    return [Path(path) for path, _ in outputs]


class Background:
    """A writer's work, done in order on one thread of its own while the caller renders the next
    band: at most `depth` jobs wait (so at most that many bands are held); a job's error is raised
    in the caller by the next submit or by finish."""

    def __init__(self, depth: int = 2):
        self.pool = ThreadPoolExecutor(max_workers=1)
        self.pending: deque = deque()
        self.depth = depth

    def submit(self, job, *args) -> None:
        self.pending.append(self.pool.submit(job, *args))
        while len(self.pending) > self.depth or (self.pending and self.pending[0].done()):
            self.pending.popleft().result()

    def finish(self) -> None:
        while self.pending:
            self.pending.popleft().result()

    def stop(self) -> None:
        """After a failure: drop the waiting jobs and wait for the running one."""
        self.pool.shutdown(wait=True, cancel_futures=True)
