"""The prepared scene's host arrays and their device buffers (a CPU device uses the arrays' own memory)."""
from __future__ import annotations

import numpy as np
import pyopencl as cl

ALIGNMENT = 128  # bytes: the kernels load a struct's double4 and float8 members with aligned vector loads


def aligned(array: np.ndarray) -> np.ndarray:
    """The array itself if contiguous and aligned to ALIGNMENT bytes, else an aligned copy."""
    if array.flags.c_contiguous and array.ctypes.data % ALIGNMENT == 0:
        return array
    raw = np.empty(array.nbytes + ALIGNMENT, np.uint8)
    start = -raw.ctypes.data % ALIGNMENT
    raw[start:start + array.nbytes] = np.ascontiguousarray(array).reshape(-1).view(np.uint8)  # padding too
    return raw[start:start + array.nbytes].view(array.dtype).reshape(array.shape)


def aligned_empty(shape, dtype) -> np.ndarray:
    """An uninitialized array aligned to ALIGNMENT bytes (numpy's large arrays start 16 bytes past a
    page: aligned() would copy each; docs/benchmarks.md, "Why the engine does what it does")."""
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape)) * dtype.itemsize
    raw = np.empty(nbytes + ALIGNMENT, np.uint8)
    start = -raw.ctypes.data % ALIGNMENT
    return raw[start:start + nbytes].view(dtype).reshape(shape)


def device_buffer(ctx, array: np.ndarray, writable: bool = False) -> cl.Buffer:
    """A device buffer of this array: the array's own memory on a CPU device (no copy: the array
    must be aligned, see aligned(), and live as long as the buffer), a copy elsewhere."""
    mf = cl.mem_flags
    access = mf.READ_WRITE if writable else mf.READ_ONLY
    if shares_host_memory(ctx):
        return cl.Buffer(ctx.context, access | mf.USE_HOST_PTR, hostbuf=array)
    return cl.Buffer(ctx.context, access | mf.COPY_HOST_PTR, hostbuf=array)


def shares_host_memory(ctx) -> bool:
    """Whether device_buffer's buffers are their arrays' own memory (a CPU device): a row written
    into the array while no command that uses the buffer is queued is what the next kernel reads."""
    return bool(ctx.device.type & cl.device_type.CPU)
