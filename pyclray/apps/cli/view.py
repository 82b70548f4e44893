"""`pyclray view`: the scene in the browser, live (pyclray/apps/view): orbit, pan and dolly with the
mouse, any image, the animation's time, and the scene file watched for edits."""
from __future__ import annotations

import argparse

from .options import BadInput, image_size, load
from .texts import EXIT_STATUS_HELP


def port(text: str) -> int:
    try:
        value = int(text)
        if not 0 <= value < 65536:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port 0 to 65535 (0: any free one), got {text!r}") from None
    return value


def view_aov(text: str) -> str:
    from ..view.frames import AOVS

    if text not in AOVS:
        raise argparse.ArgumentTypeError(f"expected one of {', '.join(AOVS)}, got {text!r}")
    return text


def run(args) -> int:
    import asyncio
    from importlib.util import find_spec

    for module, package in (("websockets", "websockets"), ("PIL", "Pillow")):  # the server, the images
        if find_spec(module) is None:
            raise BadInput(f"pyclray view needs {package}: pip install 'pyclray[view]'")
    from ..view.server import App, ListenError

    scene = load(args.scene, args.size)  # a bad scene is one line and exit 2, before anything is served
    app = App(args.scene, scene, args.aov, args.size)
    try:
        return asyncio.run(app.serve(args.port, not args.no_browser))
    except ListenError as error:  # the port is taken, or not ours to take
        raise BadInput(f"--port {args.port}: {error}") from None


def add_command(commands) -> None:
    view = commands.add_parser(
        "view",
        help="show a scene in the browser, live: orbit, pan, dolly, any image, the animation's time; edits reload",
        description="Serve SCENE's view on 127.0.0.1 and open it in the browser: left drag orbits about the "
        "target, right or shift + left drag pans, the wheel dollies, r restores the scene's camera, h shows "
        "the keys. Saving the scene file shows the new scene (keeping your camera unless the file's camera "
        "changed); a bad edit shows its error on the page and keeps the last image. Prints the URL (with its "
        "access token) on one line; Ctrl-C ends it. For a remote machine, forward the port over SSH "
        "(ssh -L PORT:127.0.0.1:PORT host) rather than opening it.",
        epilog=EXIT_STATUS_HELP,
    )
    view.add_argument("scene", metavar="SCENE", help="scene file (TOML, or Mitsuba 3 XML)")
    view.add_argument("--aov", type=view_aov, default="shaded", metavar="NAME",
                      help="the image shown first: shaded (default), depth, zdepth, normal, id, primitive or label")
    view.add_argument("--size", type=image_size, metavar="WxH", help="override the scene's image size")
    view.add_argument("--port", type=port, default=0, help="the port to listen on (default 0: any free one)")
    view.add_argument("--no-browser", action="store_true", help="print the URL, do not open a browser")
    view.set_defaults(run=run)
