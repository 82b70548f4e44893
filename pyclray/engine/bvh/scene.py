"""The BVH over a scene's bounded primitives (a shape is one primitive, a batch many), with what the
packers need of it: each bounded type's entries in leaf order, the refs, the anchors of cast."""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ...model.shapes import KINDS
from .pairs import leaf_codes, pack_pairs
from .tree import BINARY_STACK, BVH, LEAF_SIZE, SAH_FROM, SCENE_LEAF_SIZE, SCENE_TRAVERSAL, WIDEN, build, pack_nodes, widened
from .wide import STACK, WIDTH, WideBVH, collapse, pack_wide


@dataclass(frozen=True)
class SceneBVH:
    """The BVH over a scene's bounded primitives: per leaf position, the primitive's type and its
    index in that type's array (which is in leaf order), each type's permutation into leaf order,
    and the primitives' unwidened bounds in leaf order (cast's anchors, an animation's refit)."""

    tree: BVH
    types: tuple[str, ...]  # the bounded types present, in the registry's order
    leaf_type: np.ndarray  # (N,) index into types
    leaf_index: np.ndarray  # (N,) index in its type's (leaf-ordered) array
    order: dict  # type -> int64 array: its entries' positions (in the type's array as given) in leaf order
    given_bounds: np.ndarray  # (N, 2, 3) in the order given (the types' arrays one after the other)

    @cached_property
    def bounds(self) -> np.ndarray:
        """(N, 2, 3) the unwidened bounds in leaf order, gathered when first asked (cast, a refit: a
        render needs none of it; docs/benchmarks.md, "Why the engine does what it does")."""
        return self.given_bounds[self.tree.order]

    @cached_property
    def wide(self) -> WideBVH:
        """The wide tree, which render's packets and cast's single rays traverse (made at the scene's
        preparation, prepared.py)."""
        if not len(self.given_bounds):  # no bounded shapes: no tree to traverse (the kernels then have no BVH at all)
            return WideBVH(np.full((1, WIDTH), -1, np.int64), np.zeros((1, WIDTH), np.int32), 1)
        return collapse(self.tree)

    def nodes(self, origin) -> np.ndarray:
        """The wide nodes with their boxes relative to origin (see pack_wide)."""
        return pack_wide(self.tree, self.wide, origin)

    def binary_nodes(self, origin) -> np.ndarray:
        """The binary nodes with their boxes relative to origin (see pack_nodes)."""
        return pack_nodes(self.tree, origin)

    def pair_nodes(self, origin, binary=None, wide_child=None) -> np.ndarray:
        """The pair nodes (one ray per work-item: bvh/pairs.py) with their boxes relative to origin;
        binary: the binary nodes already packed around origin, if made; wide_child: the wide
        nodes' packed codes where cast's regroup rewrote their leaves."""
        binary = self.binary_nodes(origin) if binary is None else binary
        return pack_pairs(self.tree, binary, leaf_codes(self.tree, self.wide if wide_child is not None else None, wide_child))

    def refs(self, shape_types) -> np.ndarray:
        """refs[q] = index * 16 + kind (kernels/shapes.h: KIND_<Type> = 1 + its place among the
        program's shape types). Each type's entries lie in leaf order, so with one bounded type
        index = q (the render kernel's PYCLRAY_ONE_BOUNDED relies on it)."""
        kinds = np.array([1 + list(shape_types).index(t) for t in self.types], np.int64)
        refs = self.leaf_index * 16 + kinds[self.leaf_type]
        return (refs if refs.size else np.zeros(1, np.int64)).astype(np.int32)

    def anchors(self, positions=None) -> np.ndarray:
        """(N, 4) float64 per leaf position: the centre A of the primitive's box (its packing space
        in cast) and a bounding radius R about it: half the box's diagonal, with a margin over the
        shape test's rounding (no hit the test reports lies nearer than (A - O).D - R). Of the
        given positions only, where given (their bounds gathered without keeping them)."""
        if positions is None:
            bounds = self.bounds
        elif "bounds" in self.__dict__:  # gathered, and written by a refit since (the given ones are the build's)
            bounds = self.__dict__["bounds"][positions]
        else:
            bounds = self.given_bounds[self.tree.order[positions]]
        lo, hi = bounds[:, 0], bounds[:, 1]
        out = np.empty((max(len(lo), 1), 4))
        out[: len(lo), :3] = 0.5 * (lo + hi)
        out[: len(lo), 3] = 0.5 * np.linalg.norm(hi - lo, axis=1) * (1 + WIDEN)
        return out


def primitives_bvh(bounds_by_type: dict) -> SceneBVH:
    """The BVH of the bounded primitives given as type -> (N_t, 2, 3) world bounds (in the order of
    the types' arrays; the types in the registry's order)."""
    types = tuple(t for t, b in bounds_by_type.items() if len(b))
    bounds = [bounds_by_type[t] for t in types]
    bounds = np.concatenate(bounds) if bounds else np.zeros((0, 2, 3))
    type_of = np.concatenate([np.full(len(bounds_by_type[t]), k) for k, t in enumerate(types)] or [np.zeros(0, int)])
    within = np.concatenate([np.arange(len(bounds_by_type[t])) for t in types] or [np.zeros(0, int)])
    # leaves as large as the largest of the types' (Shape.leaf_size: a mesh's triangles), else LEAF_SIZE;
    # a large scene's SAH tree is built for render's packets (bvh.SCENE_LEAF_SIZE, SCENE_TRAVERSAL)
    leaf_size = max([KINDS[t].leaf_size or LEAF_SIZE for t in types] or [LEAF_SIZE])
    if len(bounds) >= SAH_FROM:
        leaf_size = max(leaf_size, SCENE_LEAF_SIZE)
    tree = build(widened(bounds), leaf_size, traversal=SCENE_TRAVERSAL)
    leaf_type = type_of[tree.order]
    leaf_index = np.zeros(len(tree.order), np.int64)
    order = {}
    for k, t in enumerate(types):
        mine = leaf_type == k
        leaf_index[mine] = np.arange(int(mine.sum()))
        order[t] = within[tree.order[mine]]
    out = SceneBVH(tree, types, leaf_type, leaf_index, order, bounds)
    # the kernels' stacks: a binary level per entry, a wide level (no more levels than the binary
    # tree's) 7 entries; the wide tree is made here only where the binary depth leaves a doubt
    depth = tree.depth()
    if depth > BINARY_STACK or (7 * depth + 1 > STACK and 7 * out.wide.depth + 1 > STACK):
        raise ValueError(f"the BVH is {depth} binary levels deep, more than the kernels' stacks hold")
    return out


def scene_bvh(shapes, registry) -> SceneBVH:
    """The BVH of these shapes' bounded primitives (registry: type name -> shape class)."""
    bounds = {}
    for t, cls in registry.items():
        mine = [s for s in shapes if s.type == t]
        if cls.bounded and mine:
            bounds[t] = cls.world_bounds(mine)
    return primitives_bvh(bounds)
