"""What a view of a prepared scene needs besides the shapes: the camera, the lights in its space,
the tile lists, the acceleration choice and the range check. A scene handle (engine/tracer.py) keeps
one ViewState per view it renders (camera, image, lights and shading), dropping them when its shapes
change."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pyopencl as cl

from ...model.errors import RequestError, SceneError
from ...model.scene import Scene, check_renderable, check_shape_count
from ..bvh import tiles
from ..launch.programs import lanes_for, packet_shape
from ..launch.run import REAL, input_buffer
from ..launch.signatures import shared_arguments
from . import lighting
from .prepared import PreparedScene


# Render visits the bounded shapes through tile lists (pyclray/engine/bvh/tiles.py) or through the
# BVH, whichever costs a packet less. Through tile lists a packet tests every shape of its tile's
# list; through the BVH it pays its traversal. The two cost the same at about 16 shapes per tile on
# average; below, tiles win by 2x and more, above, the BVH (docs/benchmarks.md, "Why the engine does
# what it does": TILE_LIST_MAX).
# Beyond TILES_MAX_SHAPES bounded entries the lists are not even computed: no visible scene of that
# many shapes has short lists, and computing them costs more than building the tree.
TILE_LIST_MAX = 16.0
TILES_MAX_SHAPES = 20_000


def check_acceleration(acceleration) -> str:
    if acceleration not in ("auto", "bvh", "tiles"):
        raise RequestError(f"acceleration: expected one of auto, bvh, tiles, got {acceleration!r}")
    return acceleration


def cheaper_acceleration(scene: Scene, prepared: PreparedScene) -> str:
    """Tile lists while they average at most TILE_LIST_MAX shapes a tile, else the BVH."""
    if prepared.bounded > TILES_MAX_SHAPES:
        return "bvh"
    pairs, tiles = 0, 1
    for kind in prepared.kinds.values():
        if kind.cls.bounded:
            start, _ = view_tile_lists(prepared, kind, scene)
            pairs += int(start[-1])
            tiles = len(start) - 1
    return "tiles" if pairs <= TILE_LIST_MAX * tiles else "bvh"


def check_entry_count(prepared: PreparedScene) -> None:
    """Refuse more entries of one type than the kernels can index (16 x index + type in 32 bits)."""
    from ...model import scene as scene_model

    for kind in prepared.kinds.values():
        if kind.count > scene_model.MAX_SHAPES:
            raise SceneError(f"{kind.count} {kind.name} primitives; pyclray renders at most {scene_model.MAX_SHAPES} of a "
                             "type (the kernels index one by 16 x its position + its type in 32 bits)")


def view_tile_lists(prepared: PreparedScene, kind, scene: Scene):
    """(start, index) of the kind's entries for each tile of this view (engine/bvh/tiles.py): culled
    by the pinhole's image plane, or for a camera whose rays are a table (a lens, a panorama) by the
    rectangles its tiles' rays span on that plane (tiles.table_rects, once per camera and size)."""
    width, height = scene.image.width, scene.image.height
    camera = scene.camera
    table = camera.space_directions(width, height)
    if table is None:
        return prepared.tile_lists(kind, camera.eye, camera.basis(), camera.image_plane(width, height), width, height)
    rects = table.derived.get("tile_rects")
    if rects is None:  # (kept with the table: every view of the lens at this size shares it)
        rects = table.derived["tile_rects"] = tiles.table_rects(*table)
    return prepared.tile_lists_in_rects(kind, camera.eye, camera.basis(), rects, -(-width // tiles.TILE),
                                        -(-height // tiles.TILE))


def table_format(directions: np.ndarray, valid: np.ndarray) -> str:
    """"plane" where every ray in the field is ahead of the eye's plane (a lens of a perspective
    camera: each ray as its image-plane coordinates, two numbers a pixel), else "sphere" (unit
    directions, three: a fisheye beyond 90 degrees, a panorama)."""
    return "plane" if np.all(directions[..., 2][valid] > 0) else "sphere"


def packet_table(directions: np.ndarray, valid: np.ndarray, lanes: int, real, form: str) -> np.ndarray:
    """A camera's table of rays (kernels/camera.h: camera_table_rays) for packets of this many lanes,
    in packet order (a packet's lanes contiguous, lane l = row * columns + column): per packet, the
    lanes' x / z, then y / z ("plane"; the kernel normalizes (x / z, y / z, 1) as a pinhole's ray),
    or x, y, z ("sphere"), then one number whose bit l says lane l is in the field (pixels past the
    image's edge are not). Each coordinate is the float64 ray's, rounded once."""
    columns, rows = packet_shape(lanes)
    height, width = valid.shape
    packets_x, packets_y = -(-width // columns), -(-height // rows)
    padded = np.zeros((packets_y * rows, packets_x * columns, 3))
    padded[..., 2] = 1.0  # a ray (forward) for the padding's lanes and the misses
    inside = np.zeros(padded.shape[:2], bool)
    padded[:height, :width] = np.where(valid[..., None], directions, [0.0, 0.0, 1.0])
    inside[:height, :width] = valid
    if form == "plane":
        padded = padded[..., :2] / padded[..., 2:]
    count = padded.shape[-1]
    # (py, row, px, column, channel) -> (py, px, channel, row, column)
    values = padded.reshape(packets_y, rows, packets_x, columns, count).transpose(0, 2, 4, 1, 3).reshape(
        packets_y, packets_x, count * lanes)
    bits = (inside.reshape(packets_y, rows, packets_x, columns).transpose(0, 2, 1, 3).reshape(packets_y, packets_x, lanes)
            * (1 << np.arange(lanes))).sum(axis=-1)
    table = np.concatenate([values, bits[..., None].astype(np.float64)], axis=-1)
    return np.ascontiguousarray(table, dtype=real).reshape(-1)


class ViewState:
    """What a scene handle keeps of one view (its camera, image, lights and shading) between renders:
    whether its range check passed, its acceleration choice and its inputs per acceleration."""

    def __init__(self):
        self.checked = False
        self.choice = None  # "tiles" or "bvh", once chosen for acceleration "auto"
        self.inputs: dict = {}  # acceleration -> ViewInputs

    def check_renderable(self, scene: Scene, precision: str, prepared: PreparedScene) -> None:
        """scene.check_renderable once per view, in O(1) where the prepared scene's conservative
        bound holds (a new view of a million shapes must not walk them), shape by shape only where it
        does not, to name the shape; a scene without shapes is warned about at every render."""
        if not scene.shapes:
            check_renderable(scene, precision)
            return
        check_shape_count(scene)
        check_entry_count(prepared)
        if not self.checked:
            if not prepared.within_range(scene.camera.eye, precision):
                check_renderable(scene, precision)
            self.checked = True

    def acceleration(self, scene: Scene, acceleration: str, prepared: PreparedScene) -> str:
        """"tiles" or "bvh" for a render of this view (see TILE_LIST_MAX)."""
        if check_acceleration(acceleration) != "auto":
            return acceleration
        if self.choice is None:
            self.choice = cheaper_acceleration(scene, prepared)
        return self.choice

    def inputs_for(self, ctx, scene: Scene, prepared: PreparedScene, acceleration: str) -> "ViewInputs":
        inputs = self.inputs.get(acceleration)
        if inputs is None:
            inputs = self.inputs[acceleration] = ViewInputs(ctx, scene, prepared, acceleration)
        return inputs

    def shapes_changed(self) -> None:
        """The handle's shapes moved (an animation's frame, refitted in place): the range check, the
        choice and the tile lists depend on them; the BVH's inputs (camera, lights) do not."""
        self.checked, self.choice = False, None
        self.inputs.pop("tiles", None)

    def nbytes(self) -> int:
        return sum(inputs.nbytes() for inputs in self.inputs.values())


class ViewInputs:
    """What a view of a prepared scene needs besides the shapes: the camera, the lights in its
    space, the eye for the position image, and (tiles) the tile lists."""

    def __init__(self, ctx, scene: Scene, prepared: PreparedScene, acceleration: str):
        precision = prepared.precision
        width, height = scene.image.width, scene.image.height
        self.rows = scene.camera.basis()
        self.eye = np.asarray(scene.camera.eye, np.float64)
        self.camera = input_buffer(ctx, scene.camera.pack(width, height, precision, self.eye - prepared.anchor))
        self.tiles = {}
        # a lens's or panorama's rays (kernels/camera.h: camera_table_rays): the camera's float64 table,
        # and its device buffer in the packet order of a lane count (directions_for)
        self.table = scene.camera.space_directions(width, height)
        self.table_format = None if self.table is None else table_format(*self.table)
        self.directions = None
        if acceleration == "tiles":
            for kind in prepared.kinds.values():
                start, index = view_tile_lists(prepared, kind, scene)
                self.tiles[kind.name] = (input_buffer(ctx, start), input_buffer(ctx, index))
        # what the lights are packed from, when asked (not the scene, whose shapes may move on)
        self._made = (ctx, scene.camera, scene.lights, scene.shading, precision)
        self._lighting = self._eye_parts = None
        if self.table is not None:
            self.directions_for(lanes_for(ctx.device, precision))

    def directions_for(self, lanes: int):
        """The device buffer of the camera's table of rays in packets of this many lanes (made again
        only if the lanes change: PYCLRAY_LANES between renders of one handle); None for a pinhole."""
        if self.table is None:
            return None
        if self.directions is None or self.directions_lanes != lanes:
            ctx, precision = self._made[0], self._made[-1]
            self.directions = input_buffer(ctx, packet_table(*self.table, lanes, REAL[precision], self.table_format))
            self.directions_lanes = lanes
        return self.directions

    def nbytes(self) -> int:
        """The bytes of its device buffers (the camera, tile lists, lights)."""
        buffers = [self.camera, *(b for pair in self.tiles.values() for b in pair)]
        if self.directions is not None:
            buffers.append(self.directions)
        if self._lighting is not None:
            buffers.append(self._lighting["lights"])
        return sum(b.size for b in buffers)

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
        camera's space, their count, ambient and background; made when a view first asks for that
        image (a view of depth, normal and id packs no lights: render_views' host work per view)."""
        if self._lighting is None:
            ctx, camera, lights, shades, precision = self._made
            packed = lighting.pack_lights(SimpleNamespace(camera=camera, lights=lights), precision)
            real = REAL[precision]
            self._lighting = {"materials": prepared.materials, "lights": input_buffer(ctx, packed),
                              "n_lights": np.int32(len(packed)), "ambient": np.array((*shades.ambient, 0), real),
                              "background": np.array((*shades.background, 0), real)}
        return self._lighting

    def shape_args(self, prepared: PreparedScene, acceleration: str, shadows: bool = False, pairs: bool = False) -> dict:
        """The render kernel's shape arguments by name (engine/launch/signatures.py): a from-world scene's eye
        space; the BVH (the wide nodes, with shadows the binary ones too, refs) and per type its
        entries and count, or per type its entries and tile lists (and with shadows its count);
        pairs: the pair nodes in place of the wide ones (Variant.through_pairs), and the mesh
        instances' own trees as pair nodes too (PreparedScene.shared_of)."""
        args = {}
        if prepared.from_world:  # the eye's space (the eye, the camera's axes), float64: each shape is rebased on it
            for name, v in zip(("space_origin", "space_u", "space_v", "space_w"), (self.eye, *self.rows)):
                args[name] = np.append(v, 0.0).view(cl.cltypes.double4)[0]
        if acceleration == "bvh" and prepared.bvh.types:
            args["refs"] = prepared.refs
            if pairs:  # one ray per work-item (GPUs): the pair nodes, shadow rays too (kernels/bvh_pairs.h)
                args["pair_nodes"] = prepared.pair_nodes
            else:
                args["wide_nodes"] = prepared.wide_nodes
                if shadows:
                    args["nodes"] = prepared.nodes
        for t, kind in prepared.kinds.items():
            # its entries: the faces and vertices (indexed), the world entries, ids and primitive
            # indices (rebased), or the view buffer; then the arrays its entries share
            if kind.indexed is not None:
                args.update({f"{t}_faces": kind.indexed.faces_buffer, f"{t}_vertices": kind.indexed.vertices,
                             f"{t}_world_vertices": kind.indexed.world_buffer, f"{t}_ids": kind.indexed.ids_buffer})
            elif kind.from_world:
                args.update({f"{t}_worlds": kind.world_buffer, f"{t}_ids": kind.ids_buffer,
                             f"{t}_primitives": kind.primitives_buffer})
            else:
                args[f"{t}s"] = kind.in_view
            args.update(shared_arguments(t, prepared.shared_of(kind, pairs)))
            if acceleration == "bvh" or shadows:
                args[f"n_{t}s"] = np.int32(kind.count)
            if acceleration != "bvh":
                args[f"{t}_tile_start"], args[f"{t}_tile_list"] = self.tiles[t]
        return args
