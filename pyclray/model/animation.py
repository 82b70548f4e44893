"""Keyframed animation (scene-format.md, "Animation"): tracks per (target, key), the static scene
at a time t (``scene.at(t)``), the frames' times, and the check that every frame's scene is valid.

A target is one of the scene's named things: "camera", or the name of an element of any of the
scene's collections of named dataclasses (shapes today, lights when they exist). Nothing here
knows a shape type: a keyed value goes through the target's own dataclass
(``dataclasses.replace``), so it is validated exactly as a value written in the scene file is.
A key can be animated when it is a field of the target's dataclass holding a number or a vector;
type, name, fov_axis and caps (strings, booleans) cannot, nor a field whose metadata says
"animatable": False (a shape's label).
"""
from __future__ import annotations

import bisect
import dataclasses
import math
from dataclasses import dataclass, field
from numbers import Real

from .errors import SceneError, _shown, no_unknown_keys, number, text
from .frames import FrameShapes, derivation, derived, derived_from  # noqa: F401 (derivation, derived_from: used from here)

INTERPOLATIONS = ("linear", "step")
CAMERA = "camera"  # the camera's target name; the other targets are named by their "name" key
KEYS_TABLE = "[[animation.keys]]"
# Every frame's scene is checked at load: a million frames (11.5 hours at 24 fps) take minutes, so more
# is taken for a typo in duration or fps (docs/benchmarks.md, "Why the engine does what it does").
MAX_FRAMES = 1_000_000


def _value(key: str, value):
    """A keyed value as given: a float, or a tuple (of floats when all are numbers). Whether it
    fits the key is checked against the target (Animation.bind), after whether the key exists."""
    if isinstance(value, (list, tuple)):
        if all(isinstance(c, Real) and not isinstance(c, bool) for c in value):
            if not all(math.isfinite(c) for c in value):
                raise SceneError(f"expected finite numbers, got {_shown(value)}", key=key)
            return tuple(float(c) for c in value)
        return tuple(value)
    if isinstance(value, Real) and not isinstance(value, bool):
        return number(key, value)
    return value


def _kind(value) -> str:
    """"a number" or "N numbers": what a field holds, for matching keyed values against it."""
    if isinstance(value, Real) and not isinstance(value, bool):
        return "a number"
    if isinstance(value, tuple) and value and all(isinstance(c, Real) and not isinstance(c, bool) for c in value):
        return f"{len(value)} numbers"
    return ""  # not animatable: a string, a boolean, None, ...


@dataclass(frozen=True)
class Key:
    """One [[animation.keys]] entry: at ``time`` (seconds), ``target`` has these (key, value) pairs."""

    target: str
    time: float
    values: tuple[tuple[str, float | tuple[float, ...]], ...]

    @classmethod
    def from_table(cls, table) -> "Key":
        """From a [[animation.keys]] entry: target, time, and the keyed values, written beside them
        or in a sub-table ``values = {...}`` (the only way to key the camera's own ``target``)."""
        if isinstance(table, Key):
            return table
        if not isinstance(table, dict):
            raise SceneError(f"expected a table, got {type(table).__name__}")
        for required in ("target", "time"):
            if required not in table:
                raise SceneError("missing required key", key=required)
        target = text("target", table["target"])
        time = number("time", table["time"])
        if time < 0:
            raise SceneError(f"expected a time >= 0 (seconds), got {time!r}", key="time")
        values = {k: v for k, v in table.items() if k not in ("target", "time", "values")}
        nested = table.get("values", {})
        if not isinstance(nested, dict):
            raise SceneError(f"expected a table of keyed values such as {{ target = [x, y, z] }}, got {_shown(nested)}",
                             key="values")
        for k in nested:
            if k in values:
                raise SceneError("keyed twice in one entry (beside target and time, and in values)", key=k)
        values.update(nested)
        if not values:
            raise SceneError("expected at least one keyed value besides target and time (e.g. eye = [x, y, z])")
        return cls(target, time, tuple((k, _value(k, v)) for k, v in values.items()))


@dataclass(frozen=True)
class Track:
    """The keys of one (target, key) pair, by increasing time; ``entries``: their [[animation.keys]] indices."""

    target: str
    key: str
    times: tuple[float, ...]
    values: tuple
    entries: tuple[int, ...]

    def value_at(self, t: float, interpolation: str = "linear"):
        """The first key's value before the first time, the last key's after the last time, and in
        between the last key at or before t ("step") or the linear blend of the two around t."""
        i = bisect.bisect_right(self.times, t) - 1  # the last key at or before t
        if i < 0:
            return self.values[0]
        if i == len(self.times) - 1 or interpolation == "step":
            return self.values[i]
        t0, t1 = self.times[i], self.times[i + 1]
        s = (t - t0) / (t1 - t0)
        a, b = self.values[i], self.values[i + 1]
        # a + s (b - a): exactly a at t0 (each key's value is met exactly, the next at its own time
        # t1 as the start of the next span) and exactly a where a track holds a value constant
        if isinstance(a, tuple):
            return tuple(x + s * (y - x) for x, y in zip(a, b))
        return a + s * (b - a)


@dataclass(frozen=True)
class Animation:
    """fps and duration give frames k = 0 .. round(duration fps) - 1 at t = k / fps; keys: Key
    objects or tables as in scene files ({"target": "camera", "time": 0.0, "eye": [...]})."""

    fps: float
    duration: float
    keys: tuple[Key, ...] = ()
    interpolation: str = "linear"
    tracks: tuple[Track, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        try:
            object.__setattr__(self, "fps", number("fps", self.fps, positive=True))
            object.__setattr__(self, "duration", number("duration", self.duration, positive=True))
            if self.interpolation not in INTERPOLATIONS:
                raise SceneError(f"expected one of {', '.join(map(repr, INTERPOLATIONS))}, got {_shown(self.interpolation)}",
                                 key="interpolation")
            if not self.duration * self.fps < MAX_FRAMES + 0.5:  # also an overflow to inf
                raise SceneError(f"duration * fps = {self.duration * self.fps:g} frames, more than {MAX_FRAMES:,}",
                                 key="duration")
            if self.frame_count() < 1:
                raise SceneError(f"duration * fps = {self.duration * self.fps:g} rounds to no frame at all", key="duration")
        except SceneError as error:
            raise error.within(table="[animation]") from None
        if isinstance(self.keys, (str, bytes, dict)) or not hasattr(self.keys, "__iter__"):
            raise SceneError(f"expected an array of tables {KEYS_TABLE}", table="[animation]", key="keys")
        keys = []
        for index, entry in enumerate(self.keys):
            try:
                keys.append(Key.from_table(entry))
            except SceneError as error:
                raise error.within(table=f"{KEYS_TABLE} #{index}") from None
        object.__setattr__(self, "keys", tuple(keys))
        object.__setattr__(self, "tracks", self._tracks())

    def _tracks(self) -> tuple[Track, ...]:
        """Group the keys per (target, key), ordered by time; two keys at one time are an error."""
        grouped: dict[tuple[str, str], list] = {}
        for index, entry in enumerate(self.keys):
            for key, value in entry.values:
                grouped.setdefault((entry.target, key), []).append((entry.time, index, value))
        tracks = []
        for (target, key), items in grouped.items():
            items.sort(key=lambda item: item[0])
            for (t0, i0, _), (t1, i1, _) in zip(items, items[1:]):
                if t0 == t1:
                    raise SceneError(
                        f"target '{target}' has two keys at time {t1!r} (entries #{i0} and #{i1}): the times "
                        "of a track must be distinct", table=f"{KEYS_TABLE} #{i1}", key=key)
            tracks.append(Track(target, key, tuple(t for t, _, _ in items), tuple(v for _, _, v in items),
                                tuple(i for _, i, _ in items)))
        return tuple(tracks)

    @classmethod
    def from_table(cls, table) -> "Animation":
        """From the [animation] table of a scene file (with its keys array)."""
        if not isinstance(table, dict):
            raise SceneError(f"expected a table [animation], got {type(table).__name__}", key="animation")
        try:
            no_unknown_keys(table, ("fps", "duration", "interpolation", "keys"), required=("fps", "duration"))
        except SceneError as error:
            raise error.within(table="[animation]") from None
        keys = table.get("keys", [])
        if not isinstance(keys, list):
            raise SceneError(f"expected an array of tables {KEYS_TABLE}", table="[animation]", key="keys")
        return cls(table["fps"], table["duration"], tuple(keys), table.get("interpolation", "linear"))

    def frame_count(self) -> int:
        return round(self.duration * self.fps)

    def frame_time(self, k: int) -> float:
        return k / self.fps

    def frame_times(self) -> list[float]:
        return [self.frame_time(k) for k in range(self.frame_count())]

    # -- against a scene ------------------------------------------------------------------------
    def bind(self, scene) -> None:
        """Check the keys against the scene (known, unambiguous targets; animatable keys of the
        right kind) and that every frame's scene is valid; raise SceneError at the first problem."""
        places = _places(scene)
        for track in self.tracks:
            where = f"{KEYS_TABLE} #{track.entries[0]}"
            found = places.get(track.target, [])
            if not found:
                names = [name for name in places if name != CAMERA]
                raise SceneError(
                    f"unknown target {track.target!r} (expected \"camera\" or the name of one of the scene's "
                    f"named things: {', '.join(names) or 'none'})", table=where, key="target", file=scene.source)
            if len(found) > 1:
                raise SceneError(
                    f"target {track.target!r} is ambiguous: {' and '.join(_describe(scene, p) for p in found)} "
                    "share that name (the names of animated things must be unique)",
                    table=where, key="target", file=scene.source)
            thing = _get(scene, found[0])
            # a number or vector field; an optional one left out (None) takes the kind keyed first
            animatable = {f.name: _kind(getattr(thing, f.name)) if getattr(thing, f.name) is not None
                          else _kind(track.values[0]) or "a number or numbers" for f in dataclasses.fields(thing)
                          if f.metadata.get("animatable", True)}
            fixed = getattr(thing, "fixed_keys", ())  # e.g. the other kind of camera's keys
            animatable = {k: kind for k, kind in animatable.items() if kind and k not in fixed}
            if track.key not in animatable:
                raise SceneError(
                    f"cannot be animated: {_describe(scene, found[0])} has no number or vector key of that name "
                    f"(expected one of: {', '.join(animatable)})", table=where, key=track.key, file=scene.source)
            for value, entry in zip(track.values, track.entries):
                if _kind(value) != animatable[track.key]:
                    raise SceneError(
                        f"expected {animatable[track.key]}, as {_describe(scene, found[0])}'s {track.key} holds, "
                        f"got {_shown(list(value) if isinstance(value, tuple) else value)}",
                        table=f"{KEYS_TABLE} #{entry}", key=track.key, file=scene.source)
        for k, t in enumerate(self.frame_times()):
            scene_at(scene, t, frame=k)


def _places(scene) -> dict[str, list[tuple[str, int | None]]]:
    """Target name -> where things of that name sit: ("camera", None), or (collection field, index)
    for each named dataclass in any tuple field of the scene (shapes, lights, ...). Found once per
    scene and kept by it (Scene.animation_places: a frozen scene's places do not change): a frame of
    an animation of a million shapes must not walk them."""
    places = getattr(scene, "animation_places", None)
    return places if places is not None else _find_places(scene)


def _find_places(scene) -> dict[str, list[tuple[str, int | None]]]:
    places: dict[str, list] = {CAMERA: [(CAMERA, None)]}
    for f in dataclasses.fields(scene):
        items = getattr(scene, f.name)
        if f.name == "animation" or not isinstance(items, tuple):
            continue
        for index, item in enumerate(items):
            name = getattr(item, "name", None)
            if dataclasses.is_dataclass(item) and isinstance(name, str):
                places.setdefault(name, []).append((f.name, index))
    return places


def _get(scene, place):
    collection, index = place
    return getattr(scene, collection) if index is None else getattr(scene, collection)[index]


def _describe(scene, place) -> str:
    thing = _get(scene, place)
    if place[1] is None:
        return place[0]
    described = thing.describe() if hasattr(thing, "describe") else f"'{thing.name}'"
    return f"{described} ({place[0]} #{place[1]})"


def scene_at(scene, t: float, *, frame: int | None = None, lazy: bool = False):
    """The static scene at time t: every animated key takes its track's value at t; the result has
    no animation. Raises SceneError naming the target, the key and the time if that scene is invalid.
    lazy: its shapes a FrameShapes rather than a tuple when shapes are animated (render_animation's
    frames, which it renders and drops: O(K) work for K animated shapes)."""
    animation = scene.animation
    if animation is None:
        return scene
    t = float(t)
    if not math.isfinite(t):
        raise SceneError(f"expected a finite time, got {t!r}")
    when = f"at t = {t:g} s" + ("" if frame is None else f" (frame {frame})")
    places = _places(scene)
    changes: dict[tuple, dict] = {}
    targets: dict[tuple, str] = {}  # place -> its target's name, for messages
    for track in animation.tracks:
        place = places[track.target][0]
        changes.setdefault(place, {})[track.key] = track.value_at(t, animation.interpolation)
        targets[place] = track.target
    replaced: dict[str, object] = {}
    items: dict[str, dict] = {}  # per collection: index -> its new item
    for place, values in changes.items():
        collection, index = place
        try:
            if index is None:
                replaced[collection] = dataclasses.replace(getattr(scene, collection), **values)
            else:
                items.setdefault(collection, {})[index] = dataclasses.replace(getattr(scene, collection)[index], **values)
        except SceneError as error:
            raise _frame_error(scene, error, targets[place], values, when) from None
    for collection, mine in items.items():
        replaced[collection] = FrameShapes(scene.shapes, mine) if lazy and collection == "shapes" \
            else scene.frame_work.frame_tuple(getattr(scene, collection), collection, mine)
    if "shapes" in replaced:  # before the Scene checks it: only the changed shapes need a look
        derived(replaced["shapes"], scene.shapes, sorted(items["shapes"]))
    try:
        return dataclasses.replace(scene, animation=None, **replaced)
    except SceneError as error:  # a scene-wide check (e.g. the fov against the image size)
        raise _frame_error(scene, error, CAMERA if error.table == "[camera]" else "the scene", changes.get((CAMERA, None), {}), when) from None


def _frame_error(scene, error: SceneError, target: str, values: dict, when: str) -> SceneError:
    animated = ", ".join(values) or "nothing"
    return SceneError(f"{when}, with {animated} animated: {error.message}",
                      file=scene.source, table=f"{KEYS_TABLE} (target '{target}')", key=error.key)


def tracks_in(scene, collection: str) -> tuple:
    """((index in the collection, track), ...) for the animation's tracks whose target sits in the
    scene's ``collection`` ("shapes", "lidars", ...; "camera" for the camera, index None): what a
    scan asks to know which shapes move and how its sensor moves (engine/queries/scan.py)."""
    if scene.animation is None:
        return ()
    places = _places(scene)
    found = []
    for track in scene.animation.tracks:
        place = places[track.target][0]
        if place[0] == collection:
            found.append((place[1], track))
    return tuple(found)
