"""PoCL 3.0 on a CPU that its LLVM 14 does not know (AMD Zen 5, family 26): name a CPU it knows.

PoCL asks LLVM for the host's CPU name and passes it to its OpenCL C compiler as ``-target-cpu``.
LLVM 14 names a CPU newer than itself "generic", which its C front end then refuses for x86-64:
every build fails with "unknown target CPU 'generic'" and nothing renders (seen on this project's
machines when they moved from Zen 4 to Zen 5). PoCL has no option or variable to override the
name (its build options are a fixed list), so pyclray sets it where PoCL keeps it: the device's
``llvm_cpu`` string, a field of PoCL's device struct, read by every later build.

The replacement is the x86-64 micro-architecture level the CPU's flags allow, at most
``x86-64-v3`` (AVX2 and FMA): what LLVM 14 compiled for the Zen 4 machines before (``znver3``, AVX2;
it compiles no 512-bit vectors for these kernels, see programs.MAX_LANE_BITS), so the programs are
those of before. The field is found by value, not by a layout: the one pointer among the struct's
128 words whose string is "generic", read through /proc/self/mem (a bad address is an error there,
not a crash). Anything unexpected (no such pointer, more than one, not Linux) leaves the
device as it is, and its builds report the compiler's error as ever.

PoCL keeps failed builds in its own cache (~/.cache/pocl) under a key that does not depend on that
name: the programs built for the named CPU say so in their first line (programs.py), so that a
failure cached by an earlier pyclray, before the name was set, is never found again.
"""
from __future__ import annotations

import ctypes
import os
import struct

import pyopencl as cl

_SCAN_WORDS = 128  # PoCL 3.0's device struct is 1,032 bytes (its field is word 80); the heap goes on after it
_patched: dict = {}  # device pointer -> the replacement name's buffer (kept alive: PoCL reads it)


def is_pocl_cpu(device: cl.Device) -> bool:
    """PoCL's CPU device (its built-ins are not inlined into kernels: see kernels/lanes.h)."""
    return "portable computing language" in device.platform.name.lower() and bool(device.type & cl.device_type.CPU)


def _level() -> bytes:
    """The x86-64 level this CPU's flags allow, at most v3."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as cpuinfo:
            flags = next((line.split(":", 1)[1].split() for line in cpuinfo if line.startswith("flags")), [])
    except OSError:
        flags = []
    flags = set(flags)
    if {"avx2", "fma", "bmi2", "movbe"} <= flags:
        return b"x86-64-v3"
    if {"sse4_2", "popcnt", "ssse3"} <= flags:
        return b"x86-64-v2"
    return b"x86-64"


def named_cpu(device: cl.Device) -> str | None:
    """The CPU name given to this device (name_known_cpu), or None where it has its own."""
    name = _patched.get(device.int_ptr)
    return None if name is None else name.value.decode()


def name_known_cpu(device: cl.Device) -> bool:
    """Give PoCL's CPU device a CPU name its compiler knows where LLVM called the host "generic"
    (see the module's docstring). True if the device was changed (now or before)."""
    if not is_pocl_cpu(device):
        return False
    key = device.int_ptr
    if key in _patched:
        return True
    if not device.version.rstrip().endswith("-generic") and "-generic " not in device.version:
        return False  # PoCL's HSTR names the CPU it compiles for: a known one needs nothing
    try:
        fd = os.open("/proc/self/mem", os.O_RDONLY)
    except OSError:
        return False
    try:
        raw = b""
        while len(raw) < 8 * _SCAN_WORDS:  # page by page: the struct may end a mapping (then the rest fails)
            try:
                raw += os.pread(fd, 4096 - (key + len(raw)) % 4096, key + len(raw))
            except OSError:
                break
        raw = raw[: 8 * _SCAN_WORDS]
        found = []
        for index, word in enumerate(struct.unpack(f"<{len(raw) // 8}Q", raw)):
            if 0x10000 < word < 1 << 47:
                try:
                    text = os.pread(fd, 8, word)
                except OSError:
                    continue
                if text == b"generic\0":
                    found.append(index)
    finally:
        os.close(fd)
    if len(found) != 1:
        return False
    name = ctypes.create_string_buffer(_level())
    ctypes.c_uint64.from_address(key + 8 * found[0]).value = ctypes.addressof(name)
    _patched[key] = name
    return True
