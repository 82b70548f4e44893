"""What every shape type provides (see pyclray/shapes/__init__.py)."""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from ..errors import no_unknown_keys, text
from ..layout import Struct, layout
from ..lighting import MATERIAL_KEYS, Material


@dataclass(frozen=True, kw_only=True)
class Shape:
    """Base of the shape dataclasses.

    Every shape has a ``material`` (keyword only; its scene-file keys color, specular and shininess
    belong to every shape type and are read here, not by the shape's module).

    Each subclass sets ``type`` (its name in scene files), ``c_type`` (its struct in OpenCL C; the
    kernel functions are ``<type>_hit`` and ``<type>_normal`` in ``kernels/<type>.cl``), ``struct``
    (its packed layout, declared once) and ``keys`` (the keys of its scene table besides type and
    name), and implements ``_from_table``, ``_pack`` and the float64 oracle.
    """

    type: ClassVar[str]
    c_type: ClassVar[str]
    struct: ClassVar[Struct]
    keys: ClassVar[tuple[str, ...]]
    required: ClassVar[tuple[str, ...]] = ()
    material: Material = field(default=Material(), compare=True)

    @classmethod
    def from_table(cls, table: dict, index: int):
        no_unknown_keys(table, ("type", "name") + cls.keys + MATERIAL_KEYS, required=cls.required)
        name = text("name", table.get("name", f"{cls.type}{index}"))
        material = Material.from_table(table)
        shape = cls._from_table({k: v for k, v in table.items() if k not in MATERIAL_KEYS}, name)
        return replace(shape, material=material) if material != Material() else shape

    @classmethod
    def pack(cls, shapes, ids, origin, rotation, precision: str) -> np.ndarray:
        """The packed array of these shapes in a frame: origin (world, float64) and rotation
        (rows: the frame's axes in world coordinates)."""
        out = np.zeros(len(shapes), dtype=layout(cls.struct, precision).dtype)
        out["id"] = ids
        if len(shapes):
            cls._pack(out, shapes, np.asarray(origin, np.float64), np.asarray(rotation, np.float64))
        return out

    def lengths(self, eye) -> dict[str, float]:
        """Scene key -> the size of what the kernel computes from it in the camera's frame (e.g. a
        centre's distance from the eye, a radius), which the kernel may square: the range check
        (scene.check_renderable) refuses a scene whose lengths exceed the precision's range."""
        return {}

    def describe(self) -> str:
        return f"{self.type} '{self.name}'"

