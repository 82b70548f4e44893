"""The prepared scene's host arrays and their device buffers (a CPU device uses the arrays' own memory)."""
from __future__ import annotations

import threading

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


class KeptBuffers:
    """A scene handle's device buffers by name, kept from call to call and grown (at least doubled)
    when a call needs more: a small cast writes its rays into them and reads its results out of them
    instead of making new buffers per call (a buffer's creation and its first use cost a device more
    than a cast of a few rays: docs/benchmarks.md, "The host path of a cast"). On a device that
    shares host memory (shares_host_memory) each is an aligned host array's own memory, which the
    call writes and reads itself (an enqueued copy cost PoCL 30 us each); elsewhere copies are
    enqueued. A call holds ``lock`` from its first write to its last read, so one call's results are
    read before the next writes."""

    SMALLEST = 256  # bytes
    MOST_CONSTANTS = 16

    def __init__(self):
        self.lock = threading.Lock()
        self.buffers: dict = {}  # name -> (buffer, its host array (uint8) or None)
        self.block_tables = None  # (engine/queries/cast.py: _block_lanes_table)
        self.device_kernels = None  # (engine/queries/cast_device.py: DeviceKernels)
        self.label_table = None  # (engine/queries/cast_device.py: _label_table)
        self.lane_primitives = None  # (engine/queries/cast.py: _lane_primitives)
        self.constants: dict = {}  # small read-only buffers by their bytes (constant)
        self.launches: dict = {}  # kernel -> the arguments it was last launched with (device.py: launch_kept)
        self.cut = None  # (buffer, sizes, sub-buffers): regions' last cut

    def get(self, ctx, name: str, nbytes: int) -> tuple:
        """(buffer, host): the buffer called name, of at least nbytes (read and written by the
        kernels), and where it is host memory its bytes as an array (uint8), else None."""
        kept = self.buffers.get(name)
        if kept is None or kept[0].size < nbytes:
            size = max(nbytes, self.SMALLEST, 2 * kept[0].size if kept is not None else 0)
            if shares_host_memory(ctx):
                host = aligned_empty((size,), np.uint8)
                buffer = cl.Buffer(ctx.context, cl.mem_flags.READ_WRITE | cl.mem_flags.USE_HOST_PTR, hostbuf=host)
            else:
                host, buffer = None, cl.Buffer(ctx.context, cl.mem_flags.READ_WRITE, size)
            kept = self.buffers[name] = (buffer, host)
        return kept

    def write(self, ctx, name: str, array: np.ndarray) -> cl.Buffer:
        """The buffer called name with array's bytes at its start: copied into its host memory
        (no command that uses it is queued: the lock), else by a copy enqueued (the caller waits for
        its results, after which the array may go)."""
        array = np.ascontiguousarray(array)
        buffer, host = self.get(ctx, name, array.nbytes)
        if host is not None:
            host[:array.nbytes] = array.reshape(-1).view(np.uint8)
        else:
            cl.enqueue_copy(ctx.queue, buffer, array, is_blocking=False)
        return buffer

    def read(self, ctx, name: str, out: np.ndarray) -> None:
        """Into out, the first out.nbytes bytes of the buffer called name, the kernel that writes it
        done: from its host memory (a CPU device's kernel wrote the array itself), else by a copy
        enqueued (current after the queue's finish)."""
        buffer, host = self.buffers[name]
        if host is not None:
            out.reshape(-1).view(np.uint8)[:] = host[:out.nbytes]
        else:
            cl.enqueue_copy(ctx.queue, out, buffer, is_blocking=False)

    def clear(self) -> None:
        self.buffers.clear()
        self.block_tables = None  # (engine/queries/cast.py: _block_lanes_table)
        self.label_table = None
        self.lane_primitives = None
        self.constants.clear()
        self.launches.clear()
        self.cut = None

    def regions(self, ctx, name: str, sizes: tuple) -> tuple:
        """(sub-buffers, offsets, total): the buffer called name cut into consecutive regions, one per
        (part, nbytes) of sizes, each starting at a multiple of the device's base address alignment
        (at least ALIGNMENT bytes), so that a call's results, written by several kernels, come back
        in one copy of its first total bytes (read). The last cut is kept (the same sizes: the same
        sub-buffers, whose kernel arguments then stay set)."""
        align = max(ctx.device.mem_base_addr_align // 8, ALIGNMENT)
        offsets, total = {}, 0
        for part, nbytes in sizes:
            offsets[part] = total
            total += -(-max(nbytes, 1) // align) * align
        buffer, _ = self.get(ctx, name, total)
        cut = self.cut
        if cut is None or cut[0] is not buffer or cut[1] != sizes:
            subs = {part: buffer.get_sub_region(offsets[part], max(nbytes, 1)) for part, nbytes in sizes}
            cut = self.cut = (buffer, sizes, subs)
        return cut[2], offsets, total

    def constant(self, ctx, values: np.ndarray) -> cl.Buffer:
        """A read-only buffer of a few values (one tmin, one tmax, an unused order), kept by their
        bytes: a later call with the same values copies nothing (MOST_CONSTANTS kept)."""
        key = (values.dtype.str, values.tobytes())
        buffer = self.constants.get(key)
        if buffer is None:
            if len(self.constants) >= self.MOST_CONSTANTS:
                self.constants.clear()
            buffer = self.constants[key] = cl.Buffer(ctx.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                                                     hostbuf=np.ascontiguousarray(values))
        return buffer

    def nbytes(self) -> int:
        return sum(buffer.size for buffer, _ in self.buffers.values())
