"""A kernel's run on the device: its input buffers, the output buffers that become the returned
arrays (straight into them on a CPU device, through a scene handle's kept buffers elsewhere), and the
launch."""
from __future__ import annotations

import threading

import numpy as np
import pyopencl as cl

from ...model.aovs import TABLE
from ..opencl.device import launch
from .programs import kernel_for
from .signatures import arguments, image_parameter

REAL = {"fp32": np.float32, "fp64": np.float64}  # the numpy type of a precision


def input_buffer(ctx, array):
    return cl.Buffer(ctx.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)


class OutputBuffers:
    """A scene handle's device buffers for the images of its renders on devices other than CPUs,
    kept per image and size and reused by every render: its renders take ``lock`` from the launch to
    the copies out, so one render's images are read before the next writes them. The lock is theirs
    alone: a render takes it inside the prepared scene's lock, which a handle's update takes inside
    the handle's."""

    MOST = 12

    def __init__(self):
        self.lock = threading.Lock()
        self.buffers: dict = {}

    def get(self, ctx, count: int, aovs, precision: str) -> list:
        buffers = []
        for aov in aovs:
            key = (aov, max(count * TABLE[aov].itemsize(precision), 1))
            buffer = self.buffers.get(key)
            if buffer is None:
                if len(self.buffers) >= self.MOST:
                    self.buffers.clear()
                buffer = self.buffers[key] = cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY, key[1])
            buffers.append(buffer)
        return buffers

    def nbytes(self) -> int:
        return sum(buffer.size for buffer in self.buffers.values())


def _with_images(args: dict, aovs, buffers) -> dict:
    """The kernel's arguments by name: args and each image's buffer."""
    return {**args, **{image_parameter(aov): buffer for aov, buffer in zip(aovs, buffers)}}


def _zero_copy(ctx) -> bool:
    """Whether the kernel writes the images straight into the returned arrays (CPU devices)."""
    return bool(ctx.device.type & cl.device_type.CPU)


def run_kernel(ctx, variant, args: dict, global_size, count, aovs, precision, shape_prefix, kept: OutputBuffers,
               local_size=None):
    """Enqueue the kernel with output buffers for the asked images and read them back into new arrays."""
    return enqueue_kernel(ctx, variant, args, global_size, count, aovs, precision, shape_prefix, kept, local_size).result()


class Pending:
    """A kernel's run in flight: result() waits for it (for it only: the work enqueued after it on the
    device's in-order queue may still run) and returns its images, AOV name -> array."""

    def __init__(self, images: dict, done=(), keep=()):
        self.images = images
        self.done = list(done)  # the events after which the images are current
        self.keep = keep  # what must live until then (the output buffers, uploads of host arrays)

    def result(self) -> dict:
        if self.done:
            cl.wait_for_events(self.done)
            self.done, self.keep = [], ()
        return self.images


def enqueue_kernel(ctx, variant, args: dict, global_size, count, aovs, precision, shape_prefix, kept: OutputBuffers,
                   local_size=None) -> Pending:
    """Enqueue the kernel with output buffers for the asked images, new arrays (see Pending). args:
    the kernel's other arguments by parameter name (engine/launch/signatures.py); on devices other than
    CPUs the images go through the handle's kept buffers."""
    outputs = {k: TABLE[k].empty((count,), precision) for k in aovs}
    images = {k: v.reshape(shape_prefix + v.shape[1:]) for k, v in outputs.items()}
    kernel = kernel_for(ctx, variant)
    if _zero_copy(ctx):
        # a CPU device writes straight into the new arrays (USE_HOST_PTR: PoCL uses them as the
        # buffers' memory), then a map and an unmap, enqueued behind the kernel, make them current as
        # OpenCL requires: no copy of the images, and nothing to wait for but the unmaps (a view
        # enqueued next runs on while its images are returned, engine/queries/render.py: render_views)
        flags = cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR
        buffers = [cl.Buffer(ctx.context, flags, hostbuf=array) for array in outputs.values()]
        launch(ctx, kernel, global_size, local_size, arguments(variant, _with_images(args, aovs, buffers)))
        maps = [
            cl.enqueue_map_buffer(ctx.queue, buffer, cl.map_flags.READ, 0, array.shape, array.dtype, is_blocking=False)[0]
            for array, buffer in zip(outputs.values(), buffers)
        ]
        unmaps = [mapped.base.release() for mapped in maps]
        ctx.queue.flush()  # the device starts on it now
        return Pending(images, unmaps, (buffers, maps))
    # other devices: device buffers kept and reused, and a copy of each image
    with kept.lock:
        buffers = kept.get(ctx, count, aovs, precision)
        launch(ctx, kernel, global_size, local_size, arguments(variant, _with_images(args, aovs, buffers)))
        for array, buffer in zip(outputs.values(), buffers):
            cl.enqueue_copy(ctx.queue, array, buffer, is_blocking=False)
        ctx.queue.finish()
    return Pending(images)
