"""Render a scene (one ray per pixel) or cast a batch of rays: pack, build, run, read back."""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from .device import AOVS, DeviceContext, Variant, context_for, has_fp64, kernel_for
from .errors import DeviceError, PyclrayError
from .layout import CAMERA, PRECISIONS, layout
from .scene import Scene
from .shapes import REGISTRY

_REAL = {"fp32": np.float32, "fp64": np.float64}


class Frame(dict):
    """The images of a render (or the per-ray results of a cast): AOV name -> numpy array.

    depth: distance from the ray origin along the unit ray, +inf on a miss (float32; float64 with
    precision "fp64"); normal: unit world normal, (0, 0, 0) on a miss; id: int32, -1 on a miss.
    """

    def __init__(self, arrays, *, precision: str, device: str):
        super().__init__(arrays)
        self.precision = precision
        self.device = device

    def __repr__(self) -> str:
        shapes = ", ".join(f"{k}: {v.dtype}{list(v.shape)}" for k, v in self.items())
        return f"Frame({shapes}; {self.precision} on {self.device})"


def _check_request(aovs, precision: str, ctx: DeviceContext) -> tuple[str, ...]:
    if isinstance(aovs, str):
        aovs = tuple(a.strip() for a in aovs.split(","))
    aovs = tuple(aovs)
    unknown = [a for a in aovs if a not in AOVS]
    if unknown or not aovs or len(set(aovs)) != len(aovs):
        raise PyclrayError(f"aovs: expected a non-empty selection of {', '.join(AOVS)} without repeats, got {aovs!r}")
    if precision not in PRECISIONS:
        raise PyclrayError(f"precision: expected one of {', '.join(PRECISIONS)}, got {precision!r}")
    if precision == "fp64" and not has_fp64(ctx.device):
        raise DeviceError(
            f"precision fp64 needs the cl_khr_fp64 extension, which {ctx.device.name.strip()} lacks; "
            "use precision fp32 or another device"
        )
    return tuple(a for a in AOVS if a in aovs)  # canonical order: one program per set


def _camera_struct(rows, tan_x, tan_y, width, height, precision):
    camera = np.zeros(1, dtype=layout(CAMERA, precision).dtype)
    for name, row in zip("uvw", rows):
        camera[name][0, :3] = row
    camera["tan_x"], camera["tan_y"] = tan_x, tan_y
    camera["width"], camera["height"] = width, height
    return camera


def _shape_args(ctx, scene: Scene, shape_types, origin, rotation, precision):
    """Buffer and count of each shape type present, packed in the frame (origin, rotation)."""
    args, keep = [], []
    for kind in shape_types:
        cls = REGISTRY[kind]
        ids = [i for i, shape in enumerate(scene.shapes) if shape.type == kind]
        packed = cls.pack([scene.shapes[i] for i in ids], ids, origin, rotation, precision)
        keep.append(packed)
        args += [_input_buffer(ctx, packed), np.int32(len(ids))]
    return args, keep


def _input_buffer(ctx, array):
    return cl.Buffer(ctx.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=array)


def _run(ctx, variant, args, global_size, count, aovs, precision, shape_prefix):
    """Enqueue the kernel with output buffers for the asked images and read them back."""
    real = _REAL[precision]
    outputs = {
        "depth": np.empty(count, real),
        "normal": np.empty((count, 3), real),
        "id": np.empty(count, np.int32),
    }
    outputs = {k: outputs[k] for k in aovs}
    buffers = [cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY, max(a.nbytes, 1)) for a in outputs.values()]
    kernel = kernel_for(ctx, variant)
    kernel(ctx.queue, global_size, None, *args, *buffers)
    for array, buffer in zip(outputs.values(), buffers):
        cl.enqueue_copy(ctx.queue, array, buffer, is_blocking=False)
    ctx.queue.finish()
    return {k: v.reshape(shape_prefix + v.shape[1:]) for k, v in outputs.items()}


def render(scene: Scene, aovs=AOVS, precision: str = "fp32", device=None) -> Frame:
    """Render the scene's depth, normal and id images (see Frame) with one ray per pixel centre.

    aovs: which images (a subset of depth, normal, id: only those are computed);
    precision: "fp32" or "fp64"; device: a pyopencl Device, a selector string, or None (default).
    """
    ctx = context_for(device)
    aovs = _check_request(aovs, precision, ctx)
    width, height = scene.image.width, scene.image.height
    rows = scene.camera.basis()
    tan_x, tan_y = scene.camera.tangents(width, height)
    camera = _camera_struct(rows, tan_x, tan_y, width, height, precision)
    shape_types = scene.shape_types()
    shape_args, _ = _shape_args(ctx, scene, shape_types, scene.camera.eye, rows, precision)
    variant = Variant("render", shape_types, aovs, precision)
    images = _run(
        ctx, variant, [_input_buffer(ctx, camera), *shape_args],
        (width, height), width * height, aovs, precision, (height, width),
    )
    return Frame(images, precision=precision, device=ctx.device.name.strip())


def _rays(name: str, value, count: int | None = None) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise PyclrayError(f"{name}: expected an (N, 3) array of numbers") from None
    if array.ndim == 1 and array.shape == (3,) and count is not None:
        array = np.broadcast_to(array, (count, 3))
    if array.size == 0 and array.ndim == 1:  # an empty list: no rays
        array = array.reshape(0, 3)
    if array.ndim != 2 or array.shape[1] != 3:
        raise PyclrayError(f"{name}: expected an (N, 3) array, got shape {array.shape}")
    if count is not None and array.shape[0] != count:
        raise PyclrayError(f"{name}: expected {count} rows like directions, got {array.shape[0]}")
    bad = ~np.isfinite(array).all(axis=1)
    if bad.any():
        raise PyclrayError(f"{name}: row {int(np.argmax(bad))} is not finite: {array[np.argmax(bad)]}")
    return array


def cast(scene: Scene, origins, directions, aovs=AOVS, precision: str = "fp32", device=None) -> Frame:
    """Cast arbitrary rays through the scene's shapes (the scene's camera and image are not used).

    origins: (N, 3), or one (3,) origin for every ray; directions: (N, 3), any non-zero length.
    Returns a Frame of per-ray arrays: depth (N,) is the distance from the origin along the
    normalized direction (+inf on a miss), normal (N, 3), id (N,).
    Raises PyclrayError for arrays of another shape, rows that are not finite, zero directions,
    and origins (or shapes) so far from the rays' mean origin that the precision overflows.
    """
    ctx = context_for(device)
    aovs = _check_request(aovs, precision, ctx)
    directions = _rays("directions", directions)
    count = directions.shape[0]
    origins = _rays("origins", origins, count)
    # unit directions: scaled by the largest component first, so that neither a tiny nor a huge
    # (finite) direction under- or overflows in the length
    largest = np.abs(directions).max(axis=1) if count else np.ones(0)
    zero = ~(largest > 0)
    if zero.any():
        raise PyclrayError(f"directions: row {int(np.argmax(zero))} has zero length")
    scaled = directions / largest[:, None]
    unit = scaled / np.linalg.norm(scaled, axis=1, keepdims=True)
    real = _REAL[precision]
    # the frame: world axes around the rays' mean origin, subtracted in float64 on the host
    reference = origins.mean(axis=0) if count else np.zeros(3)
    relative = origins - reference
    # the kernel squares distances: keep them below the square root of the largest real
    too_far = ~(np.abs(relative).max(axis=1, initial=0.0) <= np.sqrt(np.finfo(real).max) / 4)
    if too_far.any():
        row = int(np.argmax(too_far))
        raise PyclrayError(
            f"origins: row {row} ({origins[row]}) is too far from the rays' mean origin for {precision} "
            "(cast such rays in separate batches)"
        )
    rays = np.zeros((2, max(count, 1), 4), real)
    rays[0, :count, :3] = relative
    rays[1, :count, :3] = unit
    identity = np.eye(3)
    camera = _camera_struct(identity, 0.0, 0.0, 0, 0, precision)
    shape_types = scene.shape_types()
    with np.errstate(over="ignore", invalid="ignore"):
        shape_args, packed = _shape_args(ctx, scene, shape_types, reference, identity, precision)
    for array in packed:
        if not all(np.isfinite(array[name]).all() for name in array.dtype.names if array[name].dtype.kind == "f"):
            raise PyclrayError(
                f"the scene's shapes are too far from the rays' mean origin {reference} for {precision}: "
                "their coordinates relative to it overflow"
            )
    variant = Variant("cast", shape_types, aovs, precision)
    if count == 0:
        empty = {"depth": np.empty(0, real), "normal": np.empty((0, 3), real), "id": np.empty(0, np.int32)}
        return Frame({k: empty[k] for k in aovs}, precision=precision, device=ctx.device.name.strip())
    args = [_input_buffer(ctx, camera), np.int32(count), _input_buffer(ctx, rays[0]), _input_buffer(ctx, rays[1]), *shape_args]
    results = _run(ctx, variant, args, (count,), count, aovs, precision, (count,))
    return Frame(results, precision=precision, device=ctx.device.name.strip())
