"""What renders and casts of the same scene share, computed once per scene object and kept: the
shape types present, the acceleration choice, the range check, the BVH, and the packed, uploaded
inputs of the kernels (bounded caches, least recently used)."""
from __future__ import annotations

from collections import OrderedDict

import numpy as np

from ..model.errors import PyclrayError
from ..model.scene import Scene, check_renderable
from ..model.shapes import REGISTRY
from . import culling, shading
from .request import REAL, camera_struct, input_buffer, render_lock
from .scene_bvh import SceneBVH, scene_bvh as build_scene_bvh

# -- what renders of the same scene share ------------------------------------------------------
# Inputs are packed and uploaded once per (device, scene object, precision): a Scene is frozen, so
# the same object always packs to the same bytes; a moved camera or shape is a new Scene, hence new
# inputs. An entry holds its scene, so the scene's id() cannot be reused while it is cached.
_PREPARED_MAX = 16
_PREPARED_BYTES = 256 << 20
_prepared: OrderedDict = OrderedDict()


class PerObject:
    """Values computed from an object (a scene or its shapes tuple), the `most` most recently used:
    keyed by the object's id and holding the object itself, so that neither an equal object nor a
    new one at a recycled id takes another's value. The value is computed outside the lock."""

    def __init__(self, most: int):
        self.most = most
        self.entries: OrderedDict = OrderedDict()

    def get(self, obj, compute):
        key = id(obj)
        with render_lock:
            entry = self.entries.get(key)
            if entry is not None and entry[0] is obj:
                self.entries.move_to_end(key)
                return entry[1]
        value = compute()
        with render_lock:
            self.entries[key] = (obj, value)
            while len(self.entries) > self.most:
                self.entries.popitem(last=False)
        return value


# The BVH of a scene's shapes is kept per shapes tuple (a moved camera keeps the scene's tuple, so
# it reuses the tree: only the boxes are re-expressed around the new eye); an entry holds its tuple.
_bvhs = PerObject(8)


def scene_bvh(scene: Scene) -> SceneBVH:
    """The BVH over the scene's bounded shapes, built once per shapes tuple."""
    return _bvhs.get(scene.shapes, lambda: build_scene_bvh(scene.shapes, REGISTRY))


_kinds = PerObject(_PREPARED_MAX)


def shape_kinds(scene: Scene) -> tuple[tuple[str, ...], int]:
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
_choices = PerObject(_PREPARED_MAX)


def acceleration_for(scene: Scene, acceleration: str = "auto") -> str:
    """"tiles" or "bvh" for a render of this scene (see TILE_LIST_MAX)."""
    if acceleration not in ("auto", "bvh", "tiles"):
        raise PyclrayError(f"acceleration: expected one of auto, bvh, tiles, got {acceleration!r}")
    if acceleration != "auto":
        return acceleration
    return _choices.get(scene, lambda: _cheaper_acceleration(scene))


def _cheaper_acceleration(scene: Scene) -> str:
    """Tile lists while they average at most TILE_LIST_MAX shapes a tile, else the BVH."""
    shape_types, bounded = shape_kinds(scene)
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


def check_renderable_once(scene: Scene, precision: str) -> None:
    """scene.check_renderable once per scene object and precision: its range check walks every
    shape, which a warm render of a million shapes must not do again (a Scene is frozen, so the
    answer cannot change; an entry holds its scene)."""
    key = (id(scene), precision)
    with render_lock:
        entry = _checked.get(key)
        if entry is not None and entry is scene:
            return
    check_renderable(scene, precision)
    if scene.shapes:  # a scene without shapes is warned about at every render
        with render_lock:
            _checked[key] = scene
            while len(_checked) > _PREPARED_MAX:
                _checked.popitem(last=False)


def render_inputs(ctx, scene: Scene, precision: str, acceleration: str) -> list:
    """The kernel arguments of a render of this scene that do not depend on the window: the camera,
    and then either the BVH (its binary nodes around the eye, refs) and per shape type its packed
    buffer (bounded types in leaf order) and count, or per shape type its packed buffer and its tile
    lists (pyclray/culling.py)."""
    key = (ctx.device.int_ptr, id(scene), precision, acceleration)
    with render_lock:
        entry = _prepared.get(key)
        if entry is not None and entry[0] is scene:  # the same object, not an equal one
            _prepared.move_to_end(key)
            return entry[1]
    width, height = scene.image.width, scene.image.height
    rows = scene.camera.basis()
    tan_x, tan_y = scene.camera.tangents(width, height)
    camera = input_buffer(ctx, camera_struct(rows, tan_x, tan_y, width, height, precision))
    eye = np.asarray(scene.camera.eye, np.float64)
    shape_args, arrays = [], []
    if acceleration == "bvh":
        tree = scene_bvh(scene)
        if tree.types:
            arrays += [tree.binary_nodes(eye), tree.refs(scene.shape_types())]
            shape_args += [input_buffer(ctx, a) for a in arrays]
        for kind in scene.shape_types():
            cls = REGISTRY[kind]
            if cls.bounded:
                shapes, ids = tree.shapes[kind], tree.ids[kind]
            else:
                ids = [i for i, shape in enumerate(scene.shapes) if shape.type == kind]
                shapes = [scene.shapes[i] for i in ids]
            packed = cls.pack(shapes, ids, eye, rows, precision)
            arrays.append(packed)
            shape_args += [input_buffer(ctx, packed), np.int32(len(shapes))]
    else:
        for kind in scene.shape_types():
            cls = REGISTRY[kind]
            ids = [i for i, shape in enumerate(scene.shapes) if shape.type == kind]
            shapes = [scene.shapes[i] for i in ids]
            packed = cls.pack(shapes, ids, eye, rows, precision)
            start, index = culling.tile_lists(cls, shapes, eye, rows, tan_x, tan_y, width, height)
            arrays += [packed, start, index]
            # shadow rays test every shape of a type: its count follows its tile lists (kernels/pyclray.cl)
            shape_args += [input_buffer(ctx, packed), input_buffer(ctx, start), input_buffer(ctx, index),
                           (np.int32(len(ids)),)]
    # what shading needs (kernels/shading.h): materials by id, lights in the frame, [shading]
    materials = shading.pack_materials(scene, precision)
    lights = shading.pack_lights(scene, precision)
    arrays += [materials, lights]
    real = REAL[precision]
    eye_high = eye.astype(real)
    lighting = {
        "materials": input_buffer(ctx, materials),
        "lights": input_buffer(ctx, lights),
        "n_lights": np.int32(len(lights)),
        "ambient": np.array((*scene.shading.ambient, 0), real),
        "background": np.array((*scene.shading.background, 0), real),
        # the eye as a sum of two reals, for the position image (kernels/pyclray.cl)
        "eye_high": np.array((*eye_high, 0), real),
        "eye_low": np.array((*(eye - eye_high.astype(np.float64)), 0), real),
    }
    size = sum(a.nbytes for a in arrays)
    args = [camera, shape_args, lighting]
    with render_lock:
        _prepared[key] = (scene, args, size)
        # bounded: at most _PREPARED_MAX scenes and _PREPARED_BYTES of inputs (the newest always stays)
        while len(_prepared) > 1 and (
            len(_prepared) > _PREPARED_MAX or sum(e[2] for e in _prepared.values()) > _PREPARED_BYTES
        ):
            _prepared.popitem(last=False)
    return args


_cast_prepared: OrderedDict = OrderedDict()


def cast_inputs(ctx, scene: Scene, precision: str, shape_types) -> tuple[list, np.ndarray]:
    """(arguments, anchor): the BVH around the scene's anchor (its root box's centre), its refs and
    the shapes' anchors, and per shape type its packed buffer (each bounded shape relative to its
    own anchor, in leaf order) and count. They depend on the scene only, never on the rays."""
    key = (ctx.device.int_ptr, id(scene.shapes), precision)
    with render_lock:
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
            input_buffer(ctx, tree.nodes(anchor[:3])),
            input_buffer(ctx, tree.refs(shape_types)),
            input_buffer(ctx, np.ascontiguousarray(anchors)),
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
        args += [input_buffer(ctx, packed), np.int32(len(shapes))]
    with render_lock:
        _cast_prepared[key] = (scene.shapes, shape_types, args, anchor)
        while len(_cast_prepared) > _PREPARED_MAX:
            _cast_prepared.popitem(last=False)
    return args, anchor
