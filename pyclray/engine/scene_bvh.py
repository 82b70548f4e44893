"""The BVH of a scene's bounded shapes, with what the packers need of it (leaf order per shape
type, ids, anchors)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .bvh import BINARY_STACK, BVH, WIDEN, build, pack_nodes, widened
from .bvh_wide import STACK, WIDTH, WideBVH, collapse, pack_wide


@dataclass(frozen=True)
class SceneBVH:
    """The BVH over a scene's bounded shapes, with what the packers need: per leaf position, the
    shape's type and its index in that type's array, the types' shapes (and ids) in leaf order,
    and the shapes' unwidened bounds in leaf order (cast's anchors)."""

    tree: BVH
    wide: WideBVH
    types: tuple[str, ...]  # the bounded types present, in the registry's order
    leaf_type: np.ndarray  # (N,) index into types
    leaf_index: np.ndarray  # (N,) index in its type's array
    shapes: dict  # type -> list of its shapes in leaf order
    ids: dict  # type -> int32 array of their ids
    bounds: np.ndarray  # (N, 2, 3) in leaf order

    def nodes(self, origin) -> np.ndarray:
        """The wide nodes with their boxes relative to origin (see pack_wide)."""
        return pack_wide(self.tree, self.wide, origin)

    def binary_nodes(self, origin) -> np.ndarray:
        """The binary nodes with their boxes relative to origin (see pack_nodes)."""
        return pack_nodes(self.tree, origin)

    def refs(self, shape_types) -> np.ndarray:
        """refs[q] = index * 8 + kind (kernels/pyclray.cl: KIND_<Type> = 1 + its place among the
        program's shape types)."""
        kinds = np.array([1 + list(shape_types).index(t) for t in self.types], np.int64)
        refs = self.leaf_index * 8 + kinds[self.leaf_type]
        return (refs if refs.size else np.zeros(1, np.int64)).astype(np.int32)

    def anchors(self) -> np.ndarray:
        """(N, 4) float64 per leaf position: the centre A of the shape's box (its packing frame in
        cast) and a bounding radius R about it: half the box's diagonal, with a margin over the
        shape test's rounding (no hit the test reports lies nearer than (A - O).D - R)."""
        lo, hi = self.bounds[:, 0], self.bounds[:, 1]
        out = np.empty((max(len(lo), 1), 4))
        out[: len(lo), :3] = 0.5 * (lo + hi)
        out[: len(lo), 3] = 0.5 * np.linalg.norm(hi - lo, axis=1) * (1 + WIDEN)
        return out


def scene_bvh(shapes, registry) -> SceneBVH:
    """The BVH of these shapes' bounded ones (registry: type name -> shape class)."""
    types = tuple(t for t, cls in registry.items() if cls.bounded and any(s.type == t for s in shapes))
    by_type = {t: ([], []) for t in types}
    for index, shape in enumerate(shapes):
        if shape.type in by_type:
            by_type[shape.type][0].append(shape)
            by_type[shape.type][1].append(index)
    bounds = [registry[t].world_bounds(by_type[t][0]) for t in types]
    bounds = np.concatenate(bounds) if bounds else np.zeros((0, 2, 3))
    type_of = np.concatenate([np.full(len(by_type[t][0]), k) for k, t in enumerate(types)] or [np.zeros(0, int)])
    within = np.concatenate([np.arange(len(by_type[t][0])) for t in types] or [np.zeros(0, int)])
    tree = build(widened(bounds))
    leaf_type = type_of[tree.order]
    leaf_index = np.zeros(len(tree.order), np.int64)
    ordered, ids = {}, {}
    for k, t in enumerate(types):
        mine = leaf_type == k
        leaf_index[mine] = np.arange(int(mine.sum()))
        positions = within[tree.order[mine]]
        ordered[t] = [by_type[t][0][p] for p in positions]
        ids[t] = np.array(by_type[t][1], np.int64)[positions].astype(np.int32)
    if len(bounds):
        wide = collapse(tree)
    else:  # no bounded shapes: no tree to traverse (the kernels then have no BVH at all)
        wide = WideBVH(np.full((1, WIDTH), -1, np.int64), np.zeros((1, WIDTH), np.int32), 1)
    if tree.depth() > BINARY_STACK or 7 * wide.depth + 1 > STACK:
        raise ValueError(f"the BVH is {wide.depth} wide levels deep, more than the kernel's stack holds")
    return SceneBVH(tree, wide, types, leaf_type, leaf_index, ordered, ids, bounds[tree.order])
