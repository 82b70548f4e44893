"""The Mitsuba plugins pyclray reads, one builder each, found by (element, plugin type) in PLUGINS.

A builder takes the element and the scene being read (``Reading``) and adds what it makes to it.
A plugin of Mitsuba's that pyclray has no counterpart for is not in the table: reading one is an
error naming the element and its line.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..camera import Camera, Image
from ..errors import SceneError
from ..lights import DirectionalLight, Material, PointLight
from ..shapes import REGISTRY
from .properties import IDENTITY, Properties
from .tree import Element

MITSUBA_DIFFUSE = (0.5, 0.5, 0.5)  # the reflectance of a shape without a bsdf (Mitsuba's default diffuse)
FILM_SIZE = (768, 576)  # Mitsuba's hdrfilm default
# render settings that change nothing pyclray renders (sampling, filtering, pixel formats, clipping)
SENSOR_SETTINGS = ("near_clip", "far_clip", "focus_distance", "shutter_open", "shutter_close", "srf")
FILM_SETTINGS = ("pixel_format", "component_format", "banner", "sample_border", "compensate", "rfilter")


@dataclass
class Reading:
    """What a scene file has given so far (folder: the file's, which a mesh's filename is relative to)."""

    folder: Path | None = None
    camera: Camera | None = None
    image: Image | None = None
    shapes: list = field(default_factory=list)
    lights: list = field(default_factory=list)
    bsdfs: dict = field(default_factory=dict)  # id -> Material
    groups: dict = field(default_factory=dict)  # shapegroup id -> its <shape> elements
    outer: object = None  # inside an instance: its to_world (a Transform), applied after a shape's own


def checked(element: Element, make, *args, **kwargs):
    """make(*args, **kwargs), its SceneError (a pyclray key's check) named by the element."""
    try:
        return make(*args, **kwargs)
    except SceneError as error:
        raise element.error(f"{error.message}" + (f" (pyclray's key {error.key!r})" if error.key else "")) from None


def name_of(element: Element, reading: Reading, kind: str) -> str:
    """The element's id (the name pyclray gives it), or Mitsuba's type and its index."""
    index = len(reading.shapes) if kind == "shape" else len(reading.lights)
    return element.attrs.get("id", f"{element.attrs.get('type', kind)}{index}" if kind == "shape" else f"light{index}")


# -- materials -------------------------------------------------------------------------------------
def diffuse(element: Element, reading: Reading) -> Material:
    props = Properties(element)
    color = props.take("reflectance", "rgb", MITSUBA_DIFFUSE)
    props.finish()
    only_plugins(element, props, ())
    return checked(element, Material, tuple(color))


def twosided(element: Element, reading: Reading) -> Material:
    """pyclray shades the side the viewer sees: a two-sided BSDF is its one nested BSDF."""
    props = Properties(element)
    props.finish()
    inner = [child for child in props.plugins if child.tag in ("bsdf", "ref")]
    only_plugins(element, props, ("bsdf", "ref"))
    if len(inner) != 1:
        raise element.error(f"expected one nested <bsdf> (or <ref>), got {len(inner)}")
    return material(inner[0], reading)


BSDFS = {"diffuse": diffuse, "twosided": twosided}


def material(element: Element, reading: Reading) -> Material:
    """The Material of a <bsdf> or a <ref id=...> to one."""
    if element.tag == "ref":
        found = reading.bsdfs.get(element.attribute("id"))
        if found is None:
            raise element.error(f"no <bsdf id=\"{element.attrs['id']}\"> before this reference")
        return found
    return BSDFS[plugin_type(element, BSDFS)](element, reading)


def plugin_type(element: Element, table) -> str:
    kind = element.attribute("type")
    if kind not in table:
        raise element.error(f"unknown {element.tag} plugin {kind!r}: pyclray reads {', '.join(sorted(table))} "
                            "(docs/mitsuba.md)")
    return kind


def only_plugins(element: Element, props: Properties, allowed) -> None:
    for child in props.plugins:
        if child.tag not in allowed:
            raise child.error(f"not read inside <{element.tag}>: pyclray reads "
                              + (", ".join(f"<{a}>" for a in allowed) if allowed else "no nested elements") + " here")


def shape_material(element: Element, props: Properties, reading: Reading) -> Material:
    """A shape's nested <bsdf> or <ref>, or Mitsuba's default diffuse; an area emitter is an error."""
    for child in props.plugins:
        if child.tag == "emitter":
            raise child.error("an emitter on a shape (an area light): pyclray's lights are point and directional")
    only_plugins(element, props, ("bsdf", "ref"))
    found = [child for child in props.plugins if child.tag in ("bsdf", "ref")]
    if len(found) > 1:
        raise found[1].error("a shape has one bsdf")
    return material(found[0], reading) if found else Material(MITSUBA_DIFFUSE)


# -- shapes ----------------------------------------------------------------------------------------
def shape_properties(element: Element, reading: Reading) -> Properties:
    props = Properties(element, outer=reading.outer)
    if props.take("flip_normals", "boolean", False):
        raise props.element.error("flip_normals = true: pyclray's normals point out of the shape, never flipped")
    return props


def add_shape(element: Element, reading: Reading, props: Properties, make) -> None:
    """make(name=..., material=...): the shape, once its nested elements and properties are read."""
    material_ = shape_material(element, props, reading)
    props.finish()
    reading.shapes.append(checked(element, make, name=name_of(element, reading, "shape"), material=material_))


def registered_shape(cls):
    """The builder of the plugins a shape type reads (cls.mitsuba_plugins): its from_mitsuba takes
    the properties, the shape gets its name and material here."""
    def build(element: Element, reading: Reading) -> None:
        props = shape_properties(element, reading)
        add_shape(element, reading, props, cls.from_mitsuba(props, reading.folder or Path(".")))
    return build


def shapegroup(element: Element, reading: Reading) -> None:
    """A named group of shapes (any of the plugins pyclray reads, as Mitsuba instances any), drawn
    only where an instance places it: each is read here once, to say what is wrong with it at its
    own line, and again by each instance, under its to_world."""
    if "id" not in element.attrs:
        raise element.error("a shapegroup needs an id for instances to refer to")
    props = Properties(element)
    props.finish()
    children = []
    for child in props.plugins:
        if child.tag != "shape":
            raise child.error("not read inside a shapegroup: pyclray reads its <shape>s")
        kind = plugin_type(child, SHAPES)
        if kind in ("shapegroup", "instance"):
            raise child.error(f"a {kind} inside a shapegroup (Mitsuba nests neither)")
        SHAPES[kind](child, Reading(folder=reading.folder, bsdfs=reading.bsdfs))
        children.append((kind, child))
    reading.groups[element.attrs["id"]] = children


def instance(element: Element, reading: Reading) -> None:
    """A shapegroup's shapes placed by to_world (after their own placement), named ID_k (ID the
    instance's id or instance<index>): a shape read under the composed transform, as Mitsuba places
    it (a sphere stays a sphere only under a similarity: another is an error naming the instance).
    Meshes of one file share its triangles (instances on the device)."""
    props = Properties(element)
    to_world = props.take("to_world", "transform", IDENTITY)
    props.finish()
    refs = [child for child in props.plugins if child.tag == "ref"]
    only_plugins(element, props, ("ref",))
    if len(refs) != 1:
        raise element.error("expected one <ref id=...> to a shapegroup")
    group = reading.groups.get(refs[0].attribute("id"))
    if group is None:
        raise refs[0].error(f"no <shape type=\"shapegroup\" id=\"{refs[0].attrs['id']}\"> before this reference")
    name = name_of(element, reading, "shape")
    placed = Reading(folder=reading.folder, bsdfs=reading.bsdfs, outer=to_world)
    for kind, child in group:
        try:
            SHAPES[kind](child, placed)
        except SceneError as error:  # what this placement makes of the shape: said of the instance
            raise element.error(f"placing {error.message}") from None
    for k, shape in enumerate(placed.shapes):
        reading.shapes.append(checked(element, replace, shape, name=f"{name}_{k}"))


# each shape type's plugins (the registry's), and the groups of shapes and their instances
SHAPES = {plugin: registered_shape(cls) for cls in REGISTRY.values() for plugin in cls.mitsuba_plugins}
SHAPES.update(shapegroup=shapegroup, instance=instance)


# -- emitters --------------------------------------------------------------------------------------
def point_light(element: Element, reading: Reading) -> None:
    props = Properties(element)
    position = props.take("position", "point", np.zeros(3))
    to_world = props.take("to_world", "transform", IDENTITY)
    intensity = props.take("intensity", "rgb", np.ones(3))
    props.finish()
    only_plugins(element, props, ())
    reading.lights.append(checked(element, PointLight, tuple(to_world.point(position)), tuple(intensity),
                                  name_of(element, reading, "emitter")))


def directional_light(element: Element, reading: Reading) -> None:
    props = Properties(element)
    to_world = props.take("to_world", "transform", IDENTITY)
    direction = props.take("direction", "vector", np.array([0.0, 0.0, 1.0]))
    irradiance = props.take("irradiance", "rgb", np.ones(3))
    props.finish()
    only_plugins(element, props, ())
    reading.lights.append(checked(element, DirectionalLight, tuple(to_world.matrix[:3, :3] @ direction),
                                  tuple(irradiance), name_of(element, reading, "emitter")))


EMITTERS = {"point": point_light, "directional": directional_light}
