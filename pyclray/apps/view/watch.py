"""Live editing: the scene file and the files it names (a batch's .npz), polled for changes, and the
scene loaded again.

Polling modification times (no watcher library) follows every editor's way of saving: an in-place
write changes the file's mtime and size, a write-and-rename (vim, VS Code, most IDEs) its inode; a
network or container file system that sends no inotify events is watched as well. A change is
loaded once the files look the same in two polls in a row, so that a half-written file (truncated,
not yet written) is not shown as an error. Twenty stats a second cost microseconds."""
from __future__ import annotations

import dataclasses
import os
import tomllib
from pathlib import Path

import numpy as np

POLL_SECONDS = 0.05


def signature(paths) -> tuple:
    """What a change of any of these files changes: (mtime, size, inode, ctime) each, None if missing."""
    def one(path):
        try:
            stat = os.stat(path)
        except OSError:
            return None
        return stat.st_mtime_ns, stat.st_size, stat.st_ino, stat.st_ctime_ns

    return tuple(one(path) for path in paths)


def named_files(path) -> tuple[Path, ...]:
    """The scene file and the files its [[shapes]] name with `file` (relative to the scene's folder,
    as the loader reads them); just the scene file when it is not readable TOML."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_bytes().removeprefix(b"\xef\xbb\xbf").decode("utf-8"))
    except (OSError, ValueError, RecursionError):
        return (path,)
    shapes = data.get("shapes", [])
    files = [entry["file"] for entry in shapes if isinstance(entry, dict) and isinstance(entry.get("file"), str)] \
        if isinstance(shapes, list) else []
    return (path, *(path.parent / name for name in dict.fromkeys(files)))


def _same(a, b) -> bool:
    """Whether two shapes are equal, arrays compared by value (a batch's centres and radii)."""
    if type(a) is not type(b):
        return False
    for field in dataclasses.fields(a):
        if not field.compare:  # (what a shape keeps of its own checks)
            continue
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if not (isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and x.shape == y.shape and np.array_equal(x, y)):
                return False
        elif x != y:
            return False
    return True


def load(path, size, previous=None):
    """The scene file read again (at the --size given), and the files to watch. Its shapes that
    equal the previous scene's are the previous objects, so the scene prepared on the device is
    reused: as it is when no shape changed (an edit of the camera, a light, the shading), else
    updated in place for the changed shapes (pyclray.model.animation.derived_from, as an animation's
    frame): an edit of one shape beside a million spheres costs no new BVH."""
    from ...model.animation import derivation, derived_from
    from ...model.loader import load_scene

    files = named_files(path)
    scene = load_scene(path)
    if size is not None:
        scene = scene.with_size(*size)
    if previous is None or len(previous.shapes) != len(scene.shapes) or scene.animation is not None:
        return scene, files
    shapes = tuple(old if _same(old, new) else new for old, new in zip(previous.shapes, scene.shapes))
    if all(a is b for a, b in zip(shapes, previous.shapes)):
        return dataclasses.replace(scene, shapes=previous.shapes), files
    base = (derivation(previous.shapes) or (previous.shapes,))[0]  # the tuple first prepared
    return dataclasses.replace(scene, shapes=derived_from(shapes, base)), files
