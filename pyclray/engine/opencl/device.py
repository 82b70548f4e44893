"""OpenCL devices, their contexts and queues, and launching a kernel."""
from __future__ import annotations

import itertools
import os
import threading
from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from ...model.errors import DeviceError
from .pocl_cpu import is_pocl_cpu, name_known_cpu  # (is_pocl_cpu: the engine asks it here)

INSTALL_HINT = "install an OpenCL driver, e.g. `pip install 'pyopencl[pocl]'` for PoCL on the CPU"

_lock = threading.Lock()
_launch_lock = threading.Lock()  # see launch
_contexts: dict = {}


# -- devices ---------------------------------------------------------------------------------
def _platforms():
    try:
        return cl.get_platforms()
    except cl.LogicError:  # no ICD loader platform at all
        return []


def all_devices() -> list[tuple[str, cl.Device]]:
    """Every device as ("platform:device" index, device)."""
    out = []
    for p, platform in enumerate(_platforms()):
        try:
            devices = platform.get_devices()
        except cl.Error:
            continue
        out += [(f"{p}:{d}", device) for d, device in enumerate(devices)]
    return out


def has_fp64(device: cl.Device) -> bool:
    return "cl_khr_fp64" in device.extensions.split() or bool(getattr(device, "double_fp_config", 0))


def describe(device: cl.Device) -> str:
    return f"{device.platform.name.strip()} / {device.name.strip()}"


def select_device(spec: str | None = None) -> cl.Device:
    """The device to use: ``spec`` ("P:D" indices as in PYOPENCL_CTX, "P", or part of the
    platform or device name), else $PYOPENCL_CTX, else PoCL's CPU device, else the first device."""
    devices = all_devices()
    if not devices:
        raise DeviceError(f"no OpenCL platform or device found: {INSTALL_HINT}")
    if spec is None:
        spec = os.environ.get("PYOPENCL_CTX") or None
        if spec is None:
            for _, device in devices:
                if "portable computing language" in device.platform.name.lower():
                    return device
            return devices[0][1]
    spec = str(spec).strip()
    if ":" in spec or spec.isdigit():
        p, _, d = spec.partition(":")
        for index, device in devices:
            ip, idev = index.split(":")
            if ip == p and (d in ("", idev)):
                return device
    else:
        for _, device in devices:
            if spec.lower() in describe(device).lower():
                return device
    known = "; ".join(f"{index} = {describe(device)}" for index, device in devices)
    raise DeviceError(f"no OpenCL device matches {spec!r} (devices: {known})")


@dataclass
class DeviceContext:
    device: cl.Device
    context: cl.Context
    queue: cl.CommandQueue


def context_for(device: cl.Device | str | None = None) -> DeviceContext:
    if not isinstance(device, cl.Device):
        device = select_device(device)
    key = device.int_ptr
    with _lock:
        if key not in _contexts:
            name_known_cpu(device)  # PoCL on a CPU newer than its LLVM (engine/opencl/pocl_cpu.py)
            context = cl.Context([device])
            _contexts[key] = DeviceContext(device, context, cl.CommandQueue(context, device))
        return _contexts[key]


# -- the device's class -------------------------------------------------------------------------
# A device of the GPU class runs many work-items in lock-step over memory the host reaches through
# copies: there a cast's host path does nothing per ray (engine/queries/cast_device.py: the rays
# uploaded once, checked on the device, cast in their order, the results read back once). The one
# property that decides it: the device's type (not a CPU). $PYCLRAY_GPU_CLASS=1 takes that path on
# any device (the tests force it on PoCL), =0 the CPU's host path.
GPU_CLASS_VARIABLE = "PYCLRAY_GPU_CLASS"


def gpu_class(device: cl.Device) -> bool:
    """Whether the device is of the GPU class (see GPU_CLASS_VARIABLE)."""
    value = os.environ.get(GPU_CLASS_VARIABLE, "").strip()
    if value:
        if value not in ("0", "1"):
            raise DeviceError(f"{GPU_CLASS_VARIABLE}: expected 1 (the GPU's host path) or 0 (the CPU's), got {value!r}")
        return value == "1"
    return not device.type & cl.device_type.CPU


def launch(ctx: DeviceContext, kernel: cl.Kernel, global_size, local_size, args) -> cl.Event:
    """Enqueue the kernel over these arguments. pyopencl sets a numpy scalar argument (a number, or a
    struct such as a double4) through its slow generic path; declared once per kernel as scalar types (a
    kernel's arguments keep their types), its invoker packs them quickly (docs/benchmarks.md, "Why the
    engine does what it does"). A kernel object is shared by every render of its variant, and OpenCL's
    argument setting is not thread-safe: setting the arguments and enqueueing happen under one lock (the
    kernel then runs on its own; the lock is held for the enqueue only)."""
    with _launch_lock:
        _declare_scalars(kernel, args)
        kernel._pyclray_setter = None  # its arguments' record (launch_kept): none
        return kernel(ctx.queue, global_size, local_size, *args)  # its event (bench/cast_host.py profiles it)


def _declare_scalars(kernel: cl.Kernel, args) -> None:
    if not getattr(kernel, "_pyclray_scalar_types_set", False):
        kernel.set_scalar_arg_dtypes([a.dtype if isinstance(a, np.generic) and a.dtype.kind in "iufV" else None for a in args])
        kernel._pyclray_scalar_types_set = True


_setters = itertools.count(1)


def launch_kept(ctx: DeviceContext, kernel: cl.Kernel, global_size, local_size, args, record: dict) -> cl.Event:
    """launch, but where the kernel's arguments are those it was last launched with, by a call with
    this record (a scene handle's kept buffers': kernel -> (setter, arguments)) and by no launch since,
    they are not set again: a small cast's kernel reads the same kept buffers, scene inputs and
    counts from call to call, and setting its 23 arguments cost more than a third of PoCL's launch
    (docs/benchmarks.md, "The host path of a cast"). Arguments compare equal where each is the same
    buffer or an equal number; the record holds them (none is freed and its handle reused meanwhile)."""
    args = tuple(args)
    with _launch_lock:
        last = record.get(kernel)
        setter = getattr(kernel, "_pyclray_setter", None)
        if last is not None and setter is not None and last[0] == setter and last[1] == args:
            return cl.enqueue_nd_range_kernel(ctx.queue, kernel, global_size, local_size)
        _declare_scalars(kernel, args)
        event = kernel(ctx.queue, global_size, local_size, *args)
        kernel._pyclray_setter = next(_setters)
        record[kernel] = (kernel._pyclray_setter, args)
        return event


def list_devices() -> list[dict]:
    """Every OpenCL device: its selector, names, type, compute units, fp64 support, and whether it is the default."""
    try:
        default = select_device().int_ptr
    except DeviceError:
        default = None
    return [
        {
            "selector": index,
            "platform": device.platform.name.strip(),
            "device": device.name.strip(),
            "type": cl.device_type.to_string(device.type),
            "compute_units": device.max_compute_units,
            "fp64": has_fp64(device),
            "default": device.int_ptr == default,
        }
        for index, device in all_devices()
    ]
