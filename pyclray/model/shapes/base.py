"""The shape interface: what every shape type provides (the types: pyclray/model/shapes/__init__.py).

A shape module owns everything about its shape, so that nothing outside pyclray/model/shapes/ asks which
type a shape is (pbrt-v4's Shape interface, Mitsuba's plugins). ``Shape``, the one base class of the
shape types, is three parts, each the contract of one side, each listing what a type must define there:

- the scene part (``SceneShape``, here): its scene-file keys and their validation, its material and
  label, its primitives and box, and how Mitsuba's XML files name it;
- the device part (``DevicePacking``, device.py): its structs, world entries, rebase, bounds and kernel
  files, what the engine packs;
- the reference part (``ReferenceShape``, reference.py): its float64 oracle, the error model's terms and
  its Mitsuba counterpart, what pyclray.reference asks.

What only meshes and their instances do (shared vertices and faces, cast's blocks, instancing, shading
normals of their own) is not here: a type opts into those capabilities (capabilities.py), and the
engine asks for them.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from ..errors import integer, no_unknown_keys, text
from ..lights import MATERIAL_KEYS, Material
from .device import DevicePacking
from .reference import ReferenceShape


@dataclass(frozen=True, kw_only=True)
class SceneShape:
    """The scene part of the shape interface: the contract a shape type implements for scene files,
    the Python API and the scene's checks.

    Every shape has a ``material`` (keyword only; its scene-file keys color, specular and shininess
    belong to every shape type and are read here, not by the shape's module) and a ``label``.

    A shape type is a frozen dataclass (its fields are its keys, checked in ``__post_init__``: a
    SceneError naming the key) and defines (``required_members``):

    - ``type``: its name in scene files;
    - ``keys``: the keys of its scene table besides type, name, label and the material's;
    - ``_from_table(table, name)`` (``(table, name, folder)`` where ``reads_files``): the shape of a
      scene table (or a tuple of shapes, where one table makes several: a mesh file's objects);
    - ``random(rng, shift)``: a random shape for the generic tests (tests/test_shapes.py);
    - ``lengths(eye)``: the sizes of what its kernel computes from each key in the camera's space
      (the range check).

    Optional, with defaults here: ``required`` (keys that must be given), ``reads_files`` (its table
    may name files), ``bounded`` (False: no finite bounds, outside the BVH; a bounded type defines
    the device part's ``bounds_of``), ``solid`` (has an inside), ``primitive_count`` (a batch's
    primitives), ``describe``, and for Mitsuba's XML files ``mitsuba_plugins`` with ``from_mitsuba``
    (required where it names plugins) and ``mitsuba_in_groups`` (what ``pyclray export`` writes as a
    shapegroup where shapes share their arrays).
    """

    required_members: ClassVar[tuple[str, ...]] = ("type", "keys", "_from_table", "random", "lengths")

    type: ClassVar[str]
    keys: ClassVar[tuple[str, ...]]
    required: ClassVar[tuple[str, ...]] = ()
    material: Material = field(default=Material(), compare=True)
    # an optional class label (an integer >= 0) beside the shape's id, for the `label` AOV: class
    # masks beside instance masks. Not animated (a class does not change between frames).
    label: int | None = field(default=None, metadata={"animatable": False})
    # False for shapes without finite bounds (the plane): visited by every ray, outside the BVH
    bounded: ClassVar[bool] = True
    # a solid has an inside: a ray starting there sees its far side (only t > 0 counts)
    solid: ClassVar[bool] = False

    # -- scene file ----------------------------------------------------------------------------
    # True for a type whose table may name files (read relative to the scene file's folder)
    reads_files: ClassVar[bool] = False

    @classmethod
    def from_table(cls, table: dict, index: int, folder=None):
        no_unknown_keys(table, ("type", "name", "label") + cls.keys + MATERIAL_KEYS, required=cls.required)
        name = text("name", table.get("name", f"{cls.type}{index}"))
        material = Material.from_table(table)
        label = check_label(table.get("label"))
        own = {k: v for k, v in table.items() if k not in MATERIAL_KEYS and k != "label"}
        shape = cls._from_table(own, name, folder) if cls.reads_files else cls._from_table(own, name)
        if isinstance(shape, tuple):  # a file's objects as shapes of their own (a mesh's split): each alike
            return tuple(cls._with_common(one, material, label) for one in shape)
        return cls._with_common(shape, material, label)

    @staticmethod
    def _with_common(shape, material, label):
        common = {k: v for k, v in (("material", material), ("label", label)) if v != getattr(shape, k)}
        return replace(shape, **common) if common else shape

    @classmethod
    def _from_table(cls, table: dict, name: str):
        raise NotImplementedError

    @classmethod
    def random(cls, rng, shift=0.0):
        """A random instance of about unit size near ``shift`` (numpy Generator ``rng``), for the
        generic property tests over the registry (tests/test_shapes.py)."""
        raise NotImplementedError

    def describe(self) -> str:
        return f"{self.type} '{self.name}'"

    # -- its primitives and their range --------------------------------------------------------
    def primitive_count(self) -> int:
        """How many entries of the packed arrays this shape is (a batch: one per primitive)."""
        return 1

    def lengths(self, eye) -> dict[str, float]:
        """Scene key -> the size of what the kernel computes from it in the camera's space (e.g. a
        centre's distance from the eye, a radius), which the kernel may square: the range check
        (scene.check_renderable) refuses a scene whose lengths exceed the precision's range."""
        raise NotImplementedError

    def box(self) -> np.ndarray:
        """(2, 3) [lo, hi]: the box holding the whole shape (every primitive of a batch), from the
        device part's bounds of its world entries."""
        bounds = self.world_bounds([self])
        return np.stack([bounds[:, 0].min(axis=0), bounds[:, 1].max(axis=0)])

    # -- its own pose (data sets: object poses, models, object coordinates) -----------------
    def object_pose(self) -> np.ndarray | None:
        """The 4x4 float64 affine matrix world_from_object of the shape's own pose (a mesh's file
        coordinates), or None for a type without one (the default)."""
        return None

    def object_poses(self) -> np.ndarray | None:
        """(P, 4, 4) world_from_object per primitive (a batch: each sphere its own), or (1, 4, 4) for
        one pose of every primitive; None where the type has no pose (object_pose)."""
        pose = self.object_pose()
        return None if pose is None else np.asarray(pose, np.float64)[None]

    def object_model(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(vertices (V, 3) float64, faces (F, 3) int64): the shape as triangles in its own space
        (object_pose), the model a data set's object poses refer to; None (the default) where the
        type has no triangle model."""
        return None

    # -- Mitsuba's XML files -------------------------------------------------------------------
    # the <shape type=...> plugins of Mitsuba's XML read as this type (pyclray.model.mitsuba_xml),
    # each by from_mitsuba; none for a type Mitsuba has no plugin for
    mitsuba_plugins: ClassVar[tuple[str, ...]] = ()
    # True where pyclray export writes the shapes that share this type's arrays as one <shapegroup>
    # and an <instance> each (a mesh); reading, a shapegroup may hold any shape
    mitsuba_in_groups: ClassVar[bool] = False

    @classmethod
    def from_mitsuba(cls, props, folder):
        """The shape of one of mitsuba_plugins: its properties taken from props (the plugin's
        pyclray.model.mitsuba_xml.properties.Properties; what it cannot map is props.element.error),
        the constructor with its arguments bound, called with the name and material by the reader.
        folder: the one a file named by the plugin is relative to."""
        raise NotImplementedError


@dataclass(frozen=True, kw_only=True)
class Shape(SceneShape, DevicePacking, ReferenceShape):
    """Base of the shape dataclasses: the scene, device and reference parts (see the module's
    docstring); a shape module subclasses it and implements each part's ``required_members``."""

    # engine/launch/programs.py reads these of every kind: the switches of the capabilities "indexed" and
    # "cast_blocks" and the "shared" arrays (capabilities.py), off here for the types without them.
    # The rest of the engine asks capabilities.capability().
    indexed: ClassVar[bool] = False
    cast_blocks: ClassVar[bool] = False
    shared: ClassVar[tuple] = ()


LABEL_MAX = 2**31 - 1  # labels are int32 in the label image


def check_label(value) -> int | None:
    """A shape's label: None (no label) or a whole number 0 <= label <= 2^31 - 1 (a SceneError at
    the key 'label' otherwise)."""
    return None if value is None else integer("label", value, minimum=0, maximum=LABEL_MAX)


def labels_of(shapes) -> np.ndarray:
    """(N,) int32: each shape's label, -1 for a shape without one."""
    return np.array([-1 if shape.label is None else shape.label for shape in shapes], np.int32).reshape(-1)


def space_columns(normal) -> np.ndarray:
    """(t1, t2, n): a right-handed orthonormal basis around the unit vector n, float64."""
    n = np.asarray(normal, np.float64)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(helper, n)
    t1 /= np.linalg.norm(t1)
    return np.stack([t1, np.cross(n, t1), n])


def object_matrix(columns, origin) -> np.ndarray:
    """The 4x4 world_from_object of a space whose axes (world vectors, one per row of ``columns``)
    start at ``origin``."""
    out = np.eye(4)
    out[:3, :3] = np.asarray(columns, np.float64).T
    out[:3, 3] = origin
    return out


def to_world(columns, origin) -> np.ndarray:
    """The 4x4 matrix with these three columns and this translation."""
    matrix = np.eye(4)
    for k, column in enumerate(columns):
        matrix[:3, k] = column
    matrix[:3, 3] = origin
    return matrix


def unit_rows(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def flag(key: str, value) -> bool:
    """A TOML boolean (true or false); 1, 0 and strings are not."""
    from ..errors import SceneError, _shown

    if not isinstance(value, bool):
        raise SceneError(f"expected true or false, got {_shown(value)}", key=key)
    return value


def distance(point, eye) -> float:
    """|point - eye| in float64, inf where it overflows (the range check refuses it)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return float(math.hypot(*np.subtract(point, eye)))
