"""What every shape type provides (see pyclray/shapes/__init__.py)."""
from __future__ import annotations

from typing import ClassVar

import numpy as np

from ..errors import no_unknown_keys, text
from ..layout import Struct, layout


class Shape:
    """Base of the shape dataclasses.

    Each subclass sets ``type`` (its name in scene files), ``c_type`` (its struct in OpenCL C; the
    kernel functions are ``<type>_hit`` and ``<type>_normal`` in ``kernels/<type>.cl``), ``struct``
    (its packed layout, declared once), ``keys`` (the keys of its scene table besides type and
    name) and ``bounded`` (whether it has finite world bounds: such shapes go into the BVH, the
    others are tested by every ray), and implements ``_from_table``, ``_pack``, ``world_bounds``
    and the float64 oracle.

    ``_pack(out, shapes, origin, rotation)`` must accept ``origin`` of shape (3,) (one frame for
    every shape: render) or (N, 3) (one frame per shape, each at its own anchor: cast).
    """

    type: ClassVar[str]
    c_type: ClassVar[str]
    struct: ClassVar[Struct]
    keys: ClassVar[tuple[str, ...]]
    required: ClassVar[tuple[str, ...]] = ()
    bounded: ClassVar[bool] = True

    @classmethod
    def world_bounds(cls, shapes) -> np.ndarray:
        """(N, 2, 3) float64: [lo, hi] world-space corners of a box holding each shape (infinite
        for an unbounded shape)."""
        raise NotImplementedError

    @classmethod
    def from_table(cls, table: dict, index: int):
        no_unknown_keys(table, ("type", "name") + cls.keys, required=cls.required)
        name = text("name", table.get("name", f"{cls.type}{index}"))
        return cls._from_table(table, name)

    @classmethod
    def pack(cls, shapes, ids, origin, rotation, precision: str) -> np.ndarray:
        """The packed array of these shapes in a frame: origin (world, float64) and rotation
        (rows: the frame's axes in world coordinates)."""
        out = np.zeros(len(shapes), dtype=layout(cls.struct, precision).dtype)
        out["id"] = ids
        if len(shapes):
            cls._pack(out, shapes, np.asarray(origin, np.float64), np.asarray(rotation, np.float64))
        return out

    def describe(self) -> str:
        return f"{self.type} '{self.name}'"

