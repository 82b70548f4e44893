"""What a view of a prepared scene needs besides the shapes, kept per scene object: the camera, the
lights in its frame, the tile lists, the acceleration choice and the range check."""
from __future__ import annotations

import weakref
from collections import OrderedDict
from types import SimpleNamespace

import numpy as np
import pyopencl as cl

from ..model.errors import PyclrayError, SceneError
from ..model.scene import Scene, check_renderable, check_shape_count
from ..model.shapes import REGISTRY
from . import shading
from .prepared import CACHES, PreparedScene, prepared_scene
from .request import REAL, camera_struct, input_buffer, render_lock
from .scene_bvh import SceneBVH
from .signatures import shared_arguments


class PerObject:
    """Values computed from an object (a scene or its shapes tuple), the `most` most recently used:
    keyed by the object's id and holding the object itself, so that neither an equal object nor a
    new one at a recycled id takes another's value. The value is computed outside the lock."""

    def __init__(self, most: int):
        self.most = most
        self.entries: OrderedDict = OrderedDict()
        CACHES.append(self.entries)  # pyclray.clear_cache() empties it

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


_kinds = PerObject(16)


def shape_kinds(scene: Scene) -> tuple[tuple[str, ...], int]:
    """(the shape types present, the number of bounded shapes), once per shapes tuple: a warm
    render of a scene of a million shapes must not walk them."""
    return _kinds.get(scene.shapes, lambda: (
        scene.shape_types(), sum(1 for shape in scene.shapes if REGISTRY[shape.type].bounded)))


def scene_bvh(scene: Scene, ctx=None) -> SceneBVH:
    """The BVH over the scene's bounded primitives, built once per shapes tuple (with its prepared
    scene, on the default device at fp32 unless a context is given)."""
    from .device import context_for

    return prepared_scene(ctx or context_for(None), scene, "fp32").bvh


# Render visits the bounded shapes through tile lists (pyclray/engine/culling.py) or through the
# BVH, whichever costs a packet less. Through tile lists a packet tests every shape of its tile's
# list; through the BVH it pays its traversal. Measured (bench/REPORT.md, "Tiles or BVH"), the two
# cost the same at about 16 shapes per tile on average (a field of 3,000 spheres at 512x512):
# below, tiles win (2x at 1,000 spheres: no traversal at all), above, the BVH (3x at 30,000).
# Beyond TILES_MAX_SHAPES bounded entries the lists are not even computed: no visible scene of that
# many shapes has short lists, and computing them costs more than building the tree.
TILE_LIST_MAX = 16.0
TILES_MAX_SHAPES = 20_000
_choices = PerObject(16)


def acceleration_for(scene: Scene, acceleration: str = "auto", prepared: PreparedScene | None = None) -> str:
    """"tiles" or "bvh" for a render of this scene (see TILE_LIST_MAX)."""
    if acceleration not in ("auto", "bvh", "tiles"):
        raise PyclrayError(f"acceleration: expected one of auto, bvh, tiles, got {acceleration!r}")
    if acceleration != "auto":
        return acceleration
    return _choices.get(scene, lambda: _cheaper_acceleration(scene, prepared))


def _cheaper_acceleration(scene: Scene, prepared: PreparedScene | None) -> str:
    """Tile lists while they average at most TILE_LIST_MAX shapes a tile, else the BVH."""
    if prepared is None:
        from .device import context_for

        prepared = prepared_scene(context_for(None), scene, "fp32")
    if prepared.bounded > TILES_MAX_SHAPES:
        return "bvh"
    width, height = scene.image.width, scene.image.height
    rows = scene.camera.basis()
    plane = scene.camera.image_plane(width, height)
    pairs, tiles = 0, 1
    for kind in prepared.kinds.values():
        if kind.cls.bounded:
            start, _ = prepared.tile_lists(kind, scene.camera.eye, rows, plane, width, height)
            pairs += int(start[-1])
            tiles = len(start) - 1
    return "tiles" if pairs <= TILE_LIST_MAX * tiles else "bvh"


_checked = PerObject(16)


def check_entry_count(prepared: PreparedScene) -> None:
    """Refuse more entries of one type than the kernels can index (16 x index + type in 32 bits)."""
    from ..model import scene as scene_model

    for kind in prepared.kinds.values():
        if kind.count > scene_model.MAX_SHAPES:
            raise SceneError(f"{kind.count} {kind.name} primitives; pyclray renders at most {scene_model.MAX_SHAPES} of a "
                             "type (the kernels index one by 16 x its position + its type in 32 bits)")


def check_renderable_once(scene: Scene, precision: str, prepared: PreparedScene) -> None:
    """scene.check_renderable once per scene object and precision, in O(1) where the prepared
    scene's conservative bound holds (a new view of a million shapes must not walk them), shape by
    shape only where it does not, to name the shape; a scene without shapes is warned about at
    every render."""
    if not scene.shapes:
        check_renderable(scene, precision)
        return
    check_shape_count(scene)
    check_entry_count(prepared)
    done = _checked.get(scene, set)
    if precision not in done:
        if not prepared.within_range(scene.camera.eye, precision):
            check_renderable(scene, precision)
        done.add(precision)


class ViewInputs:
    """What a view of a prepared scene needs besides the shapes: the camera, the lights in its
    frame, the eye for the position image, and (tiles) the tile lists."""

    def __init__(self, ctx, scene: Scene, prepared: PreparedScene, acceleration: str):
        precision = prepared.precision
        width, height = scene.image.width, scene.image.height
        self.rows = scene.camera.basis()
        self.eye = np.asarray(scene.camera.eye, np.float64)
        plane = scene.camera.image_plane(width, height)
        # made for this prepared scene (its anchor, its materials): one rebuilt for the same scene gets
        # its own (a weak reference: an evicted prepared scene is not kept alive by its views)
        self.prepared = weakref.ref(prepared)
        self.made_for = (scene.camera, scene.image, scene.lights, scene.shading)  # what they are computed from
        self.camera = input_buffer(ctx, camera_struct(self.rows, plane, width, height, precision, self.eye - prepared.anchor))
        self.tiles = {}
        if acceleration == "tiles":
            for kind in prepared.kinds.values():
                start, index = prepared.tile_lists(kind, self.eye, self.rows, plane, width, height)
                self.tiles[kind.name] = (input_buffer(ctx, start), input_buffer(ctx, index))
        # what the lights are packed from, when asked (not the scene: the last inputs, kept by _last,
        # must not keep a dropped scene's shapes alive)
        self._made = (ctx, scene.camera, scene.lights, scene.shading, precision)
        self._lighting = self._eye_parts = None

    def eye_parts(self) -> list:
        """The eye as a sum of two reals, for the position image (kernels/images.h): made when a
        view first asks for that image."""
        if self._eye_parts is None:
            real = REAL[self._made[-1]]
            eye_high = self.eye.astype(real)
            self._eye_parts = [np.array((*eye_high, 0), real), np.array((*(self.eye - eye_high.astype(np.float64)), 0), real)]
        return self._eye_parts

    def lighting(self, prepared: PreparedScene) -> dict:
        """The shaded image's arguments by name (kernels/shading.h): materials, the lights in the
        camera's frame, their count, ambient and background; made when a view first asks for that
        image (a view of depth, normal and id packs no lights: render_views' host work per view)."""
        if self._lighting is None:
            ctx, camera, lights, shades, precision = self._made
            packed = shading.pack_lights(SimpleNamespace(camera=camera, lights=lights), precision)
            real = REAL[precision]
            self._lighting = {"materials": prepared.materials, "lights": input_buffer(ctx, packed),
                              "n_lights": np.int32(len(packed)), "ambient": np.array((*shades.ambient, 0), real),
                              "background": np.array((*shades.background, 0), real)}
        return self._lighting

    def shape_args(self, prepared: PreparedScene, acceleration: str, shadows: bool = False) -> dict:
        """The render kernel's shape arguments by name (engine/signatures.py): a framed scene's eye
        frame; the BVH (the wide nodes, with shadows the binary ones too, refs) and per type its
        entries and count, or per type its entries and tile lists (and with shadows its count)."""
        args = {}
        if prepared.framed:  # the eye's frame (the eye, the camera's axes), float64: each shape is framed on it
            for name, v in zip(("frame_origin", "frame_u", "frame_v", "frame_w"), (self.eye, *self.rows)):
                args[name] = np.append(v, 0.0).view(cl.cltypes.double4)[0]
        if acceleration == "bvh" and prepared.bvh.types:
            args["wide_nodes"], args["refs"] = prepared.wide_nodes, prepared.refs
            if shadows:
                args["nodes"] = prepared.nodes
        for t, kind in prepared.kinds.items():
            # its entries: the faces and vertices (indexed), the world entries, ids and primitive
            # indices (framed), or the frame buffer; then the arrays its entries share
            if kind.indexed is not None:
                args.update({f"{t}_faces": kind.indexed.faces_buffer, f"{t}_vertices": kind.indexed.vertices,
                             f"{t}_world_vertices": kind.indexed.world_buffer, f"{t}_ids": kind.indexed.ids_buffer})
            elif kind.framed:
                args.update({f"{t}_worlds": kind.world_buffer, f"{t}_ids": kind.ids_buffer,
                             f"{t}_primitives": kind.primitives_buffer})
            else:
                args[f"{t}s"] = kind.frame
            args.update(shared_arguments(t, kind.shared))
            if acceleration == "bvh" or shadows:
                args[f"n_{t}s"] = np.int32(kind.count)
            if acceleration != "bvh":
                args[f"{t}_tile_start"], args[f"{t}_tile_list"] = self.tiles[t]
        return args


_views = PerObject(16)
# the last view inputs made per (device, precision): an animation's frame is a new scene object with
# the same camera, image, lights and shading (and the prepared scene updated in place), whose inputs
# through the BVH are those (tile lists depend on the shapes: not reused)
_last: dict = {}
CACHES.append(_last)


def render_inputs(ctx, scene: Scene, precision: str, acceleration: str):
    """(prepared scene, view inputs) of a render of this scene."""
    prepared = prepared_scene(ctx, scene, precision)
    per_scene = _views.get(scene, dict)
    key = (ctx.device.int_ptr, precision, acceleration)
    inputs = per_scene.get(key)
    if inputs is None or inputs.prepared() is not prepared:
        last = _last.get(key)
        if acceleration == "bvh" and last is not None and last.prepared() is prepared and all(
                a is b for a, b in zip(last.made_for, (scene.camera, scene.image, scene.lights, scene.shading))):
            inputs = per_scene[key] = last
        else:
            inputs = per_scene[key] = _last[key] = ViewInputs(ctx, scene, prepared, acceleration)
    return prepared, inputs
