"""An animation's frames as collections (pyclray.model.animation.scene_at): a scene's shapes tuple once
checked, and which tuple it was made from by changing which shapes (its derivation: the engine
updates a prepared scene in place for those only); the frame's tuple made in one pass; and
FrameShapes, a frame's shapes held as the animated scene's tuple and the changed ones
(render_animation's frames). What is known of a tuple is held by the tuple itself, not in a table
keyed by its id()."""
from __future__ import annotations

import operator
import threading
from collections.abc import Sequence


class CheckedShapes(tuple):
    """A scene's shapes, checked (pyclray.model.scene.Scene keeps its shapes as this once it has
    looked at each: a view from another camera, ``dataclasses.replace(scene, camera=...)``, does not
    walk a million shapes again), and ``derived``: None, or (the base CheckedShapes, the indices of
    the shapes that differ) where an animation's frame (or an edited file's reload) made it from
    another tuple by replacing a few shapes. Equal to, and hashed as, the plain tuple."""

    derived = None

    def __reduce__(self):  # pickled (a Dask worker's scene) without its derivation: a base is not sent
        return (CheckedShapes, (tuple(self),))


def derivation(shapes):
    """(base shapes tuple, changed indices) if this tuple was made by scene_at from another, else None."""
    return getattr(shapes, "derived", None)


def derived(shapes, base: tuple, changed) -> CheckedShapes:
    """``shapes`` (a sequence) as a CheckedShapes made from ``base`` by changing ``changed``."""
    if not isinstance(shapes, (CheckedShapes, FrameShapes)):
        shapes = CheckedShapes(shapes)
    shapes.derived = (base, tuple(changed))
    return shapes


def derived_from(shapes: tuple, base: tuple):
    """``shapes``, recorded as ``base`` but for the shapes that are not base's own objects (as an
    animation's frame is): the scene prepared for ``base`` is then updated in place for it. For a
    scene file loaded again after an edit (``pyclray view``), whose unchanged shapes are the old
    objects; a tuple of another length is returned as it is."""
    shapes = tuple(shapes)
    if len(shapes) != len(base):
        return shapes
    return derived(shapes, base, (i for i, (a, b) in enumerate(zip(shapes, base)) if a is not b))


class FrameShapes(Sequence):
    """The shapes of an animation's frame as render_animation renders it: the animated scene's tuple
    with a few shapes replaced, held as that tuple and the replacements (O(K) to make, where a tuple of
    N shapes touches every shape twice, to make it and to free it; docs/benchmarks.md, "Why the engine
    does what it does"). Read-only and equal to the tuple it stands for; iterating it walks the N shapes
    (nothing on a frame's render path does)."""

    __slots__ = ("base", "replaced", "derived")

    def __init__(self, base: tuple, replaced: dict[int, object]):
        self.base, self.replaced, self.derived = base, replaced, None

    def __len__(self) -> int:
        return len(self.base)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return tuple(self)[index]
        index = operator.index(index)
        shape = self.base[index]  # (raises IndexError as the tuple does)
        return self.replaced.get(index if index >= 0 else index + len(self.base), shape)

    def __iter__(self):
        items = list(self.base)  # a copy of the pointers at C speed, then the K replacements
        for index, shape in self.replaced.items():
            items[index] = shape
        return iter(items)

    def __eq__(self, other) -> bool:
        return isinstance(other, (tuple, FrameShapes)) and len(other) == len(self) and all(a is b or a == b for a, b in zip(self, other))

    def __hash__(self) -> int:
        return hash(tuple(self))

    def __repr__(self) -> str:
        return f"FrameShapes({len(self.base)} shapes, {len(self.replaced)} replaced)"


class FrameWork:
    """A frame's copy of each animated collection of one animated scene (shapes, lights), kept from
    frame to frame with the items the last frame replaced: a frame puts those back and replaces its
    own, then makes its tuple in one pass (the collection's pointers copied once, O(K) Python work
    for K changes) where copying the collection to a list, changing it and making a tuple of that
    walked it three times (docs/benchmarks.md, "Why the engine does what it does"). The animated
    scene holds it (Scene.frame_work)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.collections: dict[str, tuple[list, set]] = {}

    def frame_tuple(self, base: tuple, collection: str, replaced: dict[int, object]) -> tuple:
        """The collection ``base`` with the items at replaced's indices replaced (the shapes as a
        CheckedShapes: their derivation is recorded on it)."""
        with self.lock:
            entry = self.collections.get(collection)
            if entry is None:
                entry = self.collections[collection] = (list(base), set())
            items, last = entry
            for index in last - replaced.keys():  # the last frame's, back to the animated scene's
                items[index] = base[index]
            for index, item in replaced.items():
                items[index] = item
            last.clear()
            last.update(replaced)
            return (CheckedShapes if collection == "shapes" else tuple)(items)
