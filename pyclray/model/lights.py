"""Lights, materials and the [shading] table of a scene (scene-format.md, "Shading").

A scene's ``[[lights]]`` are point lights (intensity / distance^2) and directional lights (an
irradiance); a scene without lights has one headlight, a directional light of irradiance 1 travelling
along the camera's view direction. Every shape carries a Material (``color``, ``specular``,
``shininess``: the keys any shape table may add). ``[shading]`` holds the ambient term, the colour of a
miss, and whether shadows are cast.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real

import numpy as np

from .errors import SceneError, _shown, no_unknown_keys, norm3, number, text, typed_table, vector3
from .layout import Struct

MATERIAL_KEYS = ("color", "specular", "shininess")
DEFAULT_COLOR = (0.8, 0.8, 0.8)


def rgb(key: str, value, *, unit: bool = False, one_number: bool = True) -> tuple[float, float, float]:
    """An RGB triple: three numbers (or one, for all three where allowed), each >= 0, and each in
    [0, 1] with unit=True."""
    if one_number and isinstance(value, Real) and not isinstance(value, bool):
        value = (value, value, value)
    try:
        triple = vector3(key, value)
    except SceneError:
        expected = "3 numbers [r, g, b]" + (" or one number" if one_number else "")
        raise SceneError(f"expected {expected}, got {_shown(value)}", key=key) from None
    low, high = (0.0, 1.0) if unit else (0.0, math.inf)
    if not all(low <= c <= high for c in triple):
        bounds = "each in [0, 1]" if unit else "each >= 0"
        raise SceneError(f"expected an RGB colour {bounds}, got {list(triple)}", key=key)
    return triple


def flag(key: str, value) -> bool:
    if not isinstance(value, bool):
        raise SceneError(f"expected true or false, got {_shown(value)}", key=key)
    return value


@dataclass(frozen=True)
class Material:
    """The surface of a shape: albedo ``color`` (each in [0, 1]), Blinn-Phong ``specular`` weight in
    [0, 1] and exponent ``shininess`` > 0."""

    color: tuple[float, float, float] = DEFAULT_COLOR
    specular: float = 0.0
    shininess: float = 32.0

    def __post_init__(self):
        object.__setattr__(self, "color", rgb("color", self.color, unit=True, one_number=False))
        specular = number("specular", self.specular)
        if not 0 <= specular <= 1:
            raise SceneError(f"expected a number in [0, 1], got {specular!r}", key="specular")
        object.__setattr__(self, "specular", specular)
        object.__setattr__(self, "shininess", number("shininess", self.shininess, positive=True))

    @classmethod
    def from_table(cls, table: dict) -> "Material":
        """The material keys of a shape's table (the others are the shape's)."""
        return cls(**{key: table[key] for key in MATERIAL_KEYS if key in table})


@dataclass(frozen=True)
class PointLight:
    """Light from a point: intensity (RGB, >= 0) / distance^2."""

    position: tuple[float, float, float]
    intensity: tuple[float, float, float] = (1.0, 1.0, 1.0)
    name: str = "light"

    type = "point"
    keys = ("position", "intensity")

    def __post_init__(self):
        object.__setattr__(self, "position", vector3("position", self.position))
        object.__setattr__(self, "intensity", rgb("intensity", self.intensity))

    @classmethod
    def _from_table(cls, table, name):
        no_unknown_keys(table, ("type", "name") + cls.keys, required=("position", "intensity"))
        return cls(table["position"], table["intensity"], name)


@dataclass(frozen=True)
class DirectionalLight:
    """Light from infinitely far away, travelling along ``direction``, of irradiance (RGB, >= 0)."""

    direction: tuple[float, float, float]
    irradiance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    name: str = "light"

    type = "directional"
    keys = ("direction", "irradiance")

    def __post_init__(self):
        direction = vector3("direction", self.direction)
        if norm3(direction) == 0:
            raise SceneError("expected a non-zero direction, got [0, 0, 0]", key="direction")
        object.__setattr__(self, "direction", direction)
        object.__setattr__(self, "irradiance", rgb("irradiance", self.irradiance))

    @classmethod
    def _from_table(cls, table, name):
        no_unknown_keys(table, ("type", "name") + cls.keys, required=("direction", "irradiance"))
        return cls(table["direction"], table["irradiance"], name)

    def toward_light(self) -> np.ndarray:
        """The unit direction from a surface toward the light, float64."""
        d = np.array(self.direction)
        return -d / np.linalg.norm(d / np.abs(d).max()) / np.abs(d).max()


LIGHT_TYPES = {cls.type: cls for cls in (PointLight, DirectionalLight)}


@dataclass(frozen=True)
class Shading:
    """The [shading] table: ambient (RGB >= 0), background (the colour of a miss), shadows."""

    ambient: tuple[float, float, float] = (0.0, 0.0, 0.0)
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    shadows: bool = True

    def __post_init__(self):
        object.__setattr__(self, "ambient", rgb("ambient", self.ambient))
        object.__setattr__(self, "background", rgb("background", self.background, one_number=False))
        object.__setattr__(self, "shadows", flag("shadows", self.shadows))

    @classmethod
    def from_table(cls, table: dict) -> "Shading":
        no_unknown_keys(table, ("ambient", "background", "shadows"))
        return cls(**table)


def lights_from_list(entries, source=None) -> tuple:
    """The [[lights]] of a scene file, in order; names default to light<index> and must be unique."""
    if not isinstance(entries, list):
        raise SceneError("expected an array of tables [[lights]]", key="lights", file=source)
    lights, seen = [], {}
    for index, entry in enumerate(entries):
        where = f"[[lights]] #{index}"
        try:
            kind = typed_table(entry, LIGHT_TYPES, "light")
            where = f"[[lights]] #{index} ({kind})"
            name = text("name", entry.get("name", f"light{index}"))
            if name in seen:
                raise SceneError(f"the name {name!r} is already used by [[lights]] #{seen[name]}", key="name")
            seen[name] = index
            lights.append(LIGHT_TYPES[kind]._from_table(entry, name))
        except SceneError as error:
            raise error.within(file=source, table=where) from None
    return tuple(lights)


def check_lights(lights, source=None) -> tuple:
    """Lights given to Scene directly: each a PointLight or DirectionalLight, names unique."""
    lights = tuple(lights)
    seen = {}
    for index, light in enumerate(lights):
        if not isinstance(light, (PointLight, DirectionalLight)):
            raise SceneError(
                f"expected a light ({', '.join(LIGHT_TYPES)}), got {type(light).__name__}",
                table=f"[[lights]] #{index}", file=source,
            )
        if light.name in seen:
            raise SceneError(
                f"the name {light.name!r} is already used by [[lights]] #{seen[light.name]}",
                table=f"[[lights]] #{index} ({light.type})", key="name", file=source,
            )
        seen[light.name] = index
    return lights


def headlight(camera) -> DirectionalLight:
    """The light of a scene without [[lights]]: irradiance 1 along the camera's view direction."""
    return DirectionalLight(tuple(camera.basis()[2]), (1.0, 1.0, 1.0), "headlight")


def effective_lights(scene) -> tuple:
    """The lights that shade the scene: its [[lights]], or the headlight."""
    return scene.lights if scene.lights else (headlight(scene.camera),)


# -- what the kernels read of them (kernels/shading.h; packed by pyclray.engine.scene.lighting) --
# Per shape id: its material.
MATERIAL = Struct(
    "Material",
    (
        ("color", "real4"),  # albedo rgb; w: specular
        ("shininess", "real"),
    ),
    "A shape's material by id: color.xyz albedo, color.w specular, shininess.",
)
# Per light: a point light's position in the frame (w = 1) or a directional light's unit direction
# toward the light in the frame (w = 0), and its intensity or irradiance.
LIGHT = Struct(
    "Light",
    (
        ("position", "real4"),  # point: xyz in the frame, w = 1; directional: toward the light, w = 0
        ("power", "real4"),  # rgb intensity (point) or irradiance (directional)
    ),
    "A light in the camera's frame: position.w = 1 point (xyz its position), 0 directional (xyz toward it).",
)
STRUCTS = (MATERIAL, LIGHT)
