"""A request's run on the device: the Frame it returns, the checks of its AOVs and precision, and
the kernel's launch over output buffers that become the returned arrays."""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..model.aovs import AOVS, TABLE
from ..model.errors import DeviceError, RequestError
from ..model.layout import PRECISIONS
from .device import DeviceContext, has_fp64, launch
from .programs import kernel_for
from .signatures import arguments, image_parameter

REAL = {"fp32": np.float32, "fp64": np.float64}  # the numpy type of a precision


class Frame(dict):
    """The images of a render (or the per-ray results of a cast): AOV name -> numpy array.

    depth: distance from the ray origin along the unit ray, +inf on a miss (float32; float64 with
    precision "fp64"); normal: unit world normal, (0, 0, 0) on a miss; id: int32, -1 on a miss.
    Renders may add zdepth (depth along the optical axis, +inf on a miss), position (world hit
    point, (0, 0, 0) on a miss), shaded (linear RGB, the background on a miss) and label (int32, the
    hit shape's label, -1 on a miss or for a shape without one).

    A render's frame also holds its camera as the vision tools take it: ``intrinsics`` (K, 3x3, in
    pixels of these images: a window's principal point is shifted by its corner) and ``pose`` (4x4
    camera-to-world), OpenCV's convention (x right, y down, z forward), so that
    pose @ [depth * normalize(K^-1 [i + 0.5, j + 0.5, 1]), 1] is pixel (j, i)'s hit point; None
    for a cast's.
    """

    def __init__(self, arrays, *, precision: str, device: str, intrinsics=None, pose=None, view=None):
        super().__init__(arrays)
        self.precision = precision
        self.device = device
        # view: (camera, width, height, col0, row0) of a render, whose intrinsics and pose are
        # computed when first asked for (a noticeable share of a warm render)
        self._camera = {"intrinsics": intrinsics, "pose": pose} if view is None else None
        self._view = view

    def _camera_of_view(self) -> dict:
        if self._camera is None:
            self._camera = frame_camera(*self._view)
        return self._camera

    @property
    def intrinsics(self):
        return self._camera_of_view()["intrinsics"]

    @intrinsics.setter
    def intrinsics(self, value):
        self._camera = {**self._camera_of_view(), "intrinsics": value}

    @property
    def pose(self):
        return self._camera_of_view()["pose"]

    @pose.setter
    def pose(self, value):
        self._camera = {**self._camera_of_view(), "pose": value}

    def __repr__(self) -> str:
        shapes = ", ".join(f"{k}: {v.dtype}{list(v.shape)}" for k, v in self.items())
        return f"Frame({shapes}; {self.precision} on {self.device})"


def check_request(aovs, precision: str, ctx: DeviceContext, known=AOVS) -> tuple[str, ...]:
    if isinstance(aovs, str):
        aovs = tuple(a.strip() for a in aovs.split(","))
    try:
        aovs = tuple(aovs)
    except TypeError:
        raise RequestError(f"aovs: expected a selection of {', '.join(known)}, got {type(aovs).__name__}") from None
    unknown = [a for a in aovs if not isinstance(a, str) or a not in known]
    if unknown or not aovs or len(set(aovs)) != len(aovs):
        raise RequestError(f"aovs: expected a non-empty selection of {', '.join(known)} without repeats, got {', '.join(a if isinstance(a, str) and a.isprintable() else repr(a) for a in aovs) or 'none'}")
    check_precision(precision, ctx)
    return tuple(a for a in known if a in aovs)  # canonical order: one program per set


def check_precision(precision: str, ctx: DeviceContext | None = None) -> str:
    """The precision's name, and (given a device) that the device has what it needs."""
    if not isinstance(precision, str) or precision not in PRECISIONS:
        raise RequestError(f"precision: expected one of {', '.join(PRECISIONS)}, got {precision!r}")
    if ctx is not None and precision == "fp64" and not has_fp64(ctx.device):
        raise DeviceError(
            f"precision fp64 needs the cl_khr_fp64 extension, which {ctx.device.name.strip()} lacks; "
            "use precision fp32 or another device"
        )
    return precision


def frame_camera(camera, width: int, height: int, col0: int = 0, row0: int = 0) -> dict:
    """The intrinsics and pose of a Frame (see Frame) of the window of a width x height image from
    column col0 and row row0 on."""
    K = camera.intrinsics(width, height)
    K[0, 2] -= col0
    K[1, 2] -= row0
    return {"intrinsics": K, "pose": camera.pose()}


def input_buffer(ctx, array):
    return cl.Buffer(ctx.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)


class OutputBuffers:
    """A scene handle's device buffers for the images of its renders on devices other than CPUs,
    kept per image and size and reused by every render: its renders take ``lock`` from the launch to
    the copies out, so one render's images are read before the next writes them."""

    MOST = 12

    def __init__(self, lock):
        self.lock = lock
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
    the kernel's other arguments by parameter name (engine/signatures.py); on devices other than
    CPUs the images go through the handle's kept buffers."""
    outputs = {k: TABLE[k].empty((count,), precision) for k in aovs}
    images = {k: v.reshape(shape_prefix + v.shape[1:]) for k, v in outputs.items()}
    kernel = kernel_for(ctx, variant)
    if _zero_copy(ctx):
        # a CPU device writes straight into the new arrays (USE_HOST_PTR: PoCL uses them as the
        # buffers' memory), then a map and an unmap, enqueued behind the kernel, make them current as
        # OpenCL requires: no copy of the images, and nothing to wait for but the unmaps (a view
        # enqueued next runs on while its images are returned, engine/render.py: render_views)
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
