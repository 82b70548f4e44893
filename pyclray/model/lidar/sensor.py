"""A spinning LiDAR (scene-format.md, "LiDAR"): its beams (a preset's table or elevations given), its
columns (firings per revolution), its pose, its range limits and its sweep; the float64 directions
of its beams, which a scan casts (pyclray.scan, engine/queries/scan.py).

Conventions (docs/lidar.md):
- the sensor's frame is ROS's (REP 103): x forward, y left, z up; ``pose`` is sensor-to-world;
- a beam of elevation e (degrees, up positive) in column c has the unit direction
  (cos e cos a, cos e sin a, sin e), a = 180 - 360 c / columns degrees the column's azimuth (from +x
  toward +y): column 0 looks straight back (-x), and the columns turn clockwise seen from above
  (as Velodyne and Ouster sensors spin), so that column columns / 4 looks left (+y), columns / 2
  straight ahead (+x) and 3 columns / 4 right (-y): a range image is not mirrored, and its seam (the
  revolution's start and end) is behind the sensor, as KITTI's scans;
- row r of a range image is beam r: a preset's beams from the highest down (its ``lasers`` keep the
  maker's laser number of each row), ``elevations`` given in their own order;
- with ``sweep`` (in an animated scene) column c fires at t + step(c) / (steps rate), step(c) =
  floor(c steps / columns): one revolution takes 1 / rate seconds (``rate`` in Hz, default 10), cut
  into ``steps`` equal slices (default: one per column, each column at its own time).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from numbers import Real

import numpy as np

from ..errors import SceneError, _shown, integer, no_unknown_keys, number, text, vector3
from ..shapes.rotations import axis_angle, rotation
from .presets import PRESETS

KEYS = ("name", "preset", "elevations", "columns", "pose", "position", "axis", "angle", "range", "sweep", "rate",
        "frequency", "steps")
DEFAULT_RATE = 10.0  # Hz: revolutions per second (the presets' sensors' default)
MAX_BEAMS = 1024
MAX_COLUMNS = 1 << 20
# beams x columns at most: a scan holds a float64 direction and a position per beam (48 bytes), 1.6 GB here
MAX_BEAMS_X_COLUMNS = 1 << 25
# a pose's rotation must be orthonormal (det +1) within this, as a camera's (cameras/perspective.py)
RIGID_TOLERANCE = 1e-6

_FIXED = {"animatable": False}


def rotated(rotations: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(beams, n, 3): each column's directions (beams, n, 3) turned by its rotation (n or 1, 3, 3),
    R d, in float64 with the same three products and two sums in the same order whatever the batch
    (so that a column's rays are the same bits in a sweep's run and in a static scan)."""
    R = rotations[None]
    d = directions[..., None, :]
    return (R[..., 0] * d[..., 0] + R[..., 1] * d[..., 1]) + R[..., 2] * d[..., 2]


def placed(position, axis, angle, fixed_rotation=None) -> np.ndarray:
    """The 4x4 float64 sensor-to-world pose of a sensor placed by position, axis and angle (its
    rotation, where given, instead of axis and angle's)."""
    m = np.eye(4)
    m[:3, :3] = rotation(axis, angle) if fixed_rotation is None else fixed_rotation
    if position is not None:
        m[:3, 3] = position
    return m


def _pose_matrix(value) -> tuple:
    """A rigid 4x4 sensor-to-world matrix, as nested tuples of floats."""
    try:
        m = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"expected a 4x4 sensor-to-world matrix of numbers, got {_shown(value)}", key="pose") from None
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise SceneError(f"expected a 4x4 sensor-to-world matrix of finite numbers, got {_shown(value)}", key="pose")
    if not np.array_equal(m[3], [0, 0, 0, 1]):
        raise SceneError(f"expected the last row 0 0 0 1, got {m[3].tolist()}", key="pose")
    R = m[:3, :3]
    deviation = float(np.abs(R.T @ R - np.eye(3)).max())
    if not (deviation <= RIGID_TOLERANCE and np.linalg.det(R) > 0):
        raise SceneError(f"expected a rigid pose: its rotation orthonormal within {RIGID_TOLERANCE:g} with det +1 "
                         f"(no scale, shear or mirror), got R^T R - I up to {deviation:.3g}, det {np.linalg.det(R):.3g}",
                         key="pose")
    return tuple(tuple(float(x) for x in row) for row in m)


def _elevations(value) -> tuple[float, ...]:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) == 0:
        raise SceneError(f"expected a non-empty list of beam elevations (degrees), got {_shown(value)}", key="elevations")
    if len(value) > MAX_BEAMS:
        raise SceneError(f"expected at most {MAX_BEAMS} beams, got {len(value)}", key="elevations")
    out = []
    for index, angle in enumerate(value):
        if isinstance(angle, bool) or not isinstance(angle, Real) or not math.isfinite(float(angle)):
            raise SceneError(f"beam {index}: expected a finite number of degrees, got {_shown(angle)}", key="elevations")
        if not -90.0 < float(angle) < 90.0:
            raise SceneError(f"beam {index}: expected an elevation between -90 and 90 degrees (exclusive), got "
                             f"{float(angle)!r}", key="elevations")
        out.append(float(angle))
    return tuple(out)


def _range(value) -> tuple[float, float]:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise SceneError(f"expected [min, max] (scene units), got {_shown(value)}", key="range")
    low, high = value
    for bound in (low, high):
        if isinstance(bound, bool) or not isinstance(bound, Real) or math.isnan(float(bound)):
            raise SceneError(f"expected [min, max] numbers, got {_shown(value)}", key="range")
    low, high = float(low), float(high)
    if not (0.0 <= low < high) or math.isinf(low):
        raise SceneError(f"expected 0 <= min < max (max may be inf), got [{low!r}, {high!r}]", key="range")
    return low, high


@dataclass(frozen=True)
class Lidar:
    """A spinning LiDAR: ``Lidar(preset="VLP-16")`` or ``Lidar(elevations=[...], columns=1800)``, placed by
    ``pose`` (4x4 sensor-to-world, rigid) or by ``position`` with an optional rotation ``axis`` and
    ``angle`` (degrees, right-handed; the keys an animation may move), never both; a preset's ``elevations`` and ``columns``
    are its table's (from the top beam down) and its default; ``range`` = (min, max): returns nearer
    than min or farther than max are misses; ``sweep``: in an animated scene each column fires at its
    own time across the revolution (``rate`` revolutions per second, ``steps`` time slices per
    revolution). The module's docstring states the axes and the azimuth convention."""

    preset: str | None = field(default=None, metadata=_FIXED)
    elevations: tuple | None = field(default=None, metadata=_FIXED)
    columns: int | None = field(default=None, metadata=_FIXED)
    pose: tuple | None = field(default=None, metadata=_FIXED)
    range: tuple = field(default=(0.0, math.inf), metadata=_FIXED)
    name: str | None = field(default=None, metadata=_FIXED)
    position: tuple | None = None
    axis: tuple | None = None
    angle: float = 0.0
    sweep: bool = field(default=False, metadata=_FIXED)
    rate: float = field(default=DEFAULT_RATE, metadata=_FIXED)
    steps: int | None = field(default=None, metadata=_FIXED)
    frequency: float | None = field(default=None, metadata=_FIXED)  # another name of rate (Hz): given, it is the rate

    def __post_init__(self):
        put = lambda key, value: object.__setattr__(self, key, value)  # noqa: E731 (a frozen dataclass)
        preset = None
        if self.preset is not None:
            name = text("preset", self.preset)
            if name not in PRESETS:
                raise SceneError(f"unknown preset {name!r} (expected one of: {', '.join(PRESETS)})", key="preset")
            preset = PRESETS[name]
        if self.elevations is not None:
            put("elevations", _elevations(self.elevations))
        if preset is None and self.elevations is None:
            raise SceneError(f"expected a preset ({', '.join(PRESETS)}) or elevations (degrees, one per beam)",
                             key="preset")
        if preset is not None:
            # a preset's beams from the top down, and the maker's laser number of each row
            order = sorted(range(len(preset.elevations)), key=lambda k: (-preset.elevations[k], k))
            table = tuple(preset.elevations[k] for k in order)
            # (given beside the preset, its own table in that order is no conflict: dataclasses.replace passes both)
            if self.elevations is not None and self.elevations != table:
                raise SceneError("expected a preset or elevations, not both", key="elevations")
            put("elevations", table)
        else:
            order = list(range(len(self.elevations)))
        if self.columns is None:
            if preset is None:
                raise SceneError("expected the number of columns (firings per revolution) beside elevations",
                                 key="columns")
            put("columns", preset.columns)
        if isinstance(self.columns, np.integer):  # (a numpy whole number, as from an array)
            put("columns", int(self.columns))
        put("columns", integer("columns", self.columns, minimum=1, maximum=MAX_COLUMNS))
        if len(self.elevations) * self.columns > MAX_BEAMS_X_COLUMNS:
            raise SceneError(f"{len(self.elevations)} beams x {self.columns} columns is more than {MAX_BEAMS_X_COLUMNS:,} "
                             "rays per scan", key="columns")
        if self.pose is not None and (self.position is not None or self.axis is not None or self.angle != 0):
            key = "position" if self.position is not None else ("axis" if self.axis is not None else "angle")
            raise SceneError("expected a pose, or a position with an optional axis and angle, not both", key=key)
        if self.pose is not None:
            put("pose", _pose_matrix(self.pose))
        if self.position is not None:
            put("position", vector3("position", self.position))
        axis, angle = axis_angle(self.axis, self.angle)
        put("axis", axis)
        put("angle", angle)
        put("range", _range(self.range))
        if self.name is not None:
            text("name", self.name)
        if not isinstance(self.sweep, bool):
            raise SceneError(f"expected true or false, got {_shown(self.sweep)}", key="sweep")
        put("rate", number("rate", self.rate, positive=True))
        if self.frequency is not None:
            frequency = number("frequency", self.frequency, positive=True)
            if self.rate not in (DEFAULT_RATE, frequency):
                raise SceneError(f"expected rate or frequency (the same: revolutions per second), not both, got "
                                 f"rate {self.rate!r} and frequency {frequency!r}", key="frequency")
            put("rate", frequency)
            put("frequency", frequency)
        if self.steps is not None:
            if isinstance(self.steps, np.integer):
                put("steps", int(self.steps))
            put("steps", integer("steps", self.steps, minimum=1, maximum=self.columns))
        # the beams in range-image order and the maker's laser numbers, as arrays
        elevations = np.array(self.elevations, np.float64)
        elevations.setflags(write=False)
        lasers = np.array(order, np.int32)
        lasers.setflags(write=False)
        put("_beams", (elevations, lasers))

    @classmethod
    def from_table(cls, table: dict, default_name: str | None = None) -> "Lidar":
        """The sensor of a [lidar] or [[lidars]] table; a SceneError naming the key."""
        if not isinstance(table, dict):
            raise SceneError(f"expected a table, got {type(table).__name__}")
        no_unknown_keys(table, KEYS)
        values = dict(table)
        values.setdefault("name", default_name)
        return cls(**values)

    # -- its beams ---------------------------------------------------------------------------------
    @property
    def beams(self) -> int:
        return len(self._beams[0])

    @property
    def elevation_angles(self) -> np.ndarray:
        """(beams,) float64 degrees: row r's elevation (up positive)."""
        return self._beams[0]

    @property
    def lasers(self) -> np.ndarray:
        """(beams,) int32: the maker's laser number of each row (a preset's table's index); for given
        elevations, their index."""
        return self._beams[1]

    @property
    def azimuth_angles(self) -> np.ndarray:
        """(columns,) float64 degrees: column c's azimuth from +x toward +y, 180 - 360 c / columns."""
        return 180.0 - 360.0 * np.arange(self.columns, dtype=np.float64) / self.columns

    def directions(self) -> np.ndarray:
        """(beams, columns, 3) float64 unit directions of the beams in the sensor's frame (x forward,
        y left, z up): (cos e cos a, cos e sin a, sin e). Read-only, made once per sensor."""
        made = self.__dict__.get("_directions")
        if made is None:
            e = np.radians(self.elevation_angles)[:, None]
            a = np.radians(self.azimuth_angles)[None, :]
            made = np.stack(np.broadcast_arrays(np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)), axis=-1)
            made.setflags(write=False)
            object.__setattr__(self, "_directions", made)
        return made

    # -- where it is ---------------------------------------------------------------------------------
    @property
    def world_from_sensor(self) -> np.ndarray:
        """The 4x4 float64 sensor-to-world pose: ``pose``, or from position, axis and angle."""
        if self.pose is not None:
            return np.array(self.pose, np.float64)
        return placed(self.position, self.axis, self.angle)

    def poses_at(self, tracks, times, interpolation: str = "linear") -> np.ndarray:
        """(len(times), 4, 4): the pose at each time of an animation whose tracks (of this sensor's
        position, axis and angle) move it; each exactly the world_from_sensor of the sensor at that
        time (the same function of the same values), without making a Lidar per time. An axis that
        passes through zero between two keys is a SceneError naming it and the time."""
        poses = np.empty((len(times), 4, 4))
        if not tracks:
            poses[:] = self.world_from_sensor
            return poses
        keys = {track.key for track in tracks}
        fixed_rotation = None if keys & {"axis", "angle"} else rotation(self.axis, self.angle)
        for k, when in enumerate(times):
            values = {"position": self.position, "axis": self.axis, "angle": self.angle}
            values.update((track.key, track.value_at(float(when), interpolation)) for track in tracks)
            if fixed_rotation is None and values["axis"] is not None and not any(values["axis"]):
                raise SceneError(f"at t = {float(when):g} s the animated axis is [0, 0, 0]: expected a non-zero "
                                 "rotation axis", key="axis")
            poses[k] = placed(values["position"], values["axis"], values["angle"], fixed_rotation)
        return poses

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """(origin (3,), directions (beams, columns, 3)): the beams in the world, float64 (the
        rotation applied to each unit direction in float64, rotated(); the kernel normalizes them
        again): the rays a scan casts."""
        pose = self.world_from_sensor
        return pose[:3, 3].copy(), rotated(pose[None, :3, :3], self.directions())

    # -- when each column fires ----------------------------------------------------------------------
    @property
    def step_count(self) -> int:
        """The revolution's time slices: ``steps``, or one per column."""
        return self.columns if self.steps is None else self.steps

    def column_steps(self) -> np.ndarray:
        """(columns,) int64: the time slice each column fires in, floor(c steps / columns)."""
        return np.arange(self.columns, dtype=np.int64) * self.step_count // self.columns

    def step_times(self, t: float) -> np.ndarray:
        """(steps,) float64: the start of each time slice of a revolution starting at t (seconds)."""
        return t + np.arange(self.step_count, dtype=np.float64) / (self.step_count * self.rate)

    def describe(self) -> str:
        what = self.preset if self.preset is not None else f"{self.beams} beams"
        return f"lidar '{self.name}' ({what}, {self.columns} columns)" if self.name else f"lidar ({what})"
