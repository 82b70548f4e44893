"""PoCL 3.0 on a CPU its LLVM 14 calls "generic" (engine/opencl/pocl_cpu.py): pyclray names the x86-64 level
the CPU's flags allow, so that every program builds; a CPU PoCL knows is left as it is."""
from __future__ import annotations

from types import SimpleNamespace

import pyopencl as cl

import pyclray
from pyclray.engine.opencl import pocl_cpu
from pyclray.engine.opencl.device import context_for, is_pocl_cpu


def test_the_level_is_one_llvm_14_knows():
    assert pocl_cpu._level() in (b"x86-64", b"x86-64-v2", b"x86-64-v3")


def test_the_default_device_builds_and_is_named_only_where_pocl_called_it_generic():
    """On a CPU newer than PoCL's LLVM (its HSTR ends in "generic") the device is named and a program
    builds from source; elsewhere nothing is changed."""
    device = context_for(None).device
    generic = is_pocl_cpu(device) and "-generic" in device.version
    assert (pocl_cpu.named_cpu(device) is not None) == generic
    if generic:
        assert pocl_cpu.named_cpu(device) == pocl_cpu._level().decode()
    scene = pyclray.load_scene("scenes/tp02.toml").with_size(8, 8)
    assert (pyclray.render(scene, aovs=("depth",))["depth"] > 0).all()


def test_other_devices_are_not_touched():
    """A GPU, another platform's CPU, or a PoCL CPU whose HSTR names a known CPU: no memory is read."""
    for name, kind, version in (("NVIDIA CUDA", cl.device_type.GPU, "OpenCL 3.0 CUDA"),
                                ("Intel(R) OpenCL", cl.device_type.CPU, "OpenCL 3.0 (Build 0)"),
                                ("Portable Computing Language", cl.device_type.CPU,
                                 "OpenCL 3.0 PoCL HSTR: pthread-x86_64-unknown-linux-gnu-znver3")):
        device = SimpleNamespace(platform=SimpleNamespace(name=name), type=kind, version=version, int_ptr=8)
        assert pocl_cpu.name_known_cpu(device) is False
        assert pocl_cpu.named_cpu(device) is None
