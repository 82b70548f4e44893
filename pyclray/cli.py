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


def _aovs(text: str) -> tuple[str, ...]:
    from .device import RENDER_AOVS

    names = tuple(a.strip() for a in text.split(",") if a.strip())
    bad = [a for a in names if a not in RENDER_AOVS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list of {', '.join(RENDER_AOVS)}, got {text!r}")
    return names


def _load(path: str, size=None):
    from .scene import load_scene

    scene = load_scene(path)
    return scene.with_size(*size) if size else scene


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
    scene = _load(args.scene, args.size)
    previews = output.preview_paths(out, args.aov) if args.png else {}
    start = time.perf_counter()
    frame = render(scene, aovs=args.aov, precision=args.precision, device=args.device)
    elapsed = time.perf_counter() - start
    written = [out]
    # every file goes to a temporary name first; all are renamed only once all are written
    with ExitStack() as stack:
        tmp = stack.enter_context(output.atomic_path(out))
        output.write_exr(tmp, frame, comment=f"pyclray render of {args.scene}")
        for name, path in previews.items():
            if name in frame:
                png = stack.enter_context(output.atomic_path(path))
                output.write_png(png, output.PREVIEWS[name](frame[name]))
                written.append(path)
    channels = ", ".join(output.exr_channels(frame))
    print(
        f"rendered {args.scene} ({scene.image.width}x{scene.image.height}, {args.precision}, "
        f"{frame.device}) in {elapsed * 1e3:.1f} ms; wrote {', '.join(map(str, written))} [{channels}]"
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
        epilog="Bad input prints one line naming the file, table and key, and exits with status 2.",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    render = commands.add_parser(
        "render",
        help="render a scene to a multi-channel OpenEXR file (and PNG previews)",
        description="Render SCENE with one ray per pixel centre and write one OpenEXR file with "
        "the channels Z (distance from the eye, inf on a miss), N.X N.Y N.Z (unit world normal, "
        "0 on a miss), id (UINT holding the int32 shape id; 4294967295 = -1 on a miss), and as asked "
        "zdepth (depth along the optical axis), P.X P.Y P.Z (world hit point) and R G B (shaded, linear).",
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
    render.add_argument("--precision", choices=("fp32", "fp64"), default="fp32", help="kernel precision (default fp32)")
    render.add_argument("--size", type=_size, metavar="WxH", help="override the scene's image size")
    render.add_argument(
        "--device", metavar="DEV",
        help="OpenCL device: P:D indices (see `pyclray devices`) or part of its name; default "
        "$PYOPENCL_CTX, else PoCL's CPU device",
    )
    render.set_defaults(run=cmd_render)

    devices = commands.add_parser("devices", help="list the OpenCL devices", description="List the OpenCL devices and their selectors.")
    devices.set_defaults(run=cmd_devices)

    for extra in _extra_commands():
        extra(commands)
    return parser


# modules that add a subcommand with add_command(subparsers); each imports its heavy parts lazily
COMMAND_MODULES = ("check", "stability")


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
    sys.exit(main())
