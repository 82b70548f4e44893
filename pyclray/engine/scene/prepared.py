"""The scene on the device: built once per shapes tuple, kept, and rebased for each view.

A PreparedScene holds a scene's shapes on one device at one precision: per shape type its world
entries (float64, camera-independent: ``Shape.pack_world``; a batch contributes one entry per
primitive, never a Python object per primitive), the BVH over the bounded entries (each bounded
type's entries in leaf order), the refs, the materials, and per type a buffer of the entries in a
camera's space, which is what the render kernel's shape tests read. A view rebases that buffer
from the world entries for its camera (kernels/rebase.cl: the differences of coordinates in
float64, what every ray from the eye shares from error-free sums) on the device; the BVH's boxes
stay around the scene's anchor (the kernel takes the eye relative to it); a view with the same
camera as the last rebases nothing. Devices
without float64 rebase on the host (``Shape.rebase``, the same formulas) and upload the result.
So a moved camera uploads the camera only, whatever the number of shapes. A large scene on a device
with float64 is rebased (FROM_WORLD_FROM): its spheres have no view buffer, the render kernel rebases each
where it tests it from its world entry (the same bits). Meshes on a device with float64 are shared
vertices and faces whose vertices the per-view pass rebases (INDEXED, engine/scene/indexed.py), in any scene.

A scene handle (engine/tracer.py) owns one: nothing here is kept between calls. A frame of an
animation (the same shapes, a few moved) updates it in place (``update``): only those entries are
rewritten and the BVH refitted.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from ...model.scene import MAX_LENGTH, Scene
from ...model.shapes import KINDS, REGISTRY
from ...model.shapes.capabilities import capability
from ..bvh import tiles
from ..bvh.scene import SceneBVH, primitives_bvh
from ..launch.programs import Variant, kernels_for
from ..opencl.buffers import aligned, device_buffer as _buffer
from ..opencl.device import has_fp64, launch
from . import instances, lighting
from .indexed import IndexedEntries, indexed_bounds
from .refit import Refit

@dataclass
class Kind:
    """One shape type's entries: world (host, float64; bounded types in the BVH's leaf order), their
    ids and primitive indices, and the device buffers."""

    name: str
    cls: type
    stored_world: np.ndarray | None  # None for indexed entries: world packs them when asked (cast)
    ids: np.ndarray
    stored_primitives: np.ndarray | None  # None for indexed entries: their faces hold them
    world_buffer: cl.Buffer | None  # the world entries on the device (devices with float64)
    # a from-world scene's (devices with float64): its entries' ids and primitive indices, read by the
    # render kernel, which rebases each entry from its world entry where it tests it
    ids_buffer: cl.Buffer | None
    primitives_buffer: cl.Buffer | None
    # elsewhere: the entries in the space of the last view (the render kernel's shape array), and
    # that buffer's memory on a CPU device (its bytes, elsewhere)
    in_view: cl.Buffer | None
    in_view_host: np.ndarray | None
    smooth: cl.Buffer | None = None  # the shading normals of its entries (SmoothShading.pack_smooth), if any
    smooth_host: np.ndarray | None = None
    shared: tuple = ()  # the arrays its entries share (SharedArrays.shared: mesh instances' triangles and BVHs)
    shared_host: tuple = ()
    # the same where a program traverses pair nodes: the trees' pair nodes in place of their binary
    # nodes (PreparedScene.shared_of), made when first asked
    pair_shared: tuple | None = None
    pair_nodes_host: np.ndarray | None = None
    indexed: IndexedEntries | None = None  # a from-world scene's triangles: shared vertices and faces
    shapes: tuple = ()  # its shapes and the leaf order of their entries (indexed: to pack world on demand)
    order: np.ndarray | None = None

    @property
    def world(self) -> np.ndarray:
        """The world entries (an indexed type's packed anew at each call: the scene keeps its vertices
        and faces instead, and only cast asks)."""
        if self.stored_world is not None:
            return self.stored_world
        world = self.cls.pack_world(self.shapes)
        return world if self.order is None else world[self.order]

    @property
    def primitives(self) -> np.ndarray:
        """Each entry's index within its shape."""
        return self.stored_primitives if self.indexed is None else self.indexed.primitives

    @property
    def from_world(self) -> bool:
        """Whether the render kernel rebases its entries where it tests them (no view buffer)."""
        return self.in_view is None

    @property
    def count(self) -> int:
        return len(self.ids)


# Scenes of at least this many entries of the types rebased where tested (Shape.tested_from_world) are
# rebased so; smaller ones keep the per-view copy, which is faster while it fits the caches; rebased
# entries hold a third less memory (docs/benchmarks.md, "Why the engine does what it does":
# FROM_WORLD_FROM). Meshes do not depend on it (INDEXED below).
FROM_WORLD_FROM = 524_288

# Meshes (the capability "indexed") are kept as shared vertices and faces on every device with float64 (engine/
# indexed.py), whatever the scene's size: 44 bytes a triangle and the BVH's share, against 160 for the
# world entries and the per-view copy (docs/benchmarks.md, "Why the engine does what it does":
# INDEXED). Tests set it False to compare with the per-view
# copy (the path of devices without float64, where the winner's normal cannot be computed from
# float64 vertices).
INDEXED = True


_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], bool)  # a box's 8: hi where 1


class PreparedScene(Refit):
    """A scene's shapes on one device at one precision (see the module's docstring)."""

    def __init__(self, ctx, shapes: tuple, precision: str):
        self.ctx, self.shapes, self.precision = ctx, shapes, precision
        self.lock = threading.RLock()  # one view at a time uses the view buffers
        self.view_key = self.view = None  # the camera the view buffers hold: (eye, rows) bytes, arrays
        by_type: dict = {}
        for index, shape in enumerate(shapes):
            by_type.setdefault(shape.type, ([], []))
            by_type[shape.type][0].append(shape)
            by_type[shape.type][1].append(index)
        # a type may pack some of its shapes as another kind (the capability "instancing": meshes that
        # share their arrays as instances, whose kernel needs float64; elsewhere each mesh is its own triangles)
        if has_fp64(ctx.device):
            packed: dict = {}
            for t, (mine, ids) in by_type.items():
                cls = REGISTRY[t]
                packed.update(cls.packed_as(mine, ids) if capability(cls, "instancing") else {t: (mine, ids)})
            by_type = packed
        self.types = tuple(t for t in KINDS if t in by_type)
        # Meshes are shared vertices and faces wherever the device has float64 (engine/scene/indexed.py):
        # their world entries are never packed, their bounds come from the vertices and faces
        self.indexed = has_fp64(ctx.device) and INDEXED
        # the others, a per-view pass rebases into the camera's space: on the device (kernels/rebase.cl,
        # float64) where it has float64, else on the host (Shape.rebase, the same operations)
        self.on_device = has_fp64(ctx.device)
        worlds, bounds, shared, counts = {}, {}, {}, {}
        for t in self.types:
            cls = KINDS[t]
            mine, ids = by_type[t]
            entry_ids, primitives = cls.entries_of(mine, ids)
            if self.indexed and capability(cls, "indexed"):
                vertices, faces = cls.pack_indexed(mine)
                worlds[t] = ((vertices, faces, tuple(ids)), entry_ids, primitives, None)
                with np.errstate(over="ignore", invalid="ignore"):
                    bounds[t] = indexed_bounds(vertices, faces)
                counts[t] = len(faces)
                continue
            world = cls.pack_world(mine)
            smooth = cls.pack_smooth(mine, precision) if capability(cls, "smooth_shading") else None
            worlds[t] = (world, entry_ids, primitives, smooth)
            counts[t] = len(world)
            if capability(cls, "shared"):  # before the entries are reordered: the shared arrays say where each starts
                shared[t] = instances.pack_shared(cls, mine, world)
            if cls.bounded:
                with np.errstate(over="ignore", invalid="ignore"):
                    bounds[t] = cls.bounds_of(world)
        with np.errstate(over="ignore", invalid="ignore"):  # geometry beyond range: refused by the range check
            self.bvh: SceneBVH = primitives_bvh(bounds)
        # Large scenes on devices with float64 rebase each shape of the types that allow it on the eye
        # where the render kernel tests it, from its world entry (Variant.from_world, Shape.tested_from_world):
        # no per-view copy of those entries, no pass over them for a new camera (see FROM_WORLD_FROM).
        from_world_entries = sum(counts[t] for t in self.types if KINDS[t].tested_from_world)
        self.from_world = has_fp64(ctx.device) and from_world_entries >= FROM_WORLD_FROM
        self.kinds: dict[str, Kind] = {}
        for t in self.types:
            world, ids, primitives, smooth = worlds[t]
            order = self.bvh.order.get(t)  # bounded: in leaf order
            if order is not None:
                ids, primitives = ids[order], primitives[order]
                if not isinstance(world, tuple):
                    world = world[order]
                smooth = None if smooth is None else smooth[order]
            self.kinds[t] = self._kind(t, world, ids, primitives, tuple(by_type[t][0]), order)
            indexed = self.kinds[t].indexed
            if indexed is not None:  # its shading normals per shared vertex
                self.kinds[t].smooth_host, self.kinds[t].smooth = indexed.smooth_host, indexed.smooth
            elif smooth is not None:
                self.kinds[t].smooth_host = aligned(smooth)
                self.kinds[t].smooth = _buffer(ctx, self.kinds[t].smooth_host)
            if t in shared:
                self.kinds[t].shared_host = tuple(aligned(a) for a in shared[t])
                self.kinds[t].shared = tuple(_buffer(ctx, a) for a in self.kinds[t].shared_host)
        # the types lit by their shapes' own normals (smooth meshes): the shaded image's variant
        self.smooth = tuple(t for t in self.types if self.kinds[t].smooth is not None)
        self.bounded = sum(k.count for k in self.kinds.values() if k.cls.bounded)
        self.wide_nodes = self.refs = None
        self._nodes = self._nodes_host = None  # the binary nodes: made when first asked (see nodes)
        self._pairs = self._pairs_host = None  # the pair nodes: made when first asked (see pair_nodes)
        # The BVH's boxes around a fixed anchor, the root box's centre, rounded outward to float once:
        # a view passes the eye relative to the anchor (and a margin over its rounding) instead of
        # re-expressing every box around the eye (kernels/bvh_packet.h: box_entries).
        self.anchor = np.zeros(3)
        if self.bvh.types:
            with np.errstate(over="ignore", invalid="ignore"):
                anchor = 0.5 * self.bvh.tree.lo[0] + 0.5 * self.bvh.tree.hi[0]
            self.anchor = anchor if np.isfinite(anchor).all() else np.zeros(3)
            # render's camera packets traverse the wide tree (kernels/bvh_wide_packet.h: PYCLRAY_TRAVERSE_PACKET_WIDE)
            with np.errstate(over="ignore", invalid="ignore"):
                self._wide_host = aligned(self.bvh.nodes(self.anchor))
            self.wide_nodes = _buffer(ctx, self._wide_host, writable=True)
            # one bounded type: leaf position q is entry q of its array, which the kernel knows
            # (PYCLRAY_ONE_BOUNDED): a placeholder instead of the refs
            one = len(self.bvh.types) == 1
            self._refs_host = aligned(np.zeros(1, np.int32) if one else self.bvh.refs(self.types))
            self.refs = _buffer(ctx, self._refs_host)
        with np.errstate(over="ignore", invalid="ignore"):
            self._materials_host = aligned(lighting.pack_materials(shapes, precision))
        self.base, self.dirty = shapes, set()  # see update
        self.stale: dict = {}  # type name (or "nodes") -> world entries changed on the host only
        self._refit = None
        self.materials = _buffer(ctx, self._materials_host)
        self.reach = self._reach()

    @property
    def nodes(self) -> cl.Buffer | None:
        """The binary tree's nodes on the device (the same boxes as the wide tree's, around the anchor),
        made when first asked: only shadow rays traverse it (kernels/shading.h), so a scene that casts
        none holds the wide tree only (a million spheres: 12.7 bytes a sphere fewer)."""
        if self._nodes is None and self.bvh.types:
            with self.lock:
                if self._nodes is None:
                    with np.errstate(over="ignore", invalid="ignore"):
                        self._nodes_host = aligned(self.bvh.binary_nodes(self.anchor))
                    self._nodes = _buffer(self.ctx, self._nodes_host, writable=True)
        return self._nodes

    @property
    def pair_nodes(self) -> cl.Buffer | None:
        """The pair nodes on the device (one ray per work-item: bvh/pairs.py; the binary tree's
        boxes around the anchor), made when first asked: only a render at a lane width of 1 (GPUs)
        traverses them."""
        if self._pairs is None and self.bvh.types:
            with self.lock:
                if self._pairs is None:
                    with np.errstate(over="ignore", invalid="ignore"):
                        # (from the binary nodes where made: the same boxes, packed once)
                        self._pairs_host = aligned(self.bvh.pair_nodes(self.anchor, self._nodes_host))
                    self._pairs = _buffer(self.ctx, self._pairs_host)
        return self._pairs

    def shared_of(self, kind: Kind, pairs: bool) -> tuple:
        """The arrays the kind's entries share, on the device (Kind.shared); pairs: for a program that
        traverses pair nodes (Variant.through_pairs), where the trees among them (of BvhNode) are
        their pair nodes instead (engine/scene/instances.py: pair_nodes), made when first asked:
        only a GPU's lane width traverses them."""
        if not pairs or not kind.shared:
            return kind.shared
        if kind.pair_shared is None:
            with self.lock:
                if kind.pair_shared is None:
                    tree = [c_type for _, c_type in kind.cls.shared].index("BvhNode")
                    kind.pair_nodes_host = aligned(instances.pair_nodes(kind.shared_host[tree], kind.world["root"]))
                    kind.pair_shared = (*kind.shared[:tree], _buffer(self.ctx, kind.pair_nodes_host), *kind.shared[tree + 1:])
        return kind.pair_shared

    # A refit keeps the tree's topology: shapes that wander far apart make its boxes overlap and
    # rays visit more of them. A frame rebuilds the scene where the refitted tree's SAH cost exceeds
    # the built tree's by this factor (docs/benchmarks.md, "Why the engine does what it does": REFIT_COST_MAX).
    REFIT_COST_MAX = 1.5

    def update(self, shapes: tuple, changed) -> bool:
        """Become the prepared scene of an animation's frame (Refit.update_in_place); a
        scene with shared arrays (mesh instances) is built anew."""
        if any(capability(kind.cls, "shared") for kind in self.kinds.values()):
            return False
        return self.update_in_place(shapes, changed)

    def _kind(self, t, world, ids, primitives, shapes, order) -> Kind:
        # a type is present only with a shape of it, and every shape is at least one entry
        cls = KINDS[t]
        if isinstance(world, tuple):  # shared vertices and faces (engine/scene/indexed.py)
            indexed = IndexedEntries(self, cls, shapes, *world, order, ids)
            return Kind(t, cls, None, indexed.ids, None, None, None, None, None, None, indexed=indexed, shapes=shapes,
                        order=order)
        world = aligned(world)
        from_world = self.from_world and cls.tested_from_world
        world_buffer = _buffer(self.ctx, world) if self.on_device or from_world else None
        if from_world:
            ids, primitives = aligned(np.ascontiguousarray(ids, np.int32)), aligned(np.ascontiguousarray(primitives, np.int32))
            return Kind(t, cls, world, ids, primitives, world_buffer, _buffer(self.ctx, ids), _buffer(self.ctx, primitives),
                        None, None)
        rebased = aligned(np.zeros(len(world), dtype=cls.rebase(world[:0], np.zeros(3), np.eye(3), self.precision).dtype))
        rebased["id"], rebased["primitive"] = ids, primitives
        return Kind(t, cls, world, ids, primitives, world_buffer, None, None, _buffer(self.ctx, rebased, writable=True), rebased)

    def nbytes(self) -> int:
        """The bytes this scene holds (host arrays shared with a CPU device counted once)."""
        total = self._materials_host.nbytes
        for kind in self.kinds.values():
            if kind.indexed is not None:
                total += kind.indexed.nbytes()
            elif kind.from_world:
                total += kind.world.nbytes + kind.ids.nbytes + kind.primitives.nbytes
            else:
                total += kind.world.nbytes + kind.in_view_host.nbytes
            total += 0 if kind.smooth_host is None else kind.smooth_host.nbytes
            total += sum(a.nbytes for a in kind.shared_host)
            total += 0 if kind.pair_nodes_host is None else kind.pair_nodes_host.nbytes
        if self.bvh.types:
            total += self._wide_host.nbytes + self._refs_host.nbytes
            total += 0 if self._nodes_host is None else self._nodes_host.nbytes
            total += 0 if self._pairs_host is None else self._pairs_host.nbytes
        return total

    # -- the range check, once per view in O(1) ---------------------------------------------------
    def _reach(self):
        """(root box corners (8, 3), root box diagonal) of the bounded entries, or None."""
        if not self.bvh.types:
            return None
        lo, hi = self.bvh.tree.lo[0], self.bvh.tree.hi[0]
        corners = np.where(_CORNERS, hi, lo)  # (one call: an animation's frame recomputes it when the root moves)
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
        """Bring the view buffers to this camera (eye: float64 (3,); rows: its axes u, v, w in
        world coordinates). Call with self.lock held, and keep it until the kernels that read the
        buffers are enqueued (the device's in-order queue runs them before a later view's pass).
        Returns the uploads of host arrays it enqueued (pyopencl events that hold the arrays): keep
        them until those kernels have run."""
        eye = np.asarray(eye, np.float64)
        rows = np.asarray(rows, np.float64)
        key = (eye.tobytes(), rows.tobytes())
        self.flush_world()  # the world entries animation frames changed (from-world types read them)
        if key == self.view_key:
            return []
        queue = self.ctx.queue
        uploads = []
        if self.on_device:
            kernels = kernels_for(self.ctx, Variant("rebase", self.types, (), self.precision))
            space = [np.append(v, 0.0).view(cl.cltypes.double4)[0] for v in (eye, *rows)]
        for kind in self.kinds.values():
            if kind.indexed is not None:  # the shared vertices
                kind.indexed.rebase(self, eye, rows)
                continue
            if not kind.count or kind.from_world:  # rebased: the kernel rebases each entry on this eye itself
                continue
            if self.on_device:
                # its scalars' types declared once (device.launch)
                launch(self.ctx, kernels[f"rebase_{kind.name}"], *self._groups(kind.count),
                       [kind.world_buffer, kind.in_view, np.int32(kind.count), *space])
            else:  # a device without float64
                packed = kind.cls.rebase(kind.world, eye, rows, self.precision, kind.ids, kind.primitives)
                uploads.append(cl.enqueue_copy(queue, kind.in_view, packed, is_blocking=False))
        self.view_key, self.view = key, (eye, rows)
        return uploads

    GROUP = 256

    def _groups(self, count: int):
        """(global size, local size) of a pass over count entries: work-groups of GROUP work-items
        (or the device's most), the count rounded up (the kernels skip the rest). Left to itself, PoCL
        divides a count like 70,669 into tiny work-groups (docs/benchmarks.md: PreparedScene.GROUP)."""
        group = min(self.GROUP, self.ctx.device.max_work_group_size)
        return (-(-count // group) * group,), (group,)

    def tile_lists(self, kind: Kind, eye, rows, plane, width, height):
        """(start, index) of the kind's entries for each screen tile of this view (tiles.tile_lists)."""
        spheres = kind.cls.spheres_of(kind.world) if kind.cls.bounded else None
        return tiles.tile_lists(kind.cls.bounded, spheres, kind.count, eye, rows, plane, width, height)

    def tile_lists_in_rects(self, kind: Kind, eye, rows, rects, tiles_x, tiles_y):
        """(start, index) of the kind's entries for each tile of a view whose camera's rays are a
        table (a lens, a panorama), its tiles' rays bounded by rects (tiles.table_rects)."""
        spheres = kind.cls.spheres_of(kind.world) if kind.cls.bounded else None
        return tiles.tile_lists_in_rects(kind.cls.bounded, spheres, kind.count, eye, rows, rects, tiles_x, tiles_y)
