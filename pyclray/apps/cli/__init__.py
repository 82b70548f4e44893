"""The command line: pyclray render | devices | check | stability | animate | view | export | scan | sample | dataset, one module per command.

Exit status: 0 success; 1 a check outside its tolerance, or an unexpected error; 2 bad input (a
scene, an option) or an output that cannot be written, reported as one line on stderr, with no
file replaced; 130 interrupted (Ctrl-C), quietly, with no file replaced.
"""
from __future__ import annotations

import argparse
import signal
import sys

from .options import BadInput, Parser
from .texts import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_STATUS_HELP

# one module per command, each with add_command(subparsers); each imports its heavy parts lazily
COMMANDS = ("render", "devices", "check", "stability", "animate", "view", "export", "scan", "sample", "dataset")


def build_parser() -> argparse.ArgumentParser:
    from importlib import import_module

    parser = Parser(
        prog="pyclray",
        description="pyclray: an exact OpenCL ray caster. It renders depth, normal, id, label and shaded images "
        "of scenes of planes, spheres, cylinders, disks, rectangles, boxes, batches of spheres and triangle meshes described in "
        "TOML files (or Mitsuba 3 XML scenes).",
        epilog=EXIT_STATUS_HELP,
    )
    parser.add_argument("--version", action="version", version=f"pyclray {_version()}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        import_module(f"{__package__}.{name}").add_command(commands)
    for command in commands.choices.values():  # every command's help ends with the same exit statuses
        command.epilog = EXIT_STATUS_HELP
    return parser


def _subparser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return commands.choices[command]


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("pyclray")
    except PackageNotFoundError:  # run from a checkout that is not installed
        from ...version import __version__

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
        from ...model.errors import DeviceError, OutputError, PyclrayError, PyclrayWarning, RequestError, SceneError

        parser = build_parser()
        args, unknown = parser.parse_known_args(argv)
        command = args.command
        if unknown:  # named by the command's parser: `pyclray render: error: ...`, not `pyclray: ...`
            _subparser(parser, command).error(f"unrecognized arguments: {' '.join(unknown)}")
        with warnings.catch_warnings():
            warnings.simplefilter("default", PyclrayWarning)
            warnings.showwarning = _show_warning(command)
            return args.run(args)
    except (BadInput, SceneError, RequestError, DeviceError, OutputError) as error:  # (RequestError: a bad option's value)
        print(f"pyclray {command}: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except PyclrayError as error:
        print(f"pyclray {command}: error: {error}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    # run the package's module, not this __main__ copy: the commands raise pyclray.apps.cli.options.BadInput
    from pyclray.apps.cli import main as package_main

    sys.exit(package_main())
