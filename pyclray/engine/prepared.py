"""The scene on the device: built once per shapes tuple, kept, and rebased for each view.

A PreparedScene holds a scene's shapes on one device at one precision: per shape type its world
entries (float64, camera-independent: ``Shape.pack_world``; a batch contributes one entry per
primitive, never a Python object per primitive), the BVH over the bounded entries (each bounded
type's entries in leaf order), the refs, the materials, and per type a buffer of the entries in a
camera's frame, which is what the render kernel's shape tests read. A view rebases that buffer
from the world entries for its camera (kernels/rebase.cl: the differences of coordinates in
float64, what every ray from the eye shares from error-free sums) on the device, and the BVH's
boxes around the eye with it; a view with the same camera as the last rebases nothing. Devices
without float64 rebase on the host (``Shape.rebase``, the same formulas) and upload the result.
So a moved camera uploads the camera only, whatever the number of shapes.

Caches (bounded, least recently used; ``clear()`` drops them all, with their device buffers):
prepared scenes per (device, shapes tuple, precision), at most PREPARED_MAX of them and about
PREPARED_BYTES; and per scene object what its view needs (camera, tile lists, lights). An entry
holds its tuple or scene, so an id() cannot be reused while it is cached. A new shapes tuple (a
moved shape) is a new prepared scene, unless it was made from a prepared one by an animation that
says which shapes changed (see ``prepared_scene``): then only those entries are rewritten and the
BVH refitted.
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from ..model.errors import PyclrayError, SceneError
from ..model.scene import MAX_LENGTH, Scene, check_renderable, check_shape_count
from ..model.shapes import REGISTRY
from ..model.animation import derivation
from ..model.shapes.base import entries
from . import culling, shading
from .bvh import outward32, sah_cost, widened
from .device import has_fp64
from .programs import Variant, kernels_for
from .request import REAL, camera_struct, input_buffer, render_lock
from .scene_bvh import SceneBVH, primitives_bvh

PREPARED_MAX = 8
PREPARED_BYTES = 1 << 30
_prepared: OrderedDict = OrderedDict()


def clear() -> None:
    """Drop every prepared scene and per-view input (their device memory goes with them)."""
    with render_lock:
        _prepared.clear()
        _cast_prepared.clear()
        for cache in (_views, _choices, _checked):
            cache.entries.clear()


@dataclass
class Kind:
    """One shape type's entries: world (host, float64; bounded types in the BVH's leaf order), their
    ids and primitive indices, and the device buffers."""

    name: str
    cls: type
    world: np.ndarray
    ids: np.ndarray
    primitives: np.ndarray
    world_buffer: cl.Buffer | None  # the world entries on the device (devices with float64)
    frame: cl.Buffer  # the entries in the frame of the last view (the render kernel's shape array)

    @property
    def count(self) -> int:
        return len(self.world)


ALIGNMENT = 128  # bytes: the kernels load a struct's double4 and float8 members with aligned vector loads


def aligned(array: np.ndarray) -> np.ndarray:
    """The array itself if contiguous and aligned to ALIGNMENT bytes, else an aligned copy."""
    if array.flags.c_contiguous and array.ctypes.data % ALIGNMENT == 0:
        return array
    raw = np.empty(array.nbytes + ALIGNMENT, np.uint8)
    start = -raw.ctypes.data % ALIGNMENT
    raw[start:start + array.nbytes] = np.ascontiguousarray(array).reshape(-1).view(np.uint8)  # padding too
    return raw[start:start + array.nbytes].view(array.dtype).reshape(array.shape)


def _buffer(ctx, array: np.ndarray, writable: bool = False) -> cl.Buffer:
    """A device buffer of this array: the array's own memory on a CPU device (no copy: the array
    must be aligned, see aligned(), and live as long as the buffer), a copy elsewhere."""
    mf = cl.mem_flags
    access = mf.READ_WRITE if writable else mf.READ_ONLY
    if ctx.device.type & cl.device_type.CPU:
        return cl.Buffer(ctx.context, access | mf.USE_HOST_PTR, hostbuf=array)
    return cl.Buffer(ctx.context, access | mf.COPY_HOST_PTR, hostbuf=array)


# Scenes of fewer entries than this rebase on the host: measured per moved view (bench/views.py's
# sphere fields, PoCL on 2 cores), the host takes 0.29 ms for 16 entries and 0.45 ms for 1,024, the
# device 0.24 and 0.28 ms (a launch each); at 4,096 0.91 against 0.36, at 16,384 4.0 against 0.6.
# Below the threshold the difference is a tenth of a millisecond, and such a scene's first render
# then needs no second program (the rebase's), which would add its build to a cold start.
DEVICE_REBASE_FROM = 1024


class PreparedScene:
    """A scene's shapes on one device at one precision (see the module's docstring)."""

    def __init__(self, ctx, shapes: tuple, precision: str):
        self.ctx, self.shapes, self.precision = ctx, shapes, precision
        self.lock = threading.Lock()  # one view at a time uses the frame buffers
        self.view_key = self.view = None  # the camera the frame buffers hold: (eye, rows) bytes, arrays
        by_type: dict = {}
        for index, shape in enumerate(shapes):
            by_type.setdefault(shape.type, ([], []))
            by_type[shape.type][0].append(shape)
            by_type[shape.type][1].append(index)
        self.types = tuple(t for t in REGISTRY if t in by_type)
        worlds, bounds = {}, {}
        self.on_device = False  # see below, once the entries are counted
        for t in self.types:
            cls = REGISTRY[t]
            mine, ids = by_type[t]
            world = cls.pack_world(mine)
            entry_ids, primitives = entries(mine, ids)
            worlds[t] = (world, entry_ids, primitives)
            self.on_device = self.on_device or len(world) >= DEVICE_REBASE_FROM
            if cls.bounded:
                with np.errstate(over="ignore", invalid="ignore"):
                    bounds[t] = cls.bounds_of(world)
        with np.errstate(over="ignore", invalid="ignore"):  # geometry beyond range: refused by the range check
            self.bvh: SceneBVH = primitives_bvh(bounds)
        # rebase on the device (float64) where it has float64 and the scene is large enough to pay
        self.on_device = has_fp64(ctx.device) and (self.on_device or self.bvh.tree.nodes >= DEVICE_REBASE_FROM)
        self.kinds: dict[str, Kind] = {}
        for t in self.types:
            world, ids, primitives = worlds[t]
            if t in self.bvh.order:  # bounded: in leaf order
                order = self.bvh.order[t]
                world, ids, primitives = world[order], ids[order], primitives[order]
            self.kinds[t] = self._kind(t, world, ids, primitives)
        self.bounded = sum(k.count for k in self.kinds.values() if k.cls.bounded)
        self.nodes = self.refs = self.world_nodes = None
        if self.bvh.types:
            nodes = aligned(np.zeros(self.bvh.tree.nodes, dtype=self.bvh.binary_nodes(np.zeros(3))[:0].dtype))
            nodes["lo"][:, 3] = self.bvh.tree.first.astype(np.int32).view(np.float32)
            nodes["hi"][:, 3] = self.bvh.tree.count.astype(np.int32).view(np.float32)
            self._nodes_host = nodes
            self.nodes = _buffer(ctx, nodes, writable=True)
            self._refs_host = aligned(self.bvh.refs(self.types))
            self.refs = _buffer(ctx, self._refs_host)
            if self.on_device:
                self._world_nodes_host = aligned(self.bvh.world_corners())
                self.world_nodes = _buffer(ctx, self._world_nodes_host)
        with np.errstate(over="ignore", invalid="ignore"):
            self._materials_host = aligned(shading.pack_materials(shapes, precision))
        self.base, self.dirty = shapes, set()  # see update
        self.stale: dict = {}  # type name (or "nodes") -> world entries changed on the host only
        self._refit = None
        self.materials = _buffer(ctx, self._materials_host)
        self.reach = self._reach()

    # -- an animation frame: a few shapes moved --------------------------------------------------
    # Rebuilding the scene when the SAH cost of the refitted tree exceeds the built tree's by this
    # factor: a refit keeps the tree's topology, so shapes that wander far apart make its boxes
    # overlap and rays visit more of them. Measured (bench/views.py, "animation"): 10 of 100,000
    # spheres moving across the whole field raise the cost by well under 1%; a refit costs about a
    # millisecond where a rebuild of that scene costs half a second.
    REFIT_COST_MAX = 1.5

    def update(self, shapes: tuple, changed) -> bool:
        """Become the prepared scene of ``shapes``, a tuple equal to this scene's but for the shapes at
        ``changed`` (an animation's frame, pyclray.model.animation.derivation): rewrite their world
        entries, their materials and the BVH's boxes above them (a refit), on the host and the device.
        O(K log N) host work for K changed shapes. False (and nothing changed) where the changes need a
        new scene: another type or primitive count, or a refit that would degrade the tree."""
        indices = sorted(set(changed) | self.dirty)  # shapes changed before and no longer: back to theirs
        for i in indices:
            if i >= len(shapes) or i >= len(self.shapes) or shapes[i].type != self.shapes[i].type \
                    or shapes[i].primitive_count() != self.shapes[i].primitive_count():
                return False
        if self._refit is None:
            self._refit = _RefitState(self)
        state = self._refit
        positions, rows_by_kind, bounds_rows = [], {}, []
        for i in indices:
            kind = self.kinds[shapes[i].type]
            mine = state.positions(kind, i)
            rows = kind.cls.pack_world([shapes[i]])
            rows_by_kind.setdefault(kind.name, ([], []))
            rows_by_kind[kind.name][0].append(mine)
            rows_by_kind[kind.name][1].append(rows)
            if kind.cls.bounded:
                positions.append(state.leaf_positions(kind, mine))
                bounds_rows.append(kind.cls.bounds_of(rows))
        refitted = None
        if positions:
            refitted = state.refit(np.concatenate(positions), np.concatenate(bounds_rows))
            if refitted is None:
                return False
        # the world entries on the host; the device's are brought up to date before the next whole
        # pass needs them (flush_world): while the camera stays, a frame writes only the frame buffers
        for name, (where, rows) in rows_by_kind.items():
            kind = self.kinds[name]
            where, rows = np.concatenate(where), np.concatenate(rows)
            kind.world[where] = rows
            if self.on_device:
                self.stale.setdefault(name, set()).update(where.tolist())
        if refitted is not None and self.on_device:
            self.stale.setdefault("nodes", set()).update(refitted.tolist())
        if self.on_device and self.view is not None:
            # the frame buffers hold the last view: bring the changed entries and nodes to it in place
            # (the same floats as a whole pass: the host's rebase is the device's, bit for bit)
            eye, rows = self.view
            for name, (where, _) in rows_by_kind.items():
                kind = self.kinds[name]
                where = np.concatenate(where)
                self._scatter(kind.frame, where, kind.cls.rebase(kind.world[where], eye, rows, self.precision,
                                                                 kind.ids[where], kind.primitives[where]))
            if refitted is not None:
                tree = self.bvh.tree
                nodes = self._nodes_host[refitted].copy()
                nodes["lo"][:, :3], nodes["hi"][:, :3] = outward32(tree.lo[refitted] - eye, tree.hi[refitted] - eye)
                self._scatter(self.nodes, refitted, nodes)
        # materials (an animated colour or size): the rows that differ
        materials = shading.pack_materials([shapes[i] for i in indices], self.precision)
        if not (materials == self._materials_host[indices]).all():
            self._materials_host[indices] = materials
            cl.enqueue_copy(self.ctx.queue, self.materials, self._materials_host)
        self.reach = self._reach()
        self.shapes, self.dirty = shapes, set(changed)
        if not (self.on_device and self.view is not None):
            self.view_key = None  # a whole pass at the next view
        return True

    def flush_world(self) -> None:
        """Write the world entries and BVH corners that animation frames changed to the device."""
        for name, where in self.stale.items():
            where = np.array(sorted(where), np.int64)
            if name == "nodes":
                corners = self._world_nodes_host.reshape(-1, 2, 4)[where]  # a node's two corners: 64 bytes
                self._scatter(self.world_nodes, where, corners.reshape(len(where), 8).view([("corners", "f8", 8)]).reshape(-1))
            else:
                kind = self.kinds[name]
                self._scatter(kind.world_buffer, where, kind.world[where])
        self.stale = {}

    def _scatter(self, buffer, index, rows) -> None:
        """Write rows (structs of a multiple of 16 bytes) at these indices of a device buffer of such
        rows (kernels' scatter_rows)."""
        rows = np.ascontiguousarray(rows)
        if not len(index):
            return
        width = rows.dtype.itemsize // 16
        kernels = kernels_for(self.ctx, Variant("rebase", self.types, (), self.precision))
        index = np.ascontiguousarray(index, np.int32)
        words = rows.view(np.uint8).reshape(-1).view(np.uint32)
        kernels["scatter_rows"](self.ctx.queue, (len(index),), None, buffer, input_buffer(self.ctx, index),
                                input_buffer(self.ctx, words), np.int32(len(index)), np.int32(width))

    def _kind(self, t, world, ids, primitives) -> Kind:
        cls = REGISTRY[t]
        frame = aligned(np.zeros(max(len(world), 1), dtype=cls.rebase(world[:0], np.zeros(3), np.eye(3), self.precision).dtype))
        frame["id"][: len(world)] = ids
        frame["primitive"][: len(world)] = primitives
        world = aligned(world if len(world) else np.zeros(1, world.dtype))[: len(world)]
        world_buffer = _buffer(self.ctx, world.base if not len(world) else world) if self.on_device else None
        kind = Kind(t, cls, world, ids, primitives, world_buffer, _buffer(self.ctx, frame, writable=True))
        kind.frame_host = frame  # the frame buffer's memory on a CPU device
        return kind

    def nbytes(self) -> int:
        """The bytes this scene holds (host arrays shared with a CPU device counted once)."""
        total = self._materials_host.nbytes
        for kind in self.kinds.values():
            total += kind.world.nbytes + kind.frame_host.nbytes
        if self.bvh.types:
            total += self._nodes_host.nbytes + self._refs_host.nbytes
            if self.on_device:
                total += self._world_nodes_host.nbytes
        return total

    # -- the range check, once per view in O(1) ---------------------------------------------------
    def _reach(self):
        """(root box corners (8, 3), root box diagonal) of the bounded entries, or None."""
        if not self.bvh.types:
            return None
        lo, hi = self.bvh.tree.lo[0], self.bvh.tree.hi[0]
        corners = np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        with np.errstate(over="ignore", invalid="ignore"):  # inf: the shape by shape check decides
            return corners, float(np.linalg.norm(hi - lo))

    def within_range(self, eye, precision: str) -> bool:
        """True if every length the kernel squares in this view stays within the precision's range
        (scene.check_renderable), by a conservative bound: the farthest corner of the bounded
        entries' box from the eye plus its diagonal bound every centre's distance and every size;
        planes are few and checked one by one. False: check shape by shape."""
        limit = MAX_LENGTH[precision]
        with np.errstate(over="ignore", invalid="ignore"):
            if self.reach is not None:
                corners, diagonal = self.reach
                if not np.linalg.norm(corners - np.asarray(eye), axis=1).max() + diagonal <= limit:
                    return False
            for kind in self.kinds.values():
                if not kind.cls.bounded and not kind.cls.world_within(kind.world, eye, limit):
                    return False
        return True

    # -- a view ----------------------------------------------------------------------------------
    def rebase(self, eye, rows) -> None:
        """Bring the frame buffers to this camera (eye: float64 (3,); rows: its axes u, v, w in
        world coordinates). Call with self.lock held, and keep it until the kernels that read the
        buffers have run."""
        eye = np.asarray(eye, np.float64)
        rows = np.asarray(rows, np.float64)
        key = (eye.tobytes(), rows.tobytes())
        if key == self.view_key:
            return
        queue = self.ctx.queue
        if self.on_device:
            self.flush_world()
            kernels = kernels_for(self.ctx, Variant("rebase", self.types, (), self.precision))
            frame = [np.append(v, 0.0).view(cl.cltypes.double4)[0] for v in (eye, *rows)]
        for kind in self.kinds.values():
            if not kind.count:
                continue
            if self.on_device and kind.count >= self.GROUP:
                kernels[f"rebase_{kind.name}"](queue, *self._groups(kind.count), kind.world_buffer, kind.frame,
                                               np.int32(kind.count), *frame)
            else:  # on the host: a few entries (a ground plane) cost less than a launch
                packed = kind.cls.rebase(kind.world, eye, rows, self.precision, kind.ids, kind.primitives)
                cl.enqueue_copy(queue, kind.frame, packed)
        if self.bvh.types:
            if self.on_device:
                kernels["rebase_nodes"](queue, *self._groups(self.bvh.tree.nodes), self.world_nodes, self.nodes,
                                        np.int32(self.bvh.tree.nodes), frame[0])
            else:
                nodes = self._nodes_host.copy()  # not the buffer's own memory (a CPU device's) as the source
                nodes["lo"][:, :3], nodes["hi"][:, :3] = outward32(self.bvh.tree.lo - eye, self.bvh.tree.hi - eye)
                cl.enqueue_copy(queue, self.nodes, nodes)
        self.view_key, self.view = key, (eye, rows)

    GROUP = 256

    def _groups(self, count: int):
        """(global size, local size) of a pass over count entries: work-groups of GROUP work-items
        (or the device's most), the count rounded up (the kernels skip the rest). Left to itself, PoCL
        divides a count like 70,669 into tiny work-groups: the nodes' pass then took 2.0 ms for
        100,000 spheres, 1.6 ms in groups of 256."""
        group = min(self.GROUP, self.ctx.device.max_work_group_size)
        return (-(-count // group) * group,), (group,)

    def tile_lists(self, kind: Kind, eye, rows, plane, width, height):
        """(start, index) of the kind's entries for each screen tile of this view (culling.tile_lists)."""
        spheres = kind.cls.spheres_of(kind.world) if kind.cls.bounded else None
        return culling.tile_lists(kind.cls.bounded, spheres, kind.count, eye, rows, plane, width, height)


class _RefitState:
    """What refitting a prepared scene's BVH needs, computed at its first update: each node's parent,
    each leaf position's leaf, the entries' widened boxes in leaf order, the built tree's SAH cost,
    and per type its entries sorted by shape id and their leaf positions."""

    def __init__(self, prepared: PreparedScene):
        tree, bvh = prepared.bvh.tree, prepared.bvh
        self.prepared = prepared
        self.parent = np.full(tree.nodes, -1, np.int64)
        internal = np.nonzero(tree.count == 0)[0] if tree.nodes > 1 else np.zeros(0, np.int64)
        self.parent[tree.first[internal]] = internal
        self.parent[tree.first[internal] + 1] = internal
        self.leaf_of = np.zeros(len(bvh.leaf_type), np.int64)
        for leaf in np.nonzero(tree.count > 0)[0]:
            self.leaf_of[tree.first[leaf]: tree.first[leaf] + tree.count[leaf]] = leaf
        self.widened = widened(bvh.bounds) if len(bvh.bounds) else np.zeros((0, 2, 3))
        self.built_cost = sah_cost(tree) if tree.nodes else 0.0
        # the SAH cost's sum (sah_cost before the division by the root's area), kept up to date as
        # nodes change: a frame's check costs O(changed nodes), not a pass over the tree
        self.weight = np.where(tree.count > 0, tree.count, 1).astype(np.float64)
        self.cost_sum = float((self._areas(np.arange(tree.nodes)) * self.weight).sum())
        self.by_id, self.leaf_positions_of, self.found = {}, {}, {}
        for k, t in enumerate(bvh.types):
            self.leaf_positions_of[t] = np.nonzero(bvh.leaf_type == k)[0]

    def _areas(self, nodes) -> np.ndarray:
        tree = self.prepared.bvh.tree
        extent = np.maximum(tree.hi[nodes] - tree.lo[nodes], 0.0)
        return extent[:, 0] * extent[:, 1] + extent[:, 1] * extent[:, 2] + extent[:, 2] * extent[:, 0]

    def cost(self) -> float:
        """The tree's SAH cost as sah_cost computes it (relative to the root's area)."""
        root = self._areas(np.zeros(1, np.int64))[0]
        return self.cost_sum / (root if root > 0 else 1.0)

    def positions(self, kind: Kind, shape_index: int) -> np.ndarray:
        """The positions of a shape's entries in its type's array."""
        found = self.found.get((kind.name, shape_index))
        if found is None:
            if kind.name not in self.by_id:
                order = np.argsort(kind.ids, kind="stable")
                self.by_id[kind.name] = (order, kind.ids[order])
            order, ids = self.by_id[kind.name]
            lo, hi = np.searchsorted(ids, shape_index, "left"), np.searchsorted(ids, shape_index, "right")
            found = self.found[(kind.name, shape_index)] = order[lo:hi]  # an animation asks each frame
        return found

    def leaf_positions(self, kind: Kind, positions: np.ndarray) -> np.ndarray:
        return self.leaf_positions_of[kind.name][positions]

    def refit(self, positions: np.ndarray, bounds: np.ndarray):
        """New unwidened bounds of the entries at these leaf positions: the boxes of their leaves and
        of every ancestor recomputed (each after its changed descendants). Returns the changed nodes,
        or None (nothing changed) where the refitted tree's SAH cost exceeds REFIT_COST_MAX times the
        built one's."""
        tree, bvh = self.prepared.bvh.tree, self.prepared.bvh
        ancestors = [np.unique(self.leaf_of[positions])]
        while True:  # every node whose box may change: the leaves, then their ancestors
            up = np.unique(self.parent[ancestors[-1]])
            up = up[up >= 0]
            if not up.size:
                break
            ancestors.append(up)
        every = np.unique(np.concatenate(ancestors))
        old = (tree.lo[every].copy(), tree.hi[every].copy(), bvh.bounds[positions].copy(), self.widened[positions].copy())
        before = float((self._areas(every) * self.weight[every]).sum())
        bvh.bounds[positions] = bounds
        self.widened[positions] = widened(bounds)
        for leaf in ancestors[0]:  # a leaf's box: its entries'
            first, count = tree.first[leaf], tree.count[leaf]
            tree.lo[leaf] = self.widened[first:first + count, 0].min(axis=0)
            tree.hi[leaf] = self.widened[first:first + count, 1].max(axis=0)
        for nodes in ancestors[1:]:  # a level's parents after the level (a node again after a deeper change)
            left, right = tree.first[nodes], tree.first[nodes] + 1
            tree.lo[nodes] = np.minimum(tree.lo[left], tree.lo[right])
            tree.hi[nodes] = np.maximum(tree.hi[left], tree.hi[right])
        after = float((self._areas(every) * self.weight[every]).sum())
        self.cost_sum += after - before
        if self.cost() > PreparedScene.REFIT_COST_MAX * self.built_cost:
            tree.lo[every], tree.hi[every] = old[0], old[1]
            bvh.bounds[positions], self.widened[positions] = old[2], old[3]
            self.cost_sum -= after - before
            return None
        changed = every
        if self.prepared.on_device:
            corners = self.prepared._world_nodes_host.reshape(-1, 2, 4)
            corners[changed, 0, :3], corners[changed, 1, :3] = tree.lo[changed], tree.hi[changed]
        return changed


def prepared_scene(ctx, scene: Scene, precision: str) -> PreparedScene:
    """The scene's shapes prepared on this device at this precision: kept per shapes tuple (a moved
    camera keeps the scene's tuple), built at the first view; a frame of an animation (a tuple that
    pyclray.model.animation says was made from another by changing a few shapes) updates the prepared
    scene of that other tuple in place (PreparedScene.update) instead."""
    shapes = scene.shapes
    key = (ctx.device.int_ptr, id(shapes), precision)
    with render_lock:
        entry = _prepared.get(key)
        if entry is not None and entry.shapes is shapes:
            _prepared.move_to_end(key)
            return entry
    derived = derivation(shapes)
    if derived is not None:
        base, changed = derived
        with render_lock:
            candidates = [(k, p) for k, p in _prepared.items()
                          if p.base is base and k[0] == ctx.device.int_ptr and p.precision == precision]
        for old_key, candidate in candidates:
            with candidate.lock:
                updated = candidate.shapes is not shapes and candidate.update(shapes, changed)
            with render_lock:
                _prepared.pop(old_key, None)
                if updated:
                    _prepared[key] = candidate
                    return candidate
    prepared = PreparedScene(ctx, shapes, precision)
    if derived is not None:
        prepared.base, prepared.dirty = derived[0], set(derived[1])
    with render_lock:
        _prepared[key] = prepared
        while len(_prepared) > 1 and (len(_prepared) > PREPARED_MAX or
                                      sum(p.nbytes() for p in _prepared.values()) > PREPARED_BYTES):
            _prepared.popitem(last=False)
    return prepared


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
    """Refuse more entries of one type than the kernels can index (8 x index + type in 32 bits)."""
    from ..model import scene as scene_model

    for kind in prepared.kinds.values():
        if kind.count > scene_model.MAX_SHAPES:
            raise SceneError(f"{kind.count} {kind.name} primitives; pyclray renders at most {scene_model.MAX_SHAPES} of a "
                             "type (the kernels index one by 8 x its position + its type in 32 bits)")


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
        self.camera = input_buffer(ctx, camera_struct(self.rows, plane, width, height, precision))
        self.tiles = {}
        if acceleration == "tiles":
            for kind in prepared.kinds.values():
                start, index = prepared.tile_lists(kind, self.eye, self.rows, plane, width, height)
                self.tiles[kind.name] = (input_buffer(ctx, start), input_buffer(ctx, index))
        lights = shading.pack_lights(scene, precision)
        real = REAL[precision]
        eye_high = self.eye.astype(real)
        self.lighting = {
            "materials": prepared.materials,
            "lights": input_buffer(ctx, lights),
            "n_lights": np.int32(len(lights)),
            "ambient": np.array((*scene.shading.ambient, 0), real),
            "background": np.array((*scene.shading.background, 0), real),
            # the eye as a sum of two reals, for the position image (kernels/pyclray.cl)
            "eye_high": np.array((*eye_high, 0), real),
            "eye_low": np.array((*(self.eye - eye_high.astype(np.float64)), 0), real),
        }

    def shape_args(self, prepared: PreparedScene, acceleration: str) -> list:
        """The kernel's shape arguments: the BVH (nodes, refs) and per type its frame buffer and
        count, or per type its frame buffer and tile lists (a tuple: the argument of shadow rays
        only, each type's count)."""
        args = []
        if acceleration == "bvh":
            if prepared.bvh.types:
                args += [prepared.nodes, prepared.refs]
            for kind in prepared.kinds.values():
                args += [kind.frame, np.int32(kind.count)]
        else:
            for kind in prepared.kinds.values():
                start, index = self.tiles[kind.name]
                args += [kind.frame, start, index, (np.int32(kind.count),)]
        return args


_views = PerObject(16)


def render_inputs(ctx, scene: Scene, precision: str, acceleration: str):
    """(prepared scene, view inputs) of a render of this scene."""
    prepared = prepared_scene(ctx, scene, precision)
    per_scene = _views.get(scene, dict)
    key = (ctx.device.int_ptr, precision, acceleration)
    inputs = per_scene.get(key)
    if inputs is None:
        inputs = per_scene[key] = ViewInputs(ctx, scene, prepared, acceleration)
    return prepared, inputs


# -- cast: each bounded entry in its own frame (its anchor), the BVH around the scene's anchor ------
_cast_prepared: OrderedDict = OrderedDict()


def cast_inputs(ctx, scene: Scene, precision: str, shape_types) -> tuple[list, np.ndarray]:
    """(arguments, anchor): the BVH around the scene's anchor (its root box's centre), its refs and
    the entries' anchors, and per shape type its packed buffer (each bounded entry relative to its
    own anchor, in leaf order) and count. They depend on the shapes only, never on the rays."""
    key = (ctx.device.int_ptr, id(scene.shapes), precision)
    with render_lock:
        entry = _cast_prepared.get(key)
        if entry is not None and entry[0] is scene.shapes and entry[1] == shape_types:
            _cast_prepared.move_to_end(key)
            return entry[2], entry[3]
    prepared = prepared_scene(ctx, scene, precision)
    tree = prepared.bvh
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
    for name in shape_types:
        kind = prepared.kinds[name]
        if kind.cls.bounded:
            origin = anchors[: len(tree.leaf_type)][tree.leaf_type == tree.types.index(name), :3]
        else:
            origin = np.zeros(3)
        with np.errstate(over="ignore", invalid="ignore"):
            packed = kind.cls.rebase(kind.world, origin, identity, precision, kind.ids, kind.primitives)
        if not all(np.isfinite(packed[field]).all() for field in packed.dtype.names if packed[field].dtype.kind == "f"):
            raise PyclrayError(f"the scene's {name}s are too large for {precision}: their packed values overflow")
        args += [input_buffer(ctx, packed if len(packed) else np.zeros(1, packed.dtype)), np.int32(kind.count)]
    with render_lock:
        _cast_prepared[key] = (scene.shapes, shape_types, args, anchor)
        while len(_cast_prepared) > PREPARED_MAX:
            _cast_prepared.popitem(last=False)
    return args, anchor
