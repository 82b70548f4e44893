"""An animation's frames as collections (pyclray.model.animation.scene_at): which shapes tuple was
made from which by changing which shapes (derivation: the engine updates a prepared scene in place
for those only), the frame's tuple made in one pass, and FrameShapes, a frame's shapes held as the
animated scene's tuple and the changed ones (render_animation's frames)."""
from __future__ import annotations

import operator
import threading
from collections.abc import Sequence


# What an animation's static scenes share with the animated one: new shapes tuple -> (the tuple,
# the animated scene's tuple, the indices of the shapes whose values differ). The engine reads it to
# update a prepared scene in place (only those shapes, and a refit of its BVH) rather than prepare a
# frame's scene from nothing; an entry holds both tuples, so their id()s cannot be reused meanwhile.
_DERIVED_MAX = 8
_derived: dict = {}


def derivation(shapes: tuple):
    """(base shapes tuple, changed indices) if this tuple was made by scene_at from another, else None."""
    entry = _derived.get(id(shapes))
    return entry[1:] if entry is not None and entry[0] is shapes else None


def _remember(shapes: tuple, base: tuple, changed: tuple) -> None:
    _derived[id(shapes)] = (shapes, base, changed)
    while len(_derived) > _DERIVED_MAX:
        del _derived[next(iter(_derived))]


def derived_from(shapes: tuple, base: tuple) -> tuple:
    """``shapes``, recorded as ``base`` but for the shapes that are not base's own objects (as an
    animation's frame is): the scene prepared for ``base`` is then updated in place for it. For a
    scene file loaded again after an edit (``pyclray view``), whose unchanged shapes are the old
    objects; a tuple of another length is returned as it is."""
    shapes = tuple(shapes)
    if len(shapes) == len(base):
        _remember(shapes, base, tuple(i for i, (a, b) in enumerate(zip(shapes, base)) if a is not b))
    return shapes


class FrameShapes(Sequence):
    """The shapes of an animation's frame as render_animation renders it: the animated scene's tuple
    with a few shapes replaced, held as that tuple and the replacements (O(K) to make, where a tuple of
    N shapes touches every shape twice, to make it and to free it; docs/benchmarks.md, "Why the engine
    does what it does"). Read-only and equal to the tuple it stands for; iterating it walks the N shapes
    (nothing on a frame's render path does)."""

    __slots__ = ("base", "replaced")

    def __init__(self, base: tuple, replaced: dict[int, object]):
        self.base, self.replaced = base, replaced

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


# A frame's copy of each animated collection of a scene (shapes, lights), kept from frame to frame with
# the items the last frame replaced: a frame puts those back and replaces its own, then makes its tuple
# in one pass (the collection's pointers copied once, O(K) Python work for K changes) where copying the
# collection to a list, changing it and making a tuple of that walked it three times
# (docs/benchmarks.md, "Why the engine does what it does"). Kept for the last few animated scenes.
_WORKING_MAX = 4
_working: dict = {}
_working_lock = threading.Lock()


def _frame_tuple(scene, collection: str, replaced: dict[int, object]) -> tuple:
    """The scene's collection with the items at replaced's indices replaced."""
    base = getattr(scene, collection)
    with _working_lock:
        entry = _working.get((id(scene), collection))
        if entry is None or entry[0] is not scene:
            entry = _working[(id(scene), collection)] = (scene, list(base), set())  # holds the scene: its id() is not reused meanwhile
            while len(_working) > _WORKING_MAX:
                del _working[next(iter(_working))]
        _, items, last = entry
        for index in last - replaced.keys():  # the last frame's, back to the animated scene's
            items[index] = base[index]
        for index, item in replaced.items():
            items[index] = item
        last.clear()
        last.update(replaced)
        return tuple(items)
