"""Render a scene (one ray per pixel) or cast a batch of rays: pack, build, run, read back."""
from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np
import pyopencl as cl

from . import bvh, culling, shading
from .device import AOVS, RENDER_AOVS, DeviceContext, Variant, context_for, has_fp64, kernel_for, lanes_for, launch
from .errors import DeviceError, PyclrayError, RequestError
from .layout import CAMERA, PRECISIONS, layout
from .scene import Scene, as_scene, check_renderable, check_shape_count
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
        launch(ctx, kernel, global_size, local_size, [*args, *_interleave(aovs, buffers, extra)])
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
            launch(ctx, kernel, global_size, local_size, [*args, *_interleave(aovs, buffers, extra)])
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


class _PerObject:
    """Values computed from an object (a scene or its shapes tuple), the `most` most recently used:
    keyed by the object's id and holding the object itself, so that neither an equal object nor a
    new one at a recycled id takes another's value. The value is computed outside the lock."""

    def __init__(self, most: int):
        self.most = most
        self.entries: OrderedDict = OrderedDict()

    def get(self, obj, compute):
        key = id(obj)
        with _render_lock:
            entry = self.entries.get(key)
            if entry is not None and entry[0] is obj:
                self.entries.move_to_end(key)
                return entry[1]
        value = compute()
        with _render_lock:
            self.entries[key] = (obj, value)
            while len(self.entries) > self.most:
                self.entries.popitem(last=False)
        return value


# The BVH of a scene's shapes is kept per shapes tuple (a moved camera keeps the scene's tuple, so
# it reuses the tree: only the boxes are re-expressed around the new eye); an entry holds its tuple.
_bvhs = _PerObject(8)


def scene_bvh(scene: Scene) -> bvh.SceneBVH:
    """The BVH over the scene's bounded shapes, built once per shapes tuple."""
    return _bvhs.get(scene.shapes, lambda: bvh.scene_bvh(scene.shapes, REGISTRY))


_kinds = _PerObject(_PREPARED_MAX)


def _shape_kinds(scene: Scene) -> tuple[tuple[str, ...], int]:
    """(the shape types present, the number of bounded shapes), once per shapes tuple: a warm
    render of a scene of a million shapes must not walk them."""
    return _kinds.get(scene.shapes, lambda: (
        scene.shape_types(), sum(1 for shape in scene.shapes if REGISTRY[shape.type].bounded)))


# Render visits the bounded shapes through tile lists (pyclray/culling.py) or through the BVH,
# whichever costs a packet less. Through tile lists a packet tests every shape of its tile's list;
# through the BVH it pays its traversal. Measured (bench/REPORT.md, "Tiles or BVH"), the two cost
# the same at about 16 shapes per tile on average (a field of 3,000 spheres at 512x512): below,
# tiles win (2x at 1,000 spheres: no traversal at all), above, the BVH (3x at 30,000). Beyond
# TILES_MAX_SHAPES bounded shapes the lists are not even computed: no visible scene of that many
# shapes has short lists, and computing them costs more than building the tree.
TILE_LIST_MAX = 16.0
TILES_MAX_SHAPES = 20_000
_choices = _PerObject(_PREPARED_MAX)


def acceleration_for(scene: Scene, acceleration: str = "auto") -> str:
    """"tiles" or "bvh" for a render of this scene (see TILE_LIST_MAX)."""
    if acceleration not in ("auto", "bvh", "tiles"):
        raise PyclrayError(f"acceleration: expected one of auto, bvh, tiles, got {acceleration!r}")
    if acceleration != "auto":
        return acceleration
    return _choices.get(scene, lambda: _cheaper_acceleration(scene))


def _cheaper_acceleration(scene: Scene) -> str:
    """Tile lists while they average at most TILE_LIST_MAX shapes a tile, else the BVH."""
    shape_types, bounded = _shape_kinds(scene)
    if bounded > TILES_MAX_SHAPES:
        return "bvh"
    width, height = scene.image.width, scene.image.height
    rows = scene.camera.basis()
    tan_x, tan_y = scene.camera.tangents(width, height)
    pairs = 0
    for kind in shape_types:
        if REGISTRY[kind].bounded:
            shapes = [shape for shape in scene.shapes if shape.type == kind]
            start, _ = culling.tile_lists(REGISTRY[kind], shapes, scene.camera.eye, rows, tan_x, tan_y, width, height)
            pairs += int(start[-1])
    return "tiles" if pairs <= TILE_LIST_MAX * (len(start) - 1 if bounded else 1) else "bvh"


_checked: OrderedDict = OrderedDict()


def _check_renderable(scene: Scene, precision: str) -> None:
    """scene.check_renderable once per scene object and precision: its range check walks every
    shape, which a warm render of a million shapes must not do again (a Scene is frozen, so the
    answer cannot change; an entry holds its scene)."""
    key = (id(scene), precision)
    with _render_lock:
        entry = _checked.get(key)
        if entry is not None and entry is scene:
            return
    check_renderable(scene, precision)
    if scene.shapes:  # a scene without shapes is warned about at every render
        with _render_lock:
            _checked[key] = scene
            while len(_checked) > _PREPARED_MAX:
                _checked.popitem(last=False)


def _render_inputs(ctx, scene: Scene, precision: str, acceleration: str) -> list:
    """The kernel arguments of a render of this scene that do not depend on the window: the camera,
    and then either the BVH (its binary nodes around the eye, refs) and per shape type its packed
    buffer (bounded types in leaf order) and count, or per shape type its packed buffer and its tile
    lists (pyclray/culling.py)."""
    key = (ctx.device.int_ptr, id(scene), precision, acceleration)
    with _render_lock:
        entry = _prepared.get(key)
        if entry is not None and entry[0] is scene:  # the same object, not an equal one
            _prepared.move_to_end(key)
            return entry[1]
    width, height = scene.image.width, scene.image.height
    rows = scene.camera.basis()
    tan_x, tan_y = scene.camera.tangents(width, height)
    camera = _input_buffer(ctx, _camera_struct(rows, tan_x, tan_y, width, height, precision))
    eye = np.asarray(scene.camera.eye, np.float64)
    shape_args, arrays = [], []
    if acceleration == "bvh":
        tree = scene_bvh(scene)
        if tree.types:
            arrays += [tree.binary_nodes(eye), tree.refs(scene.shape_types())]
            shape_args += [_input_buffer(ctx, a) for a in arrays]
        for kind in scene.shape_types():
            cls = REGISTRY[kind]
            if cls.bounded:
                shapes, ids = tree.shapes[kind], tree.ids[kind]
            else:
                ids = [i for i, shape in enumerate(scene.shapes) if shape.type == kind]
                shapes = [scene.shapes[i] for i in ids]
            packed = cls.pack(shapes, ids, eye, rows, precision)
            arrays.append(packed)
            shape_args += [_input_buffer(ctx, packed), np.int32(len(shapes))]
    else:
        for kind in scene.shape_types():
            cls = REGISTRY[kind]
            ids = [i for i, shape in enumerate(scene.shapes) if shape.type == kind]
            shapes = [scene.shapes[i] for i in ids]
            packed = cls.pack(shapes, ids, eye, rows, precision)
            start, index = culling.tile_lists(cls, shapes, eye, rows, tan_x, tan_y, width, height)
            arrays += [packed, start, index]
            # shadow rays test every shape of a type: its count follows its tile lists (kernels/pyclray.cl)
            shape_args += [_input_buffer(ctx, packed), _input_buffer(ctx, start), _input_buffer(ctx, index),
                           (np.int32(len(ids)),)]
    # what shading needs (kernels/shading.h): materials by id, lights in the frame, [shading]
    materials = shading.pack_materials(scene, precision)
    lights = shading.pack_lights(scene, precision)
    arrays += [materials, lights]
    real = _REAL[precision]
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
    size = sum(a.nbytes for a in arrays)
    args = [camera, shape_args, lighting]
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


def render(scene: Scene, aovs=AOVS, precision: str = "fp32", device=None, window=None, acceleration: str = "auto") -> Frame:
    """Render the scene's depth, normal and id images (see Frame) with one ray per pixel centre.

    scene: a Scene or the path of a scene file; geometry beyond the precision's range is a
    SceneError (see scene.check_renderable).
    aovs: which images (a subset of depth, normal, id, zdepth, position, shaded: only those are
    computed; shaded casts shadow rays where the scene's [shading] asks for them);
    precision: "fp32" or "fp64"; device: a pyopencl Device, a selector string, or None (default);
    window: (x0, y0, width, height), a part of the image (column x0 and row y0 from the top left),
    rendered into images of that size, the same pixels as in the whole image; default: all of it;
    acceleration: how the kernel skips the shapes a ray cannot hit, "tiles" (screen-space tile
    lists), "bvh" (the bounding volume hierarchy) or "auto" (tiles for a few shapes, else the BVH).
    The images do not depend on it, bit for bit.
    """
    scene = as_scene(scene)
    ctx = context_for(device)
    aovs = _check_request(aovs, precision, ctx, RENDER_AOVS)
    _check_renderable(scene, precision)
    acceleration = acceleration_for(scene, acceleration)
    col0, row0, cols, rows = _window(scene, window)
    camera, shape_args, lighting = _render_inputs(ctx, scene, precision, acceleration)
    lanes = lanes_for(ctx.device, precision)
    shadows = "shaded" in aovs and scene.shading.shadows
    variant = Variant("render", _shape_kinds(scene)[0], aovs, precision, lanes, shadows, bvh=acceleration == "bvh")
    # a tuple in shape_args is the argument of shadow rays only (each shape type's count, tile lists)
    shape_args = [a for arg in shape_args for a in ((arg if shadows else ()) if isinstance(arg, tuple) else (arg,))]
    tile = culling.TILE
    tiles_x = -(-scene.image.width // tile)
    args = [camera, np.int32(col0), np.int32(row0), np.int32(cols), np.int32(rows),
            np.int32(tile.bit_length() - 1), np.int32(tiles_x), *shape_args]
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


def _ray_array(name: str, value) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise PyclrayError(f"{name}: expected an array of shape (..., 3) of numbers") from None
    if array.size == 0 and array.ndim == 1:  # an empty list: no rays
        array = array.reshape(0, 3)
    if array.ndim == 0 or array.shape[-1] != 3:
        raise PyclrayError(f"{name}: expected an array of shape (..., 3), got shape {array.shape}")
    return array


def _first_bad(name: str, bad: np.ndarray, rows: np.ndarray, what: str):
    if not bad.ndim or not bad.size:  # one shared origin and no rays: the origin itself
        raise PyclrayError(f"{name}: {what}: {rows}")
    index = np.unravel_index(int(np.argmax(bad)), bad.shape)
    where = "row " + (str(index[0]) if len(index) == 1 else str(tuple(int(i) for i in index)))
    raise PyclrayError(f"{name}: {where} {what}: {rows[index]}")


def _cast_rays(origins, directions, tmax):
    """(origins (M, 3), directions (N, 3), tmax, leading shape): float64 arrays of the rays as given,
    flattened, checked; M is N, or 1 for one origin shared by every ray. The kernel normalizes the
    directions (scaled by their largest component first, so that neither a tiny nor a huge finite
    direction under- or overflows in the length). Each check is one pass over the arrays; the row
    of a failure is looked for only then."""
    directions = _ray_array("directions", directions)
    shape = directions.shape[:-1]
    origins = _ray_array("origins", origins)
    if origins.shape != directions.shape and origins.shape != (3,):
        raise PyclrayError(
            f"origins: expected shape {directions.shape} like directions, or (3,) for one origin, got {origins.shape}"
        )
    for name, array in (("directions", directions), ("origins", origins)):
        if not np.isfinite(array).all():
            rows = array if array.shape == directions.shape else array[None]  # a shared origin: row 0, even with no rays
            _first_bad(name, ~np.isfinite(rows).all(axis=-1), rows, "is not finite")
    if not directions.any(axis=-1).all():
        _first_bad("directions", ~directions.any(axis=-1), directions, "has zero length")
    if tmax is None:
        tmax = np.full(1, np.inf)
    else:
        try:
            tmax = np.asarray(tmax, dtype=np.float64)
        except (TypeError, ValueError):
            raise PyclrayError("tmax: expected a number or an array of numbers") from None
        try:
            tmax = np.broadcast_to(tmax, shape)
        except ValueError:
            raise PyclrayError(f"tmax: expected one number or the shape {shape} of the rays, got {tmax.shape}") from None
        bad = ~(tmax > 0)
        if bad.any():
            raise PyclrayError(f"tmax: expected numbers > 0 (inf for no limit), got {tmax[np.unravel_index(int(np.argmax(bad)), bad.shape)]}")
        tmax = tmax.reshape(-1) if tmax.ndim else tmax.reshape(1)
    return origins.reshape(-1, 3), directions.reshape(-1, 3), tmax, shape


_cast_prepared: OrderedDict = OrderedDict()
# Rays are cast in the order of a Morton curve through their origins (or, sharing one origin, their
# directions) when there are at least this many: neighbouring work-items then walk the same nodes
# and shapes, which stay in cache (100,000 random rays into 100,000 spheres: half the kernel time,
# for a sort of a few milliseconds). Each ray is traced on its own, so the order changes no bit.
COHERENT_FROM = 4096


def _spread10(v: np.ndarray) -> np.ndarray:
    """Interleave the 10 low bits of v: bit b goes to bit 3 b."""
    v = v & np.uint32(0x3FF)
    for shift, mask in ((16, 0x30000FF), (8, 0x300F00F), (4, 0x30C30C3), (2, 0x9249249)):
        v = (v | (v << np.uint32(shift))) & np.uint32(mask)
    return v


def _coherent_order(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    points = origins if len(origins) > 1 else directions
    lo = points.min(axis=0)
    extent = points.max(axis=0) - lo
    extent[~(extent > 0)] = 1.0
    with np.errstate(over="ignore", invalid="ignore"):
        q = np.clip((points - lo) * (1023.0 / extent), 0, 1023).astype(np.uint32)
    code = (_spread10(q[:, 0]) << np.uint32(2)) | (_spread10(q[:, 1]) << np.uint32(1)) | _spread10(q[:, 2])
    return np.argsort(code)


def _cast_inputs(ctx, scene: Scene, precision: str, shape_types) -> tuple[list, np.ndarray]:
    """(arguments, anchor): the BVH around the scene's anchor (its root box's centre), its refs and
    the shapes' anchors, and per shape type its packed buffer (each bounded shape relative to its
    own anchor, in leaf order) and count. They depend on the scene only, never on the rays."""
    key = (ctx.device.int_ptr, id(scene.shapes), precision)
    with _render_lock:
        entry = _cast_prepared.get(key)
        if entry is not None and entry[0] is scene.shapes and entry[1] == shape_types:
            _cast_prepared.move_to_end(key)
            return entry[2], entry[3]
    tree = scene_bvh(scene)
    anchor = 0.5 * (tree.tree.lo[0] + tree.tree.hi[0]) if tree.types else np.zeros(3)
    # w: 1 where the scene reaches beyond 2^100 from its anchor, too far for the float box tests
    # (kernels/pyclray.cl: its rays then test every bounded shape)
    large = bool(tree.types) and not np.all(np.abs(np.stack([tree.tree.lo[0], tree.tree.hi[0]]) - anchor) < 2.0**100)
    anchor = np.append(anchor, 1.0 if large else 0.0)
    args = []
    if tree.types:
        anchors = tree.anchors()
        args += [
            _input_buffer(ctx, tree.nodes(anchor[:3])),
            _input_buffer(ctx, tree.refs(shape_types)),
            _input_buffer(ctx, np.ascontiguousarray(anchors)),
        ]
    identity = np.eye(3)
    for kind in shape_types:
        cls = REGISTRY[kind]
        if cls.bounded:
            shapes, ids = tree.shapes[kind], tree.ids[kind]
            origin = anchors[: len(tree.leaf_type)][tree.leaf_type == tree.types.index(kind), :3]
        else:
            ids = [i for i, shape in enumerate(scene.shapes) if shape.type == kind]
            shapes = [scene.shapes[i] for i in ids]
            origin = np.zeros(3)
        with np.errstate(over="ignore", invalid="ignore"):
            packed = cls.pack(shapes, ids, origin, identity, precision)
        if not all(np.isfinite(packed[name]).all() for name in packed.dtype.names if packed[name].dtype.kind == "f"):
            raise PyclrayError(f"the scene's {kind}s are too large for {precision}: their packed values overflow")
        args += [_input_buffer(ctx, packed), np.int32(len(shapes))]
    with _render_lock:
        _cast_prepared[key] = (scene.shapes, shape_types, args, anchor)
        while len(_cast_prepared) > _PREPARED_MAX:
            _cast_prepared.popitem(last=False)
    return args, anchor


def _cast_run(kind: str, scene: Scene, origins, directions, tmax, aovs, precision: str, device):
    scene = as_scene(scene)
    check_shape_count(scene)
    ctx = context_for(device)
    if kind == "cast":
        aovs = _check_request(aovs, precision, ctx)
    elif not isinstance(precision, str) or precision not in PRECISIONS:
        raise RequestError(f"precision: expected one of {', '.join(PRECISIONS)}, got {precision!r}")
    if not has_fp64(ctx.device):
        raise DeviceError(
            f"cast takes its rays' coordinate differences in float64 and needs the cl_khr_fp64 extension, which "
            f"{ctx.device.name.strip()} lacks; use another device"
        )
    origins, directions, tmax, shape = _cast_rays(origins, directions, tmax)
    count = len(directions)
    real = _REAL[precision]
    shape_types = _shape_kinds(scene)[0]
    args, anchor = _cast_inputs(ctx, scene, precision, shape_types)
    # the distances the kernel squares, from a shape's anchor, must stay below the square root of
    # the largest real (rays too far for the BVH's float32 box tests test every bounded shape)
    bound = np.sqrt(np.finfo(real).max) / 4
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused here, not a warning
        reach = np.abs(origins - anchor[:3]).max(axis=-1, initial=0.0)
    if not (reach <= bound).all():
        row = int(np.argmax(~(reach <= bound)))
        raise PyclrayError(
            f"origins: row {row} ({origins[row]}) is too far from the scene's shapes for {precision} "
            "(their distances overflow)"
        )
    if count == 0:
        if kind == "occluded":
            return np.zeros(shape, bool)
        empty = {"depth": np.empty(shape, real), "normal": np.empty(shape + (3,), real), "id": np.empty(shape, np.int32)}
        return Frame({k: empty[k] for k in aovs}, precision=precision, device=ctx.device.name.strip())
    order = _coherent_order(origins, directions) if count >= COHERENT_FROM else None
    if order is not None:
        directions = directions[order]
        origins = origins[order] if len(origins) > 1 else origins
        tmax = tmax[order] if len(tmax) > 1 else tmax
    head = [np.int32(count), _input_buffer(ctx, np.ascontiguousarray(origins)), np.int32(1 if len(origins) > 1 else 0),
            _input_buffer(ctx, np.ascontiguousarray(directions)),
            _input_buffer(ctx, np.ascontiguousarray(tmax)), np.int32(1 if len(tmax) > 1 else 0),
            anchor.astype(np.float64).view(cl.cltypes.double4)[0]]
    if kind == "occluded":
        variant = Variant("occluded", shape_types, (), precision)
        out = np.empty(count, np.int8)
        buffer = cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
        launch(ctx, kernel_for(ctx, variant), (count,), None, [*head, *args, buffer])
        cl.enqueue_copy(ctx.queue, out, buffer)
        return _unsorted(out.astype(bool), order).reshape(shape)
    identity = np.eye(3)
    camera = _camera_struct(identity, 0.0, 0.0, 0, 0, precision)
    variant = Variant("cast", shape_types, aovs, precision)
    results = _run(ctx, variant, [_input_buffer(ctx, camera), *head, *args], (count,), count, aovs, precision, (count,))
    results = {k: _unsorted(v, order).reshape(shape + v.shape[1:]) for k, v in results.items()}
    return Frame(results, precision=precision, device=ctx.device.name.strip())


def _unsorted(values: np.ndarray, order) -> np.ndarray:
    """Results of rays cast in this order, back in the rays' own order."""
    if order is None:
        return values
    out = np.empty_like(values)
    out[order] = values
    return out


def cast(scene: Scene, origins, directions, aovs=AOVS, precision: str = "fp32", device=None, tmax=None) -> Frame:
    """Cast arbitrary rays through the scene's shapes (the scene's camera and image are not used).

    origins: (..., 3) like directions, or one (3,) origin for every ray; directions: (..., 3), any
    non-zero length; tmax: None, one number or one per ray (shape (...)): hits farther than it
    are misses. Returns a Frame of per-ray arrays: depth (...) is the distance from the origin
    along the normalized direction (+inf on a miss), normal (..., 3), id (...).

    Each ray is traced on its own, from its float64 origin and direction: its result does not
    depend on the other rays of the batch, bit for bit, and its float32 depth and normal meet the
    render's error model for the ray as given (see kernels/pyclray.cl). Needs cl_khr_fp64.
    Raises PyclrayError for arrays of other shapes, rows that are not finite, zero directions, a
    tmax that is not > 0, and origins so far from the shapes that the precision overflows.
    """
    return _cast_run("cast", scene, origins, directions, tmax, aovs, precision, device)


def occluded(scene: Scene, origins, directions, tmax=None, precision: str = "fp32", device=None) -> np.ndarray:
    """Whether each ray hits any shape at a distance up to tmax (None: any distance): a bool array
    of the rays' leading shape. The any-hit query of shadow rays: the search stops at the first
    hit found. The same rays, arguments and exactness as cast: occluded is true exactly where
    cast(..., tmax=tmax) finds a hit, up to hits within rounding of tmax."""
    return _cast_run("occluded", scene, origins, directions, tmax, (), precision, device)
