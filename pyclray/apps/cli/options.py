"""What every command shares: the one-line error (BadInput), the parsers of option values, loading
the scene, and the cluster options. Heavy modules (numpy, pyopencl, Dask) are imported only where a
value needs them, so that a bad option fails before any slow import."""
from __future__ import annotations

import argparse
import re

from .texts import EXIT_BAD_INPUT


class BadInput(Exception):
    """Reported as one line on stderr with exit status 2."""


class Parser(argparse.ArgumentParser):
    """argparse, with a bad option reported as the contract asks: ONE line on stderr,
    `pyclray <command>: error: ...`, and exit status 2 (argparse's own prints its usage lines first).
    The subcommands' parsers are of this class too (add_subparsers makes its parent's class)."""

    def error(self, message: str):
        message = " ".join(message.split())  # one line whatever argparse wrote
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def max_side() -> int:
    from ...model.camera import MAX_IMAGE_SIDE

    return MAX_IMAGE_SIDE


def image_size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
        if width < 1 or height < 1:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 512x512, got {text!r}") from None
    if max(width, height) > max_side():
        raise argparse.ArgumentTypeError(f"expected each side at most {max_side()} pixels, got {text!r}")
    return width, height


def time_value(text: str) -> float:
    try:
        value = float(text)
        if not value >= 0 or value == float("inf"):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a time in seconds >= 0, got {text!r}") from None
    return value


def count(text: str) -> int:
    try:
        value = int(text)
        if value < 1:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}") from None
    return value


def positive(text: str, what: str = "a number > 0") -> float:
    try:
        value = float(text)
        if not 0 < value < float("inf"):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    return value


def seed(text: str) -> int:
    try:
        value = int(text)
        if value < 0:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}") from None
    return value


def aov_list(text: str) -> tuple[str, ...]:
    from ...model.aovs import RENDER_AOVS

    names = tuple(a.strip() for a in text.split(",") if a.strip())
    bad = [a for a in names if a not in RENDER_AOVS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list of {', '.join(RENDER_AOVS)}, got {text!r}")
    repeated = sorted({a for a in names if names.count(a) > 1})
    if repeated:
        raise argparse.ArgumentTypeError(f"expected each image once, got {text!r} ({', '.join(repeated)} more than once)")
    return names


def load(path: str, size=None, t=None):
    from ...model.loader import load_scene

    scene = load_scene(path)
    scene = scene.with_size(*size) if size else scene
    if t is not None and scene.animation is None:  # a time of nothing: a mistake, not ignored
        raise BadInput(f"--time: {path} has no [animation] table; --time renders a time of an animated scene")
    return scene if t is None else scene.at(t)  # the static scene at that time of its animation


# The addresses Dask's Client takes: protocol://host:port (tcp, tls, ws, wss, ucx; the host a name, an
# IPv4 address or an IPv6 one in brackets), host:port (tcp), or inproc://... (within one process).
_PROTOCOLS = ("tcp", "tls", "ws", "wss", "ucx")
_HOST_PORT = re.compile(r"(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(?P<port>\d{1,5})")


def scheduler_address(text: str) -> str:
    """--scheduler ADDRESS, checked before Dask is imported or anything connects: a typo (a
    missing port, an unknown protocol) is one line at once, not a connection attempt."""
    protocol, separator, rest = text.partition("://")
    if not separator:
        protocol, rest = "tcp", text
    if protocol == "inproc" and rest:
        return text
    match = _HOST_PORT.fullmatch(rest)
    if protocol not in _PROTOCOLS or not match or not 0 < int(match["port"]) < 65536:
        raise argparse.ArgumentTypeError(
            f"expected a Dask scheduler's address PROTOCOL://HOST:PORT such as tcp://10.0.0.5:8786 "
            f"(protocols: {', '.join(_PROTOCOLS)}; a port 1 to 65535), got {text!r}")
    return text


def add_cluster_options(parser, what: str) -> None:
    """--workers N | --scheduler ADDRESS (pyclray.apps.cluster; needs the cluster extra)."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--workers", type=count, metavar="N",
                       help=f"render {what} on a local Dask cluster of N worker processes (pip install 'pyclray[cluster]')")
    group.add_argument("--scheduler", type=scheduler_address, metavar="ADDRESS",
                       help=f"render {what} on a running Dask cluster, e.g. tcp://host:8786 (see docs/clusters.md)")


def cluster_module():
    """pyclray.apps.cluster, or a BadInput saying how to install what it needs."""
    try:
        from .. import cluster
    except ModuleNotFoundError as error:
        if error.name not in ("distributed", "dask"):
            raise
        raise BadInput("--workers and --scheduler need Dask distributed: pip install 'pyclray[cluster]'") from None
    return cluster
