"""Render a scene (one ray per pixel) or cast a batch of rays: pack, build, run, read back."""
from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np
import pyopencl as cl

from . import culling
from . import shading
from .device import AOVS, RENDER_AOVS, DeviceContext, Variant, context_for, has_fp64, kernel_for, lanes_for
from .errors import DeviceError, PyclrayError, RequestError
from .layout import CAMERA, PRECISIONS, layout
from .scene import Scene, as_scene, check_renderable
from .shapes import REGISTRY

_REAL = {"fp32": np.float32, "fp64": np.float64}


class Frame(dict):
    """The images of a render (or the per-ray results of a cast): AOV name -> numpy array.

    depth: distance from the ray origin along the unit ray, +inf on a miss (float32; float64 with
    precision "fp64"); normal: unit world normal, (0, 0, 0) on a miss; id: int32, -1 on a miss.
    Renders may add zdepth (depth along the optical axis, +inf on a miss), position (world hit
    point, (0, 0, 0) on a miss) and shaded (linear RGB, the background on a miss).
    """

    def __init__(self, arrays, *, precision: str, device: str):
        super().__init__(arrays)
        self.precision = precision
        self.device = device

    def __repr__(self) -> str:
        shapes = ", ".join(f"{k}: {v.dtype}{list(v.shape)}" for k, v in self.items())
        return f"Frame({shapes}; {self.precision} on {self.device})"


def _check_request(aovs, precision: str, ctx: DeviceContext, known=AOVS) -> tuple[str, ...]:
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


def _output_buffers(ctx, count: int, aovs, precision: str) -> list:
    """Device buffers for the asked images, kept per device and size and reused by every render
    (renders are serialized by _render_lock, and each copies its images out before the next)."""
    real = np.dtype(_REAL[precision]).itemsize
    itemsize = {"depth": real, "normal": 3 * real, "id": 4, "zdepth": real, "position": 3 * real, "shaded": 3 * real}
    buffers = []
    for aov in aovs:
        key = (ctx.device.int_ptr, aov, max(count * itemsize[aov], 1))
        buffer = _outputs.get(key)
        if buffer is None:
            if len(_outputs) >= _OUTPUTS_MAX:
                _outputs.clear()
            buffer = _outputs[key] = cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY, key[2])
        buffers.append(buffer)
    return buffers


def _interleave(aovs, buffers, extra) -> list:
    """Each image's buffer, preceded by the arguments that image's code takes (extra[aov])."""
    out = []
    for aov, buffer in zip(aovs, buffers):
        out += (extra or {}).get(aov, []) + [buffer]
    return out


def _zero_copy(ctx) -> bool:
    """Whether the kernel writes the images straight into the returned arrays (CPU devices)."""
    return bool(ctx.device.type & cl.device_type.CPU)


def _run(ctx, variant, args, global_size, count, aovs, precision, shape_prefix, local_size=None, extra=None):
    """Enqueue the kernel with output buffers for the asked images and read them back into new arrays."""
    real = _REAL[precision]
    empty = {
        "depth": lambda: np.empty(count, real),
        "normal": lambda: np.empty((count, 3), real),
        "id": lambda: np.empty(count, np.int32),
        "zdepth": lambda: np.empty(count, real),
        "position": lambda: np.empty((count, 3), real),
        "shaded": lambda: np.empty((count, 3), real),
    }
    outputs = {k: empty[k]() for k in aovs}
    kernel = kernel_for(ctx, variant)
    if _zero_copy(ctx):
        # a CPU device writes straight into the new arrays (USE_HOST_PTR: PoCL uses them as the
        # buffers' memory), then a map makes them current as OpenCL requires: no copy of the images
        flags = cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR
        buffers = [cl.Buffer(ctx.context, flags, hostbuf=array) for array in outputs.values()]
        kernel(ctx.queue, global_size, local_size, *args, *_interleave(aovs, buffers, extra))
        maps = [
            cl.enqueue_map_buffer(ctx.queue, buffer, cl.map_flags.READ, 0, array.shape, array.dtype, is_blocking=False)[0]
            for array, buffer in zip(outputs.values(), buffers)
        ]
        ctx.queue.finish()
        for mapped in maps:
            mapped.base.release()  # unmap
        ctx.queue.finish()
    else:  # other devices: device buffers kept and reused, and a copy of each image
        with _render_lock:
            buffers = _output_buffers(ctx, count, aovs, precision)
            kernel(ctx.queue, global_size, local_size, *args, *_interleave(aovs, buffers, extra))
            for array, buffer in zip(outputs.values(), buffers):
                cl.enqueue_copy(ctx.queue, array, buffer, is_blocking=False)
            ctx.queue.finish()
    return {k: v.reshape(shape_prefix + v.shape[1:]) for k, v in outputs.items()}


# -- what renders of the same scene share ------------------------------------------------------
# Inputs are packed and uploaded once per (device, scene object, precision): a Scene is frozen, so
# the same object always packs to the same bytes; a moved camera or shape is a new Scene, hence new
# inputs. An entry holds its scene, so the scene's id() cannot be reused while it is cached.
_PREPARED_MAX = 16
_PREPARED_BYTES = 256 << 20
_OUTPUTS_MAX = 12
_prepared: OrderedDict = OrderedDict()
_outputs: dict = {}
_render_lock = threading.RLock()


def _render_inputs(ctx, scene: Scene, precision: str) -> list:
    """The kernel arguments of a render of this scene that do not depend on the window: the camera,
    and per shape type its packed buffer and its tile lists (pyclray/culling.py)."""
    key = (ctx.device.int_ptr, id(scene), precision)
    with _render_lock:
        entry = _prepared.get(key)
        if entry is not None and entry[0] is scene:  # the same object, not an equal one
            _prepared.move_to_end(key)
            return entry[1]
    width, height = scene.image.width, scene.image.height
    rows = scene.camera.basis()
    tan_x, tan_y = scene.camera.tangents(width, height)
    camera = _input_buffer(ctx, _camera_struct(rows, tan_x, tan_y, width, height, precision))
    shape_args, counts, size = [], [], 0
    for kind in scene.shape_types():
        cls = REGISTRY[kind]
        ids = [i for i, shape in enumerate(scene.shapes) if shape.type == kind]
        shapes = [scene.shapes[i] for i in ids]
        packed = cls.pack(shapes, ids, scene.camera.eye, rows, precision)
        start, index = culling.tile_lists(cls, shapes, scene.camera.eye, rows, tan_x, tan_y, width, height)
        shape_args.append([_input_buffer(ctx, packed), _input_buffer(ctx, start), _input_buffer(ctx, index)])
        counts.append(np.int32(len(ids)))
        size += packed.nbytes + start.nbytes + index.nbytes
    # what shading needs (kernels/shading.h): materials by id, lights in the frame, [shading]
    materials = shading.pack_materials(scene, precision)
    lights = shading.pack_lights(scene, precision)
    real = _REAL[precision]
    eye = np.array(scene.camera.eye)
    eye_high = eye.astype(real)
    lighting = {
        "materials": _input_buffer(ctx, materials),
        "lights": _input_buffer(ctx, lights),
        "n_lights": np.int32(len(lights)),
        "ambient": np.array((*scene.shading.ambient, 0), real),
        "background": np.array((*scene.shading.background, 0), real),
        # the eye as a sum of two reals, for the position image (kernels/pyclray.cl)
        "eye_high": np.array((*eye_high, 0), real),
        "eye_low": np.array((*(eye - eye_high.astype(np.float64)), 0), real),
    }
    size += materials.nbytes + lights.nbytes
    args = [camera, (shape_args, counts), lighting]
    with _render_lock:
        _prepared[key] = (scene, args, size)
        # bounded: at most _PREPARED_MAX scenes and _PREPARED_BYTES of inputs (the newest always stays)
        while len(_prepared) > 1 and (
            len(_prepared) > _PREPARED_MAX or sum(e[2] for e in _prepared.values()) > _PREPARED_BYTES
        ):
            _prepared.popitem(last=False)
    return args


def _window(scene: Scene, window) -> tuple[int, int, int, int]:
    """(col0, row0, cols, rows) of the part of the image to render: the whole image by default."""
    width, height = scene.image.width, scene.image.height
    if window is None:
        return 0, 0, width, height
    try:
        col0, row0, cols, rows = (int(v) for v in window)
    except (TypeError, ValueError):
        raise PyclrayError(f"window: expected (x0, y0, width, height) integers, got {window!r}") from None
    if not (0 <= col0 and 0 <= row0 and cols >= 1 and rows >= 1 and col0 + cols <= width and row0 + rows <= height):
        raise PyclrayError(
            f"window: expected (x0, y0, width, height) inside the {width}x{height} image, got {tuple(window)!r}"
        )
    return col0, row0, cols, rows


def render(scene: Scene, aovs=AOVS, precision: str = "fp32", device=None, window=None) -> Frame:
    """Render the scene's depth, normal and id images (see Frame) with one ray per pixel centre.

    scene: a Scene or the path of a scene file; geometry beyond the precision's range is a
    SceneError (see scene.check_renderable).
    aovs: which images (a subset of depth, normal, id, zdepth, position, shaded: only those are
    computed; shaded casts shadow rays where the scene's [shading] asks for them);
    precision: "fp32" or "fp64"; device: a pyopencl Device, a selector string, or None (default);
    window: (x0, y0, width, height), a part of the image (column x0 and row y0 from the top left),
    rendered into images of that size, the same pixels as in the whole image; default: all of it.
    """
    scene = as_scene(scene)
    ctx = context_for(device)
    aovs = _check_request(aovs, precision, ctx, RENDER_AOVS)
    check_renderable(scene, precision)
    col0, row0, cols, rows = _window(scene, window)
    camera, (shape_args, counts), lighting = _render_inputs(ctx, scene, precision)
    lanes = lanes_for(ctx.device, precision)
    shadows = "shaded" in aovs and scene.shading.shadows
    variant = Variant("render", scene.shape_types(), aovs, precision, lanes, shadows)
    tile = culling.TILE
    tiles_x = -(-scene.image.width // tile)
    args = [camera, np.int32(col0), np.int32(row0), np.int32(cols), np.int32(rows),
            np.int32(tile.bit_length() - 1), np.int32(tiles_x)]
    for buffers, count in zip(shape_args, counts):
        args += buffers + ([count] if shadows else [])  # shadow rays test every shape of a type
    # the arguments before each image's buffer, in the kernel's order (kernels/pyclray.cl)
    extra = {
        "position": [lighting["eye_high"], lighting["eye_low"]],
        "shaded": [lighting[k] for k in ("materials", "lights", "n_lights", "ambient", "background")],
    }
    # one packet of `lanes` pixels per work-item, packets aligned to multiples of lanes in the image;
    # work-groups of one tile (tile / lanes packets by tile rows) where the device allows (the kernel
    # needs none)
    packets = -(-(col0 + cols) // lanes) - col0 // lanes
    group = (tile // lanes, tile)
    global_size = (-(-packets // group[0]) * group[0], -(-rows // tile) * tile)
    local_size = group if ctx.device.max_work_group_size >= group[0] * group[1] else None
    images = _run(ctx, variant, args, global_size, cols * rows, aovs, precision, (rows, cols), local_size, extra)
    return Frame(images, precision=precision, device=ctx.device.name.strip())


def _rays(name: str, value, count: int | None = None) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
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
    scene = as_scene(scene)
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
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused just below, not a warning
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
    lanes = lanes_for(ctx.device, precision)
    stride = -(-max(count, 1) // lanes) * lanes  # whole packets: the padding rays are never written
    rays = np.zeros((6, stride), real)  # structure of arrays: origin x, y, z, direction x, y, z
    rays[:3, :count] = relative.T
    rays[3:, :count] = unit.T
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
    variant = Variant("cast", shape_types, aovs, precision, lanes)
    if count == 0:
        empty = {"depth": np.empty(0, real), "normal": np.empty((0, 3), real), "id": np.empty(0, np.int32)}
        return Frame({k: empty[k] for k in aovs}, precision=precision, device=ctx.device.name.strip())
    args = [_input_buffer(ctx, camera), np.int32(count), np.int32(stride), _input_buffer(ctx, rays), *shape_args]
    results = _run(ctx, variant, args, (stride // lanes,), count, aovs, precision, (count,))
    return Frame(results, precision=precision, device=ctx.device.name.strip())
