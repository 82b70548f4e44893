"""The infinite plane: the points p with normal . p + offset = 0."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SceneError, norm3, number, vector3
from ..exact import dot2
from ..layout import Struct
from .base import Shape


@dataclass(frozen=True)
class Plane(Shape):
    normal: tuple[float, float, float]
    offset: float = 0.0
    name: str = "plane"

    type = "plane"
    c_type = "Plane"
    keys = ("normal", "offset", "point")
    required = ("normal",)
    struct = Struct(
        "Plane",
        (
            ("normal", "real4"),  # unit normal in the frame; w: signed distance of the frame origin
            ("world_normal", "real4"),  # unit normal in world space (the normal image's value)
            ("id", "int"),
        ),
        "Plane n.p + h = 0: normal.xyz = n in the frame, normal.w = h at the frame's origin.",
    )

    def __post_init__(self):
        normal = vector3("normal", self.normal)
        if norm3(normal) == 0:
            raise SceneError("expected a non-zero normal vector, got [0, 0, 0]", key="normal")
        object.__setattr__(self, "normal", normal)
        object.__setattr__(self, "offset", number("offset", self.offset))

    @classmethod
    def through(cls, point, normal, name: str = "plane") -> "Plane":
        """The plane with this normal through this point."""
        normal = vector3("normal", normal)
        point = vector3("point", point)
        return cls(normal, -float(dot2(np.array(normal), np.array(point))), name)

    @classmethod
    def _from_table(cls, table, name):
        if ("offset" in table) == ("point" in table):
            raise SceneError(
                "expected exactly one of 'offset' or 'point', got "
                + ("both" if "offset" in table else "neither"),
                key="offset",
            )
        if "point" in table:
            return cls.through(table["point"], table["normal"], name)
        return cls(table["normal"], table["offset"], name)

    def unit(self) -> tuple[np.ndarray, float]:
        """(n, h): unit normal and offset scaled together, in float64."""
        length = norm3(self.normal)
        return np.array(self.normal) / length, self.offset / length

    def lengths(self, eye) -> dict[str, float]:
        n, h = self.unit()
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is an inf, which the range check refuses
            return {"offset": abs(float(np.dot(n, eye) + h))}  # the eye's distance to the plane

    @classmethod
    def _pack(cls, out, planes, origin, rotation):
        n = np.array([p.unit()[0] for p in planes])
        h = np.array([p.unit()[1] for p in planes])
        # signed distance of the frame origin: n . origin + h, compensated (a far origin cancels)
        n_h = np.concatenate([n, h[:, None]], axis=1)
        origin_1 = np.broadcast_to(np.append(origin, 1.0), n_h.shape)
        out["normal"][:, :3] = n @ rotation.T
        out["normal"][:, 3] = dot2(n_h, origin_1)
        out["world_normal"][:, :3] = n

    # -- float64 oracle ----------------------------------------------------------------------
    def oracle_distance(self, origins, directions):
        """Distance t > 0 along unit directions to the plane, inf where there is none."""
        n, h = self.unit()
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -(origins @ n + h) / (directions @ n)
        return np.where(t > 0, t, np.inf)

    def oracle_normal(self, points):
        n, _ = self.unit()
        return np.broadcast_to(n, points.shape)
