"""An animation's frame on a prepared scene (pyclray.engine.prepared): the shapes it changed written
in place, the BVH refitted above them (or the scene rebuilt where a refit would degrade the tree),
and while the camera stays, the frame buffers brought to the view entry by entry (no whole pass)."""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from . import shading
from .bvh import outward32, sah_cost, widened
from .programs import Variant, kernels_for
from .request import input_buffer


# Rebuilding the scene when the SAH cost of the refitted tree exceeds the built tree's by this
# factor: a refit keeps the tree's topology, so shapes that wander far apart make its boxes
# overlap and rays visit more of them. Measured (bench/views.py, "animation"): 10 of 100,000
# spheres moving across the whole field raise the cost by well under 1%; a refit costs about a
# millisecond where a rebuild of that scene costs half a second.
# (the factor is PreparedScene.REFIT_COST_MAX)


def update(prepared, shapes: tuple, changed) -> bool:
    """Become the prepared scene of ``shapes``, a tuple equal to this scene's but for the shapes at
    ``changed`` (an animation's frame, pyclray.model.animation.derivation): rewrite their world
    entries, their materials and the BVH's boxes above them (a refit), on the host and the device.
    O(K log N) host work for K changed shapes. False (and nothing changed) where the changes need a
    new scene: another type or primitive count, or a refit that would degrade the tree."""
    indices = sorted(set(changed) | prepared.dirty)  # shapes changed before and no longer: back to theirs
    for i in indices:
        if i >= len(shapes) or i >= len(prepared.shapes) or shapes[i].type != prepared.shapes[i].type \
                or shapes[i].primitive_count() != prepared.shapes[i].primitive_count() \
                or prepared.kinds[shapes[i].type].smooth is not None \
                or prepared.kinds[shapes[i].type].indexed is not None:  # its world shading normals, its vertices: packed anew
            return False
    if prepared._refit is None:
        prepared._refit = RefitState(prepared)
    state = prepared._refit
    positions, rows_by_kind, bounds_rows = [], {}, []
    for i in indices:
        kind = prepared.kinds[shapes[i].type]
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
        kind = prepared.kinds[name]
        where, rows = np.concatenate(where), np.concatenate(rows)
        kind.world[where] = rows
        if prepared.on_device or kind.framed:
            prepared.stale.setdefault(name, set()).update(where.tolist())
    if refitted is not None:
        # the boxes around the scene's anchor, as built (prepared.py): written now, whatever the view
        tree = prepared.bvh.tree
        nodes = prepared._nodes_host[refitted].copy()
        nodes["lo"][:, :3], nodes["hi"][:, :3] = outward32(tree.lo[refitted] - prepared.anchor,
                                                           tree.hi[refitted] - prepared.anchor)
        prepared._nodes_host[refitted] = nodes
        if prepared.on_device:
            scatter(prepared, prepared.nodes, refitted, nodes)
        else:  # no float64 program to scatter with: the whole array (devices without float64 only)
            cl.enqueue_copy(prepared.ctx.queue, prepared.nodes, prepared._nodes_host.copy())
    if prepared.on_device and prepared.view is not None:
        # the frame buffers hold the last view: bring the changed entries and nodes to it in place
        # (the same floats as a whole pass: the host's rebase is the device's, bit for bit)
        eye, rows = prepared.view
        for name, (where, _) in rows_by_kind.items():
            kind = prepared.kinds[name]
            if kind.framed:  # no frame buffer: its world entries are what the kernel reads
                continue
            where = np.concatenate(where)
            scatter(prepared, kind.frame, where, kind.cls.rebase(kind.world[where], eye, rows, prepared.precision,
                                                             kind.ids[where], kind.primitives[where]))
    # materials (an animated colour or size): the rows that differ
    # (none where the frame changed no shape: pack_materials gives one row even for no shape)
    materials = shading.pack_materials([shapes[i] for i in indices], prepared.precision)[: len(indices)]
    if len(indices) and not (materials == prepared._materials_host[indices]).all():
        prepared._materials_host[indices] = materials
        cl.enqueue_copy(prepared.ctx.queue, prepared.materials, prepared._materials_host)
    prepared.reach = prepared._reach()
    prepared.shapes, prepared.dirty = shapes, set(changed)
    if not (prepared.on_device and prepared.view is not None):
        prepared.view_key = None  # a whole pass at the next view
    return True


def flush_world(prepared) -> None:
    """Write the world entries that animation frames changed to the device."""
    for name, where in prepared.stale.items():
        where = np.array(sorted(where), np.int64)
        kind = prepared.kinds[name]
        scatter(prepared, kind.world_buffer, where, kind.world[where])
    prepared.stale = {}


def scatter(prepared, buffer, index, rows) -> None:
    """Write rows (structs of a multiple of 16 bytes) at these indices of a device buffer of such
    rows (kernels' scatter_rows)."""
    rows = np.ascontiguousarray(rows)
    if not len(index):
        return
    width = rows.dtype.itemsize // 16
    kernels = kernels_for(prepared.ctx, Variant("rebase", prepared.types, (), prepared.precision))
    index = np.ascontiguousarray(index, np.int32)
    words = rows.view(np.uint8).reshape(-1).view(np.uint32)
    kernels["scatter_rows"](prepared.ctx.queue, (len(index),), None, buffer, input_buffer(prepared.ctx, index),
                            input_buffer(prepared.ctx, words), np.int32(len(index)), np.int32(width))


class RefitState:
    """What refitting a prepared scene's BVH needs, computed at its first update: each node's parent,
    each leaf position's leaf, the entries' widened boxes in leaf order, the built tree's SAH cost,
    and per type its entries sorted by shape id and their leaf positions."""

    def __init__(self, prepared):
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

    def positions(self, kind, shape_index: int) -> np.ndarray:
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

    def leaf_positions(self, kind, positions: np.ndarray) -> np.ndarray:
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
        if self.cost() > self.prepared.REFIT_COST_MAX * self.built_cost:
            tree.lo[every], tree.hi[every] = old[0], old[1]
            bvh.bounds[positions], self.widened[positions] = old[2], old[3]
            self.cost_sum -= after - before
            return None
        return every
