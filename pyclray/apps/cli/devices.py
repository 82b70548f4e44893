"""`pyclray devices`: the OpenCL devices and their selectors."""
from __future__ import annotations

from .options import BadInput


def run(args) -> int:
    from ...engine.opencl.device import list_devices

    devices = list_devices()
    if not devices:
        raise BadInput("no OpenCL device found: install a driver, e.g. pip install 'pyopencl[pocl]'")
    for d in devices:
        mark = "*" if d["default"] else " "
        fp64 = "fp64" if d["fp64"] else "no fp64"
        print(f"{mark} {d['selector']:>5}  {d['platform']} / {d['device']} ({d['type']}, {d['compute_units']} units, {fp64})")
    print("* the default; select another with --device P:D (or a part of its name) or PYOPENCL_CTX=P:D")
    return 0


def add_command(commands) -> None:
    devices = commands.add_parser("devices", help="list the OpenCL devices", description="List the OpenCL devices and their selectors.")
    devices.set_defaults(run=run)
