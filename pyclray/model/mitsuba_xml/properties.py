"""The properties of a Mitsuba plugin element: ``<float name=... value=...>`` and its kin, nested
plugins and ``<ref id=...>``, and ``<transform>`` with its operations, as Mitsuba 3's XML parser
reads them (src/core/xml.cpp): each operation of a transform is applied after those before it, so
it multiplies them from the left (``<translate/><rotate/>`` is R T).

A builder takes the properties it knows (``Properties.take``) and ends with ``finish``: a property
nobody took is an error naming its element and line (a typo is never ignored), except those a
plugin lists as render settings without meaning for pyclray (``ignore``).
"""
from __future__ import annotations

import math
import re

import numpy as np

from .tree import Element

VALUE_KINDS = ("float", "integer", "boolean", "string", "point", "vector", "rgb", "spectrum", "transform")
_SEPARATORS = re.compile(r"[\s,]+")


def numbers(element: Element, key: str, text: str) -> list[float]:
    """The numbers of an attribute written as "1, 2, 3" or "1 2 3" (finite)."""
    try:
        values = [float(part) for part in _SEPARATORS.split(text.strip()) if part]
    except ValueError:
        raise element.error(f"attribute {key!r}: expected numbers, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise element.error(f"attribute {key!r}: expected finite numbers, got {text!r}")
    return values


def triple(element: Element, *, default: float = 0.0, broadcast: bool = False) -> np.ndarray:
    """A 3-vector from ``value="x, y, z"`` or the attributes x, y, z (each defaulting to ``default``);
    broadcast: one number stands for all three (rgb, scale)."""
    if "value" in element.attrs:
        values = numbers(element, "value", element.attrs["value"])
        if broadcast and len(values) == 1:
            values = values * 3
        if len(values) != 3:
            raise element.error(f"attribute 'value': expected 3 numbers, got {element.attrs['value']!r}")
        return np.array(values)
    return np.array([numbers(element, k, element.attrs[k])[0] if k in element.attrs else default for k in "xyz"])


def scalar(element: Element, key: str = "value") -> float:
    values = numbers(element, key, element.attribute(key))
    if len(values) != 1:
        raise element.error(f"attribute {key!r}: expected one number, got {element.attrs[key]!r}")
    return values[0]


# -- transforms ----------------------------------------------------------------------------------
def rotation(axis, degrees: float) -> np.ndarray:
    """Mitsuba 3's Transform4f::rotate(axis, degrees) (drjit's rotate): cos I + sin [a]x + (1 - cos) a a^T
    with the axis a as given. A unit axis makes the right-handed rotation by ``degrees`` (Rodrigues);
    Mitsuba does not normalise another, and neither does pyclray: the result then also scales (and
    may shear) what it places, as Mitsuba renders it."""
    a = np.asarray(axis, np.float64)
    angle = math.radians(degrees)
    cross = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return math.cos(angle) * np.eye(3) + math.sin(angle) * cross + (1 - math.cos(angle)) * np.outer(a, a)


def coordinate_system(n) -> np.ndarray:
    """The first tangent of Mitsuba's coordinate_system(n) (Duff et al. 2017): the up vector a
    <lookat> without one gets."""
    x, y, z = n
    sign = math.copysign(1.0, z)
    a = -1.0 / (sign + z)
    b = x * y * a
    return np.array([1.0 + sign * x * x * a, sign * b, -sign * x])


def look_at(origin, target, up) -> np.ndarray:
    """Transform4f::look_at: columns left = normalize(up x dir), up' = dir x left, dir; origin."""
    direction = target - origin
    direction = direction / np.linalg.norm(direction)
    left = np.cross(up, direction)
    left = left / np.linalg.norm(left)
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = left, np.cross(direction, left), direction, origin
    return matrix


class Transform:
    """A to_world transform: its 4x4 float64 matrix, and the <lookat> arguments when it is exactly
    one lookat (a camera keeps them: the same rays as Mitsuba's own look_at)."""

    def __init__(self, matrix: np.ndarray, look_at_args=None):
        self.matrix = matrix
        self.look_at_args = look_at_args

    @classmethod
    def read(cls, element: Element) -> "Transform":
        matrix = np.eye(4)
        look_at_args = None
        for k, op in enumerate(element.children):
            step = np.eye(4)
            if op.tag == "translate":
                step[:3, 3] = triple(op)
            elif op.tag == "scale":
                step[:3, :3] = np.diag(triple(op, default=1.0, broadcast=True))
            elif op.tag == "rotate":
                axis = triple(op)
                if not np.any(axis):
                    raise op.error("expected a non-zero rotation axis (x, y, z or value)")
                step[:3, :3] = rotation(axis, scalar(op, "angle"))
            elif op.tag == "matrix":
                values = numbers(op, "value", op.attribute("value"))
                if len(values) == 9:
                    step[:3, :3] = np.reshape(values, (3, 3))
                elif len(values) == 16:
                    step = np.reshape(values, (4, 4))
                else:
                    raise op.error(f"attribute 'value': expected 16 (or 9) numbers, row by row, got {len(values)}")
            elif op.tag == "lookat":
                origin = np.array(numbers(op, "origin", op.attribute("origin")))
                target = np.array(numbers(op, "target", op.attribute("target")))
                if len(origin) != 3 or len(target) != 3:
                    raise op.error("attributes 'origin' and 'target': expected 3 numbers each")
                if np.array_equal(origin, target):
                    raise op.error("origin and target are the same point: no direction to look along")
                direction = (target - origin) / np.linalg.norm(target - origin)
                up = np.array(numbers(op, "up", op.attrs["up"])) if "up" in op.attrs else coordinate_system(direction)
                if len(up) != 3 or np.linalg.norm(np.cross(up, direction)) == 0:
                    raise op.error("attribute 'up': expected 3 numbers, not parallel to target - origin")
                step = look_at(origin, target, up)
                look_at_args = (origin, target, up) if len(element.children) == 1 else None
            else:
                raise op.error("unknown transform operation (expected translate, rotate, scale, matrix or lookat)")
            matrix = step @ matrix
        if not np.array_equal(matrix[3], [0, 0, 0, 1]) or not abs(np.linalg.det(matrix[:3, :3])) > 0:
            raise element.error("expected an invertible affine transform (last row 0 0 0 1)")
        return cls(matrix, look_at_args)

    def point(self, p) -> np.ndarray:
        return self.matrix[:3, :3] @ np.asarray(p, np.float64) + self.matrix[:3, 3]

    def columns(self) -> np.ndarray:
        """The images of the unit axes (the linear part's columns), rows of the result."""
        return self.matrix[:3, :3].T.copy()

    def flat_axes(self):
        """(centre, first axis, second axis, unit normal) of Mitsuba's unit shape in z = 0 under
        this transform. Its normal is the normal transform of +z, (M^-T) e_z, which is
        det(M) cross(M e_x, M e_y) / |...|: a mirroring transform turns it around."""
        columns = self.columns()
        normal = np.cross(columns[0], columns[1]) * math.copysign(1.0, np.linalg.det(self.matrix[:3, :3]))
        return self.point(np.zeros(3)), columns[0], columns[1], normal / np.linalg.norm(normal)

    def similarity(self, element: Element, what: str) -> float:
        """The scale of a transform that is a rotation (or mirror) times one uniform scale; any other
        (a non-uniform scale, a shear) is an error: ``what`` says why the shape needs it."""
        columns = self.columns()
        lengths = np.linalg.norm(columns, axis=1)
        gram = columns @ columns.T / np.outer(lengths, lengths)
        if np.abs(gram - np.eye(3)).max() > 1e-9 or lengths.max() - lengths.min() > 1e-9 * lengths.max():
            raise element.error(f"to_world: expected a rotation, translation and uniform scale ({what}); "
                                "a non-uniform scale or a shear has no pyclray counterpart")
        return float(lengths.mean())


IDENTITY = Transform(np.eye(4))


# -- the properties of one plugin ----------------------------------------------------------------
class Properties:
    """The named properties and the nested plugins (and <ref>s) of a plugin element."""

    def __init__(self, element: Element, ignore=(), outer: "Transform | None" = None):
        self.element = element
        self.outer = outer  # an instance's to_world, applied after the plugin's own (shapegroups)
        self.values: dict = {}
        self.plugins: list[Element] = []
        for child in element.children:
            if child.tag in VALUE_KINDS:
                name = child.attribute("name")
                if name in self.values:
                    raise child.error(f"property {name!r} is given twice")
                self.values[name] = child
            else:
                self.plugins.append(child)
        self.ignore = set(ignore)

    def take(self, name: str, kind: str, default=None, required: bool = False):
        """The value of property ``name`` of this kind (a float, an int, a bool, a str, a 3-vector,
        an RGB triple or a Transform), ``default`` if absent (an error if required)."""
        child = self.values.pop(name, None)
        if child is None:
            if required:
                raise self.element.error(f"missing property {name!r} (<{kind} name=\"{name}\" .../>)")
            return default
        if child.tag != kind and not (kind == "rgb" and child.tag in ("float", "spectrum")) and not (
                kind == "point" and child.tag == "vector") and not (kind == "vector" and child.tag == "point"):
            raise child.error(f"property {name!r}: expected <{kind}>, got <{child.tag}>")
        if kind == "transform":
            return Transform.read(child)
        if kind in ("point", "vector"):
            return triple(child)
        if kind == "rgb":
            return triple(child, broadcast=True) if child.tag != "float" else np.full(3, scalar(child))
        text = child.attribute("value")
        if kind == "float":
            return scalar(child)
        if kind == "integer":
            try:
                return int(text)
            except ValueError:
                raise child.error(f"attribute 'value': expected a whole number, got {text!r}") from None
        if kind == "boolean":
            if text.lower() not in ("true", "false"):
                raise child.error(f"attribute 'value': expected true or false, got {text!r}")
            return text.lower() == "true"
        return text

    def to_world(self) -> Transform:
        """The plugin's to_world transform, the identity if it has none (after it, an instance's)."""
        own = self.take("to_world", "transform", IDENTITY)
        return own if self.outer is None else Transform(self.outer.matrix @ own.matrix)

    def finish(self) -> None:
        """Every property taken or ignored; the nested plugins are the builder's (plugins.py)."""
        for name, child in self.values.items():
            if name not in self.ignore:
                raise child.error(f"unknown property {name!r} of {self.element.where()[self.element.where().index('<'):]} "
                                  "(pyclray reads the properties docs/mitsuba.md lists)")
