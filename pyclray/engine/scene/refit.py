"""An animation's frame on a prepared scene, as the prepared scene's own methods (Refit, a base of
pyclray.engine.scene.prepared.PreparedScene): the shapes it changed written in place, the BVH
refitted above them (or the scene rebuilt where a refit would degrade the tree), and while the
camera stays, the view buffers brought to the view entry by entry (no whole pass).

A frame where K of N shapes move costs O(K log N) host work and writes O(K log N) rows: on a CPU
device the host arrays are the buffers' memory (buffers.device_buffer) and are written in place;
elsewhere the rows go up with one scatter launch per buffer (kernels' scatter_rows)."""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..bvh.tree import outward32, sah_cost, widened
from ..bvh.wide import pack_wide, row_of
from ..launch.programs import Variant, kernels_for
from ..launch.run import input_buffer
from ..opencl.buffers import shares_host_memory
from . import lighting


# Rebuilding the scene when the SAH cost of the refitted tree exceeds the built tree's by this factor: a
# refit keeps the tree's topology, so shapes that wander far apart make its boxes overlap and rays visit
# more of them; a frame's update costs a small part of a rebuild. The factor is
# PreparedScene.REFIT_COST_MAX (docs/benchmarks.md, "Why the engine does what it does").


class Refit:
    """The prepared scene's own methods for an animation's frame (PreparedScene takes this class
    among its bases): the changed shapes' entries rewritten in place, the tree refitted above them,
    the world entries brought to the device before the next pass, rows scattered on the device."""

    def update_in_place(self, shapes: tuple, changed) -> bool:
        """Become the prepared scene of ``shapes``, a tuple equal to this scene's but for the shapes at
        ``changed`` (an animation's frame, pyclray.model.animation.derivation): rewrite their world
        entries, their materials and the BVH's boxes above them (a refit), on the host and the device.
        O(K log N) host work for K changed shapes. False (and nothing changed) where the changes need a
        new scene: another type or primitive count, or a refit that would degrade the tree."""
        indices = sorted(set(changed) | self.dirty)  # shapes changed before and no longer: back to theirs
        if indices and indices[-1] >= min(len(shapes), len(self.shapes)):
            return False
        new, old = [shapes[i] for i in indices], [self.shapes[i] for i in indices]
        for i, shape, before in zip(indices, new, old):
            kind = self.kinds.get(shape.type)
            if kind is None or shape.type != before.type or shape.primitive_count() != before.primitive_count() \
                    or kind.smooth is not None:  # its world shading normals: packed anew
                return False
            if kind.indexed is not None and not kind.indexed.holds(i, shape):  # shared vertices: as many, in place
                return False
        if self._refit is None:
            self._refit = RefitState(self)
        state = self._refit
        # per type: the changed shapes and their entries' positions in its array, packed in one call
        # (pack_world gives each shape's entries in primitive order, as state.positions lists them)
        by_kind: dict[str, tuple[list, list, list]] = {}
        for i, shape in zip(indices, new):
            mine = by_kind.setdefault(shape.type, ([], [], []))
            mine[0].append(shape)
            mine[1].append(state.positions(self.kinds[shape.type], i))
            mine[2].append(i)
        packed, positions, bounds_rows, moved = {}, [], [], []
        for name, (mine, where, at) in by_kind.items():
            kind = self.kinds[name]
            if kind.indexed is not None:  # shared vertices (engine/scene/indexed.py): each shape's rewritten, its faces' bounds
                for i, shape, mine_where in zip(at, mine, where):
                    world, bounds = kind.indexed.moved_bounds(i, shape, mine_where)
                    moved.append((kind, i, world, shape))
                    positions.append(state.leaf_positions(kind, mine_where))
                    bounds_rows.append(bounds)
                continue
            where = np.concatenate(where)
            packed[name] = (where, kind.cls.pack_world(mine))
            if kind.cls.bounded:
                positions.append(state.leaf_positions(kind, where))
                bounds_rows.append(kind.cls.bounds_of(packed[name][1]))
        refitted = None
        if positions:
            one = len(positions) == 1  # (one bounded type changed: no copies)
            refitted = state.refit(positions[0] if one else np.concatenate(positions),
                                   bounds_rows[0] if one else np.concatenate(bounds_rows))
            if refitted is None:
                return False
        shared = shares_host_memory(self.ctx)
        replaced: dict[str, dict] = {}
        for kind, i, world, shape in moved:  # (brought to the view the view buffers hold, if any)
            kind.indexed.move(self, i, world, shared)
            replaced.setdefault(kind.name, {})[kind.indexed.slots[i]] = shape
        for name, slots in replaced.items():  # the type's shapes too: cast packs its world entries from them
            kind = self.kinds[name]
            items = list(kind.shapes)
            for slot, shape in slots.items():
                items[slot] = shape
            kind.shapes = tuple(items)
        # the world entries; on another device, written to it before the next whole pass or render that
        # reads them (flush_world): while the camera stays, a frame writes only the view buffers
        for name, (where, rows) in packed.items():
            kind = self.kinds[name]
            kind.world[where] = rows
            if not shared and (self.on_device or kind.from_world):
                self.stale.setdefault(name, set()).update(where.tolist())
        if refitted is not None and len(refitted):
            # the boxes around the scene's anchor, as built (prepared.py): written now, whatever the view;
            # the wide tree's nodes that hold a refitted node, and the binary tree's if it was made
            tree = self.bvh.tree
            rows = state.wide_row[refitted]
            rows = np.unique(rows[rows >= 0])
            wide = pack_wide(tree, self.bvh.wide, self.anchor, rows)
            self._wide_host[rows] = wide
            written = [(self.wide_nodes, self._wide_host, rows, wide)]
            if self._nodes_host is not None:
                nodes = self._nodes_host[refitted]
                nodes["lo"][:, :3], nodes["hi"][:, :3] = outward32(tree.lo[refitted] - self.anchor,
                                                                   tree.hi[refitted] - self.anchor)
                self._nodes_host[refitted] = nodes
                written.append((self.nodes, self._nodes_host, refitted, nodes))
            # the pair nodes (a render at a lane width of 1), made anew from the boxes when next asked
            self._pairs = self._pairs_host = None
            if not shared:
                for buffer, host, index, rows_written in written:
                    if self.on_device:
                        self.scatter(buffer, index, rows_written)
                    else:  # no float64 program to scatter with: the whole array (devices without float64 only)
                        cl.enqueue_copy(self.ctx.queue, buffer, host.copy())
            if refitted[0] == 0:  # the root's box (refit returns the nodes sorted): the range check's
                self.reach = self._reach()
        if self.on_device and self.view is not None:
            # the view buffers hold the last view: bring the changed entries to it in place (the same
            # floats as a whole pass: the host's rebase is the device's, bit for bit)
            eye, rows = self.view
            for name, (where, _) in packed.items():
                kind = self.kinds[name]
                if kind.from_world:  # no view buffer: its world entries are what the kernel reads
                    continue
                rebased = kind.cls.rebase(kind.world[where], eye, rows, self.precision, kind.ids[where], kind.primitives[where])
                if shared:
                    kind.in_view_host[where] = rebased
                else:
                    self.scatter(kind.in_view, where, rebased)
        # materials (an animated colour or size): the rows of the shapes whose material is another object
        materials = [(i, shape) for i, shape, before in zip(indices, new, old) if shape.material is not before.material]
        if materials:
            rows = lighting.pack_materials([shape for _, shape in materials], self.precision)
            materials = [i for i, _ in materials]
            if not (rows == self._materials_host[materials]).all():
                self._materials_host[materials] = rows
                if not shared:
                    cl.enqueue_copy(self.ctx.queue, self.materials, self._materials_host)
        self.shapes, self.dirty = shapes, set(changed)
        if not (self.on_device and self.view is not None):
            self.view_key = None  # a whole pass at the next view
        return True

    def flush_world(self) -> None:
        """Write the world entries that animation frames changed to the device (devices whose buffers
        are not the host arrays)."""
        for name, where in self.stale.items():
            where = np.array(sorted(where), np.int64)
            kind = self.kinds[name]
            self.scatter(kind.world_buffer, where, kind.world[where])
        self.stale = {}

    def scatter(self, buffer, index, rows) -> None:
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


class RefitState:
    """What refitting a prepared scene's BVH needs, computed at its first update: each node's parent,
    depth, children and box (as one row), each leaf position's leaf, the entries' widened boxes in
    leaf order, the built tree's SAH cost, and per type its entries sorted by shape id and their
    leaf positions."""

    def __init__(self, prepared):
        tree, bvh = prepared.bvh.tree, prepared.bvh
        self.prepared = prepared
        self.parent = np.full(tree.nodes, -1, np.int64)
        internal = np.nonzero(tree.count == 0)[0] if tree.nodes > 1 else np.zeros(0, np.int64)
        self.parent[tree.first[internal]] = internal
        self.parent[tree.first[internal] + 1] = internal
        # each leaf position's leaf: the leaves' ranges of positions, in order, cover them all
        leaves = np.nonzero(tree.count > 0)[0]
        leaves = leaves[np.argsort(tree.first[leaves], kind="stable")]
        self.leaf_of = np.repeat(leaves, tree.count[leaves]).astype(np.int64)
        # each node's depth (the root's 0), from the root down a level at a time
        self.depth = np.zeros(tree.nodes, np.int64)
        level = internal[:1] if len(internal) and internal[0] == 0 else np.zeros(0, np.int64)
        while level.size:
            children = np.concatenate([tree.first[level], tree.first[level] + 1])
            self.depth[children] = self.depth[level[0]] + 1
            level = children[tree.count[children] == 0]
        self.widened = widened(bvh.bounds) if len(bvh.bounds) else np.zeros((0, 2, 3))
        # each node's box as one row (lo, -hi): the union of boxes is then one elementwise minimum
        # (half the numpy calls per level of a refit); the tree's lo and hi are kept equal to it
        self.box = np.concatenate([tree.lo, -tree.hi], axis=1)
        self.children = np.stack([tree.first, tree.first + 1])  # an internal node's two children
        self.built_cost = sah_cost(tree) if tree.nodes else 0.0
        self.wide_row = row_of(bvh.wide, tree.nodes)  # the wide node holding each binary node
        # the SAH cost's sum (sah_cost before the division by the root's area), kept up to date as
        # nodes change: a frame's check costs O(changed nodes), not a pass over the tree
        self.weight = np.where(tree.count > 0, tree.count, 1).astype(np.float64)
        self.cost_sum = float((self._areas(self.box) * self.weight).sum())
        self.by_id, self.leaf_positions_of, self.found, self.plans = {}, {}, {}, {}
        for k, t in enumerate(bvh.types):
            self.leaf_positions_of[t] = np.nonzero(bvh.leaf_type == k)[0]

    @staticmethod
    def _areas(box) -> np.ndarray:
        """Half the surface area of boxes given as rows (lo, -hi)."""
        extent = np.maximum(-box[:, 3:] - box[:, :3], 0.0)
        return extent[:, 0] * extent[:, 1] + extent[:, 1] * extent[:, 2] + extent[:, 2] * extent[:, 0]

    def cost(self) -> float:
        """The tree's SAH cost as sah_cost computes it (relative to the root's area)."""
        root = self._areas(self.box[:1])[0]
        return self.cost_sum / (root if root > 0 else 1.0)

    def positions(self, kind, shape_index: int) -> np.ndarray:
        """The positions of a shape's entries in its type's array, by primitive index (pack_world's
        order of its entries)."""
        found = self.found.get((kind.name, shape_index))
        if found is None:
            if kind.name not in self.by_id:
                order = np.lexsort((kind.primitives, kind.ids))
                self.by_id[kind.name] = (order, kind.ids[order])
            order, ids = self.by_id[kind.name]
            lo, hi = np.searchsorted(ids, shape_index, "left"), np.searchsorted(ids, shape_index, "right")
            found = self.found[(kind.name, shape_index)] = order[lo:hi]  # an animation asks each frame
        return found

    def leaf_positions(self, kind, positions: np.ndarray) -> np.ndarray:
        return self.leaf_positions_of[kind.name][positions]

    PLANS_MAX = 16

    def plan(self, positions: np.ndarray):
        """What a refit above the entries at these leaf positions visits, kept per set of positions
        (an animation moves the same shapes frame after frame): their leaves, the gather of the
        leaves' entries and where each leaf's start, and the internal ancestors a level at a time,
        deepest first, each level's nodes with their children. Every node the refit writes: every."""
        key = positions.tobytes()
        plan = self.plans.get(key)
        if plan is not None:
            return plan
        tree = self.prepared.bvh.tree
        leaves = np.unique(self.leaf_of[positions])
        # the leaves and their ancestors, walked up in Python (K paths of log N nodes that soon meet)
        every, parent = set(), self.parent
        for node in leaves.tolist():
            while node >= 0 and node not in every:
                every.add(node)
                node = parent.item(node)
        every = np.fromiter(every, np.int64, len(every))
        internal = every[tree.count[every] == 0]
        internal = internal[np.argsort(-self.depth[internal], kind="stable")]  # deepest first
        cuts = [0, *(np.flatnonzero(np.diff(self.depth[internal])) + 1).tolist(), len(internal)]
        levels = [(internal[a:b], self.children[:, internal[a:b]]) for a, b in zip(cuts, cuts[1:])]
        first, count = tree.first[leaves], tree.count[leaves]
        starts = np.cumsum(count) - count
        gather = np.repeat(first - starts, count) + np.arange(int(count.sum()))
        plan = self.plans[key] = (leaves, gather, starts, levels, every)
        while len(self.plans) > self.PLANS_MAX:
            del self.plans[next(iter(self.plans))]
        return plan

    def refit(self, positions: np.ndarray, bounds: np.ndarray):
        """New unwidened bounds of the entries at these leaf positions: the boxes of their leaves and
        of every ancestor recomputed, deepest first (each after its children). Returns the nodes whose
        boxes changed (sorted), or None (nothing changed) where the refitted tree's SAH cost exceeds
        REFIT_COST_MAX times the built one's."""
        tree, bvh = self.prepared.bvh.tree, self.prepared.bvh
        leaves, gather, starts, levels, every = self.plan(positions)
        entries = (bvh.bounds[positions], self.widened[positions])  # copies (fancy indexing)
        old = self.box[every]
        bvh.bounds[positions] = bounds
        self.widened[positions] = widened(bounds)
        # the leaves' boxes: the union of their entries' widened boxes
        boxes = self.widened[gather]
        self.box[leaves] = np.minimum.reduceat(np.concatenate([boxes[:, 0], -boxes[:, 1]], axis=1), starts)
        # the internal nodes', a level at a time: the union of their two children's
        for nodes, children in levels:
            self.box[nodes] = self.box[children].min(axis=0)
        new = self.box[every]
        delta = float((self._areas(new) - self._areas(old)) @ self.weight[every])
        self.cost_sum += delta
        if self.cost() > self.prepared.REFIT_COST_MAX * self.built_cost:
            self.box[every] = old
            bvh.bounds[positions], self.widened[positions] = entries
            self.cost_sum -= delta
            return None
        tree.lo[every], tree.hi[every] = new[:, :3], -new[:, 3:]
        changed = (new != old).any(axis=1)
        return np.sort(every[changed])
