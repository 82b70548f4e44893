"""The command line: pyclray render | devices (and the commands other modules add).

Exit status: 0 success; 1 a check outside its tolerance, or an unexpected error; 2 bad input (a
scene, an option) or an output that cannot be written, reported as one line on stderr, with no
file replaced; 130 interrupted (Ctrl-C), quietly, with no file replaced.
"""
from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130
EXIT_STATUS_HELP = (
    "Exit status: 0 done; 1 a check outside its tolerance (or an unexpected error); 2 bad input (one "
    "line naming the file, table and key, or the option) or an output that cannot be written (a "
    "missing or read-only folder, a full disk, a path that is a folder); 130 interrupted. On 2 and "
    "130 no output file is replaced: the files of one command are replaced together or not at all."
)


class BadInput(Exception):
    """Reported as one line on stderr with exit status 2."""


def _max_side() -> int:
    from .scene import MAX_IMAGE_SIDE

    return MAX_IMAGE_SIDE


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
        if width < 1 or height < 1:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 512x512, got {text!r}") from None
    if max(width, height) > _max_side():
        raise argparse.ArgumentTypeError(f"expected each side at most {_max_side()} pixels, got {text!r}")
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
    from .device import RENDER_AOVS

    names = tuple(a.strip() for a in text.split(",") if a.strip())
    bad = [a for a in names if a not in RENDER_AOVS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list of {', '.join(RENDER_AOVS)}, got {text!r}")
    repeated = sorted({a for a in names if names.count(a) > 1})
    if repeated:
        raise argparse.ArgumentTypeError(f"expected each image once, got {text!r} ({', '.join(repeated)} more than once)")
    return names


def _load(path: str, size=None, t=None):
    from .scene import load_scene

    scene = load_scene(path)
    scene = scene.with_size(*size) if size else scene
    return scene if t is None else scene.at(t)  # the static scene at that time of its animation


def _band_renderer(scene, aovs, precision, device):
    """window (x0, y0, w, h) -> the images of that part of the image (pyclray.render's window)."""
    from .render import render

    return lambda window: render(scene, aovs=aovs, precision=precision, device=device, window=window)


def cmd_render(args) -> int:
    from . import output
    from .progress import progress, seconds

    out = Path(args.output)
    scene = _load(args.scene, args.size, args.time)
    targets = [out, *(output.preview_paths(out, args.aov).values() if args.png else ())]
    for target in targets:  # before the render: a path that cannot be written costs no time
        output.check_target(target)
    if args.workers is not None or args.scheduler is not None:
        return _render_on_cluster(args, scene, out)
    width, height = scene.image.width, scene.image.height
    render_band = _band_renderer(scene, args.aov, args.precision, args.device)
    rows = output.band_rows(width)
    spent = {"render": 0.0}
    devices = []

    def bands():
        """The image in bands of whole rows, rendered as they are written (bounded memory)."""
        for top in range(0, height, rows):
            count = min(rows, height - top)
            start = time.perf_counter()
            frame = render_band((0, top, width, count))
            spent["render"] += time.perf_counter() - start
            devices.append(frame.device)
            yield frame
            bar.update(count)

    start = time.perf_counter()
    with progress(height, desc="pyclray render", unit="row") as bar:
        written = output.write_images(out, bands(), width=width, height=height, aovs=args.aov, previews=args.png,
                                      comment=f"pyclray render of {args.scene}")
    total = time.perf_counter() - start
    channels = ", ".join(output.exr_channel_arrays(output.empty_images(args.aov)))
    print(
        f"rendered {args.scene} ({width}x{height}, {args.precision}, {devices[0] if devices else '?'}) in "
        f"{seconds(total)} (render {seconds(spent['render'])}, write {seconds(total - spent['render'])}); "
        f"wrote {', '.join(map(str, written))} [{channels}]"
    )
    return 0


def _render_on_cluster(args, scene, out) -> int:
    """`pyclray render --workers N | --scheduler ADDRESS`: the image's bands of whole rows are the
    tasks (pyclray/cluster.py); they come back in order and are streamed into the files as a local
    render streams its bands, so the files are the same bytes."""
    from . import output
    from .animate import cluster_module
    from .progress import progress, seconds

    cluster = cluster_module()
    width, height = scene.image.width, scene.image.height
    start = time.perf_counter()
    try:
        with cluster.connect(args.workers, args.scheduler) as client:
            start_time = time.perf_counter() - start
            where = cluster.describe(client)
            rows = cluster.band_rows(width, height)
            devices = []

            def bands():
                for band in cluster.render_bands(client, scene, args.aov, args.precision, args.device, rows, bar):
                    devices.append(band.device)
                    yield band

            with progress(-(-height // rows), desc="pyclray render", unit="band") as bar:
                written = output.write_images(out, bands(), width=width, height=height, aovs=args.aov,
                                              previews=args.png, comment=f"pyclray render of {args.scene}")
    except cluster.ClusterError as error:
        raise BadInput(str(error)) from None
    total = time.perf_counter() - start
    channels = ", ".join(output.exr_channel_arrays(output.empty_images(args.aov)))
    count = -(-height // rows)
    print(
        f"rendered {args.scene} ({width}x{height}, {args.precision}, {devices[0] if devices else '?'}) in "
        f"{seconds(total)} (cluster start {seconds(start_time)}, {count} band{'s' if count != 1 else ''} of {rows} rows "
        f"on {where}, rendered there and written here as they came); wrote {', '.join(map(str, written))} [{channels}]"
    )
    return 0


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
        epilog=EXIT_STATUS_HELP,
    )
    parser.add_argument("--version", action="version", version=f"pyclray {_version()}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    render = commands.add_parser(
        "render",
        help="render a scene to a multi-channel OpenEXR file (and PNG previews)",
        description="Render SCENE with one ray per pixel centre and write one OpenEXR file with "
        "the channels Z (distance from the eye, inf on a miss), N.X N.Y N.Z (unit world normal, "
        "0 on a miss), id (UINT holding the int32 shape id; 4294967295 = -1 on a miss), and as asked "
        "zdepth (depth along the optical axis), P.X P.Y P.Z (world hit point) and R G B (shaded, linear RGB). "
        "Z, N and the other float images are 32-bit FLOAT channels also for --precision fp64 (rounded to "
        "float32): OpenEXR has no 64-bit "
        "float channel type. Large images are rendered and written in bands of rows, so memory stays "
        "bounded; a progress bar shows on a terminal.",
        epilog=EXIT_STATUS_HELP,
    )
    render.add_argument("scene", metavar="SCENE", help="scene file (TOML)")
    render.add_argument("-o", "--output", required=True, metavar="OUT.exr", help="the OpenEXR file to write")
    render.add_argument(
        "--aov", type=_aovs, default=("depth", "normal", "id"), metavar="LIST",
        help="comma-separated images to compute: depth,normal,id,zdepth,position,shaded "
        "(default: depth,normal,id); fewer is faster",
    )
    render.add_argument(
        "--png", action="store_true",
        help="also write a PNG preview of each image: OUT.depth.png and OUT.zdepth.png (near bright, far "
        "dark, misses black), OUT.normal.png (n*0.5+0.5), OUT.id.png (a colour per shape, misses black), "
        "OUT.shaded.png (clamped, sRGB)",
    )
    render.add_argument(
        "--precision", choices=("fp32", "fp64"), default="fp32",
        help="kernel precision (default fp32); fp64 depth and normals are stored in the EXR as 32-bit floats",
    )
    render.add_argument("--size", type=_size, metavar="WxH",
                        help="override the scene's image size (each side at most 65536)")
    render.add_argument("--time", type=_time, metavar="T", help="render the scene at time T (seconds) of its [animation]")
    render.add_argument(
        "--device", metavar="DEV",
        help="OpenCL device: P:D indices (see `pyclray devices`) or part of its name; default "
        "$PYOPENCL_CTX, else PoCL's CPU device",
    )
    from .animate import add_cluster_options

    add_cluster_options(render, "the image's bands of rows")
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


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("pyclray")
    except PackageNotFoundError:  # run from a checkout that is not installed
        from . import __version__

        return __version__


def _show_warning(command: str):
    def show(message, category, filename, lineno, file=None, line=None):
        print(f"pyclray {command}: warning: {message}", file=sys.stderr)

    return show


def main(argv=None) -> int:
    import warnings

    # Ctrl-C from here on is a KeyboardInterrupt, answered below (pyclray/__init__ answers it
    # while the package is imported)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    command = "?"
    try:
        from .errors import DeviceError, OutputError, PyclrayError, PyclrayWarning, SceneError

        parser = build_parser()
        args = parser.parse_args(argv)
        command = args.command
        with warnings.catch_warnings():
            warnings.simplefilter("default", PyclrayWarning)
            warnings.showwarning = _show_warning(command)
            return args.run(args)
    except (BadInput, SceneError, DeviceError, OutputError) as error:
        print(f"pyclray {command}: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except PyclrayError as error:
        print(f"pyclray {command}: error: {error}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    # run the package's module, not this __main__ copy: the commands raise pyclray.cli.BadInput
    from pyclray.cli import main as package_main

    sys.exit(package_main())
