"""Errors and the value checks shared by the scene model and the shapes."""
from __future__ import annotations

import math
from numbers import Real

import numpy as np


class PyclrayError(Exception):
    """Base class of pyclray's own errors."""


class SceneError(PyclrayError, ValueError):
    """A scene that cannot be rendered: says which file, which table, which key, what was expected."""

    def __init__(self, message: str, *, file=None, table=None, key=None):
        self.message = message
        self.file = None if file is None else str(file)
        self.table = table
        self.key = key
        super().__init__(str(self))

    def within(self, *, file=None, table=None) -> "SceneError":
        """The same error with the file or table filled in where it was not known yet."""
        return SceneError(
            self.message,
            file=self.file if self.file is not None else file,
            table=self.table if self.table is not None else table,
            key=self.key,
        )

    def __str__(self) -> str:
        where = []
        if self.file is not None:
            where.append(self.file)
        if self.table is not None:
            where.append(f"table {self.table}")
        if self.key is not None:
            where.append(f"key {self.key!r}")  # repr: quoted, and one line whatever the key holds
        return ": ".join(where + [self.message])


class DeviceError(PyclrayError, RuntimeError):
    """No usable OpenCL device, or a device that lacks what the request needs."""


class BuildError(PyclrayError, RuntimeError):
    """The OpenCL compiler rejected a kernel; the message holds its log."""


class OutputError(PyclrayError, OSError):
    """An output file that cannot be written (a missing or read-only folder, a full disk, a path
    that is a folder): names the path and the reason. Nothing was replaced: the command's old
    files are intact and no temporary is left behind. Exit status 2 on the command line.
    Also an output file that cannot be read back (read_exr, read_npz: a missing, unreadable or
    damaged file, or one of another format): "cannot read PATH: reason"."""


class RequestError(PyclrayError, ValueError):
    """A call with arguments of the wrong kind (e.g. aovs with repeats, an unknown precision, a
    scene that is neither a Scene nor a path): says which argument and what was expected."""


class PyclrayWarning(UserWarning):
    """Something that renders but is probably not what was meant (e.g. a scene with no shapes)."""


def _shown(value) -> str:
    """A value as an error message shows it: one line of at most 60 characters, numpy's numbers as
    plain numbers (1.0, not np.float64(1.0)) and an array with its shape."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, np.ndarray):
        body = np.array2string(value, separator=", ", threshold=8, edgeitems=2, max_line_width=1 << 30)
        text = f"an array of shape {value.shape}: {' '.join(body.split())}"
    else:
        text = " ".join(repr(value).split())
    return text if len(text) <= 60 else text[:57] + "..."


def _real(value) -> bool:
    """A real number and not a bool; a float (numpy's float64 too) is told first, without the
    abstract base class's slower check (an animation's frame checks every changed shape's numbers)."""
    return isinstance(value, float) or (isinstance(value, Real) and not isinstance(value, bool))


def number(key: str, value, *, positive: bool = False) -> float:
    """A finite real number (an int is accepted; a bool or a string is not)."""
    if not _real(value):
        raise SceneError(f"expected a number, got {_shown(value)}", key=key)
    try:
        value = float(value)
    except OverflowError:  # an integer beyond float64
        value = math.inf
    if not math.isfinite(value):
        raise SceneError(f"expected a finite number, got {value}", key=key)
    if positive and not value > 0:
        raise SceneError(f"expected a number > 0, got {value!r}", key=key)
    return value


def vector3(key: str, value) -> tuple[float, float, float]:
    """Three finite numbers."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 3:
        raise SceneError(f"expected 3 numbers [x, y, z], got {_shown(value)}", key=key)
    out = []
    for component in value:
        if not _real(component):
            raise SceneError(f"expected 3 numbers [x, y, z], got {_shown(value)}", key=key)
        try:
            component = float(component)
        except OverflowError:  # an integer beyond float64
            component = math.inf
        if not math.isfinite(component):
            raise SceneError(f"expected 3 finite numbers, got {_shown(value)}", key=key)
        out.append(component)
    return tuple(out)


def integer(key: str, value, *, minimum: int | None = None, maximum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise SceneError(f"expected a whole number, got {_shown(value)}", key=key)
    if minimum is not None and value < minimum:
        raise SceneError(f"expected a whole number >= {minimum}, got {value}", key=key)
    if maximum is not None and value > maximum:
        raise SceneError(f"expected a whole number <= {maximum}, got {value}", key=key)
    return int(value)


def text(key: str, value) -> str:
    if not isinstance(value, str):
        raise SceneError(f"expected a string, got {_shown(value)}", key=key)
    return value


def typed_table(entry, types, noun: str) -> str:
    """The type of one table of an array of tables ([[shapes]], [[lights]]): the entry must be a
    table whose "type" names one of types (the noun says what they are in the messages)."""
    if not isinstance(entry, dict):
        raise SceneError(f"expected a table, got {type(entry).__name__}")
    if "type" not in entry:
        raise SceneError(f"missing required key (one of: {', '.join(types)})", key="type")
    kind = text("type", entry["type"])
    if kind not in types:
        raise SceneError(f"unknown {noun} type {kind!r} (expected one of: {', '.join(types)})", key="type")
    return kind


def no_unknown_keys(table: dict, known, *, required=()) -> None:
    for key in table:
        if key not in known:
            expected = ", ".join(sorted(known))
            raise SceneError(f"unknown key (expected one of: {expected})", key=key)
    for key in required:
        if key not in table:
            raise SceneError("missing required key", key=key)


def norm3(v) -> float:
    return math.hypot(*v)
