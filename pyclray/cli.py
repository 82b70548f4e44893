"""The command line: pyclray render | devices (and the commands other modules add)."""
from __future__ import annotations

import argparse
import sys
import time
from contextlib import ExitStack
from pathlib import Path

EXIT_BAD_INPUT = 2


class BadInput(Exception):
    """Reported as one line on stderr with exit status 2."""


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
        if width < 1 or height < 1:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 512x512, got {text!r}") from None
    return width, height


def _time(text: str) -> float:
    try:
        value = float(text)
        if not value >= 0 or value == float("inf"):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a time in seconds >= 0, got {text!r}") from None
    return value


def _count(text: str) -> int:
    try:
        value = int(text)
        if value < 1:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}") from None
    return value


def _aovs(text: str) -> tuple[str, ...]:
    from .device import AOVS

    names = tuple(a.strip() for a in text.split(",") if a.strip())
    bad = [a for a in names if a not in AOVS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list of {', '.join(AOVS)}, got {text!r}")
    return names


def _load(path: str, size=None, t=None):
    from .scene import load_scene

    scene = load_scene(path)
    scene = scene.with_size(*size) if size else scene
    return scene if t is None else scene.at(t)  # the static scene at that time of its animation


def _writable(path: Path, what: str) -> None:
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise BadInput(f"{what} {path}: the folder {folder} does not exist")
    if path.is_dir():
        raise BadInput(f"{what} {path}: is a folder")


def cmd_render(args) -> int:
    from . import output
    from .render import render

    out = Path(args.output)
    _writable(out, "-o")
    scene = _load(args.scene, args.size, args.time)
    previews = output.preview_paths(out) if args.png else {}
    start = time.perf_counter()
    where = ""
    if args.workers is not None or args.scheduler is not None:
        frame, where = _render_on_cluster(args, scene)
    else:
        frame = render(scene, aovs=args.aov, precision=args.precision, device=args.device)
    elapsed = time.perf_counter() - start
    written = [out]
    # every file goes to a temporary name first; all are renamed only once all are written
    with ExitStack() as stack:
        tmp = stack.enter_context(output.atomic_path(out))
        output.write_exr(tmp, frame, comment=f"pyclray render of {args.scene}")
        for name, make in (("depth", output.depth_preview), ("normal", output.normal_preview)):
            if name in frame and name in previews:
                png = stack.enter_context(output.atomic_path(previews[name]))
                output.write_png(png, make(frame[name]))
                written.append(previews[name])
    channels = ", ".join(output.exr_channels(frame))
    print(
        f"rendered {args.scene} ({scene.image.width}x{scene.image.height}, {args.precision}, "
        f"{frame.device}) in {elapsed * 1e3:.1f} ms{where}; wrote {', '.join(map(str, written))} [{channels}]"
    )
    return 0


def _render_on_cluster(args, scene):
    """The image rendered in tiles on a Dask cluster (pyclray/cluster.py), and what to report of it."""
    from tqdm import tqdm

    from .animate import cluster_module

    cluster = cluster_module()
    windows = cluster.tiles(scene.image.width, scene.image.height, args.tile)
    start = time.perf_counter()
    try:
        with cluster.connect(args.workers, args.scheduler) as client:
            start_time = time.perf_counter() - start
            where = cluster.describe(client)
            with tqdm(total=len(windows), unit="tile", disable=not sys.stderr.isatty(), leave=False) as bar:
                frame = cluster.render_tiled(client, scene, args.aov, args.precision, args.device, args.tile, bar)
    except cluster.ClusterError as error:
        raise BadInput(str(error)) from None
    return frame, f" ({len(windows)} tile{'s' if len(windows) != 1 else ''} on {where}, cluster start {start_time:.2f} s)"


def cmd_devices(args) -> int:
    from .device import list_devices

    devices = list_devices()
    if not devices:
        raise BadInput("no OpenCL device found: install a driver, e.g. pip install 'pyopencl[pocl]'")
    for d in devices:
        mark = "*" if d["default"] else " "
        fp64 = "fp64" if d["fp64"] else "no fp64"
        print(f"{mark} {d['selector']:>5}  {d['platform']} / {d['device']} ({d['type']}, {d['compute_units']} units, {fp64})")
    print("* the default; select another with --device P:D (or a part of its name) or PYOPENCL_CTX=P:D")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pyclray",
        description="pyclray: an exact OpenCL ray caster. It renders depth, normal and id images of "
        "analytic scenes (planes, spheres) described in TOML files.",
        epilog="Bad input prints one line naming the file, table and key, and exits with status 2.",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    render = commands.add_parser(
        "render",
        help="render a scene to a multi-channel OpenEXR file (and PNG previews)",
        description="Render SCENE with one ray per pixel centre and write one OpenEXR file with "
        "the channels Z (distance from the eye, inf on a miss), N.X N.Y N.Z (unit world normal, "
        "0 on a miss) and id (UINT holding the int32 shape id; 4294967295 = -1 on a miss).",
    )
    render.add_argument("scene", metavar="SCENE", help="scene file (TOML)")
    render.add_argument("-o", "--output", required=True, metavar="OUT.exr", help="the OpenEXR file to write")
    render.add_argument(
        "--aov", type=_aovs, default=("depth", "normal", "id"), metavar="LIST",
        help="comma-separated images to compute: depth,normal,id (default: all); fewer is faster",
    )
    render.add_argument(
        "--png", action="store_true",
        help="also write OUT.depth.png (near bright, far dark, misses black) and OUT.normal.png (n*0.5+0.5)",
    )
    render.add_argument("--precision", choices=("fp32", "fp64"), default="fp32", help="kernel precision (default fp32)")
    render.add_argument("--size", type=_size, metavar="WxH", help="override the scene's image size")
    render.add_argument("--time", type=_time, metavar="T", help="render the scene at time T (seconds) of its [animation]")
    render.add_argument(
        "--device", metavar="DEV",
        help="OpenCL device: P:D indices (see `pyclray devices`) or part of its name; default "
        "$PYOPENCL_CTX, else PoCL's CPU device",
    )
    render.add_argument("--tile", type=_count, default=512, metavar="PIXELS",
                        help="with --workers or --scheduler: the side of a tile, a task (default 512)")
    from .animate import add_cluster_options

    add_cluster_options(render, "the image's tiles")
    render.set_defaults(run=cmd_render)

    devices = commands.add_parser("devices", help="list the OpenCL devices", description="List the OpenCL devices and their selectors.")
    devices.set_defaults(run=cmd_devices)

    for extra in _extra_commands():
        extra(commands)
    return parser


# modules that add a subcommand with add_command(subparsers); each imports its heavy parts lazily
COMMAND_MODULES = ("check", "stability", "animate")


def _extra_commands():
    from importlib import import_module

    out = []
    for name in COMMAND_MODULES:
        try:
            out.append(import_module(f"{__package__}.{name}").add_command)
        except ModuleNotFoundError as error:
            if error.name != f"{__package__}.{name}":
                raise
    return out


def main(argv=None) -> int:
    from .errors import DeviceError, PyclrayError, SceneError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except (BadInput, SceneError, DeviceError) as error:
        print(f"pyclray {args.command}: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except PyclrayError as error:
        print(f"pyclray {args.command}: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    # run the package's module, not this __main__ copy: the commands raise pyclray.cli.BadInput
    from pyclray.cli import main as package_main

    sys.exit(package_main())
