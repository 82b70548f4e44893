"""A request's run on the device: the Frame it returns, the checks of its AOVs and precision, the
camera's struct, and the kernel's launch over output buffers that become the returned arrays."""
from __future__ import annotations

import threading

import numpy as np
import pyopencl as cl

from ..model.aovs import AOVS, TABLE
from ..model.errors import DeviceError, RequestError
from ..model.layout import CAMERA, PRECISIONS, layout
from .device import DeviceContext, has_fp64, launch
from .programs import kernel_for
from .signatures import arguments, image_parameter

REAL = {"fp32": np.float32, "fp64": np.float64}  # the numpy type of a precision
_OUTPUTS_MAX = 12
_outputs: dict = {}
# renders that reuse the kept output buffers (devices other than CPUs) run one at a time; the
# caches of prepared inputs take it too
render_lock = threading.RLock()


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
        # computed when first asked for (a warm render of tp02 takes a millisecond: they took 30 us)
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
    if not isinstance(precision, str) or precision not in PRECISIONS:
        raise RequestError(f"precision: expected one of {', '.join(PRECISIONS)}, got {precision!r}")
    if precision == "fp64" and not has_fp64(ctx.device):
        raise DeviceError(
            f"precision fp64 needs the cl_khr_fp64 extension, which {ctx.device.name.strip()} lacks; "
            "use precision fp32 or another device"
        )
    return tuple(a for a in known if a in aovs)  # canonical order: one program per set


def camera_struct(rows, plane, width, height, precision, box_origin=(0.0, 0.0, 0.0)):
    """The kernel's Camera (model/layout.py): the frame's rows u, v, w, the image plane (a
    model.camera.ImagePlane at this size) and the eye in the BVH's frame (box_origin: the eye minus
    the scene's anchor, float64). Twice the principal point goes as an integer and the rest, so
    that the kernel's numerator 2 cx - 1 - 2 i is exact but for one rounding of the sum (and exactly
    width - 1 - 2 i, as ever, for a centred camera)."""
    camera = np.zeros(1, dtype=layout(CAMERA, precision).dtype)
    for name, row in zip("uvw", rows):
        camera[name][0, :3] = row
    # rounded to float: the box tests are in float; the margin, 2^-20 |o|_1 (as cast's box rays),
    # covers that rounding and the kernel's differences of faces and origin (kernels/bvh.h)
    origin = np.asarray(box_origin, np.float64)
    camera["box_origin"][0, :3] = origin
    camera["box_origin"][0, 3] = 2.0**-20 * float(np.abs(origin).sum())
    camera["tan_x"], camera["tan_y"] = plane.tan_x, plane.tan_y
    camera["width"], camera["height"] = width, height
    for axis, c in (("x", plane.cx), ("y", plane.cy)):
        whole = round(2 * c)
        camera[f"centre_{axis}"] = whole
        camera[f"centre_{axis}_low"] = 2 * c - whole  # exact in float64: |2 c| < 2^30
    return camera


def frame_camera(camera, width: int, height: int, col0: int = 0, row0: int = 0) -> dict:
    """The intrinsics and pose of a Frame (see Frame) of the window of a width x height image from
    column col0 and row row0 on."""
    K = camera.intrinsics(width, height)
    K[0, 2] -= col0
    K[1, 2] -= row0
    return {"intrinsics": K, "pose": camera.pose()}


def input_buffer(ctx, array):
    return cl.Buffer(ctx.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)


def _output_buffers(ctx, count: int, aovs, precision: str) -> list:
    """Device buffers for the asked images, kept per device and size and reused by every render
    (renders are serialized by render_lock, and each copies its images out before the next)."""
    buffers = []
    for aov in aovs:
        key = (ctx.device.int_ptr, aov, max(count * TABLE[aov].itemsize(precision), 1))
        buffer = _outputs.get(key)
        if buffer is None:
            if len(_outputs) >= _OUTPUTS_MAX:
                _outputs.clear()
            buffer = _outputs[key] = cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY, key[2])
        buffers.append(buffer)
    return buffers


def _with_images(args: dict, aovs, buffers) -> dict:
    """The kernel's arguments by name: args and each image's buffer."""
    return {**args, **{image_parameter(aov): buffer for aov, buffer in zip(aovs, buffers)}}


def _zero_copy(ctx) -> bool:
    """Whether the kernel writes the images straight into the returned arrays (CPU devices)."""
    return bool(ctx.device.type & cl.device_type.CPU)


def run_kernel(ctx, variant, args, global_size, count, aovs, precision, shape_prefix, local_size=None):
    """Enqueue the kernel with output buffers for the asked images and read them back into new arrays."""
    return enqueue_kernel(ctx, variant, args, global_size, count, aovs, precision, shape_prefix, local_size).result()


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


def enqueue_kernel(ctx, variant, args: dict, global_size, count, aovs, precision, shape_prefix, local_size=None) -> Pending:
    """Enqueue the kernel with output buffers for the asked images, new arrays (see Pending). args:
    the kernel's other arguments by parameter name (engine/signatures.py)."""
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
    with render_lock:
        buffers = _output_buffers(ctx, count, aovs, precision)
        launch(ctx, kernel, global_size, local_size, arguments(variant, _with_images(args, aovs, buffers)))
        for array, buffer in zip(outputs.values(), buffers):
            cl.enqueue_copy(ctx.queue, array, buffer, is_blocking=False)
        ctx.queue.finish()
    return Pending(images)
