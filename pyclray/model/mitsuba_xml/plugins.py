"""The Mitsuba plugins pyclray reads, one builder each, found by (element, plugin type) in PLUGINS.

A builder takes the element and the scene being read (``Reading``) and adds what it makes to it.
A plugin of Mitsuba's that pyclray has no counterpart for is not in the table: reading one is an
error naming the element and its line.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..camera import Camera, Image
from ..errors import SceneError
from ..lights import DirectionalLight, Material, PointLight
from ..shapes import Box, Cylinder, Disk, Mesh, Rectangle, Sphere
from .properties import IDENTITY, Properties, Transform
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
    groups: dict = field(default_factory=dict)  # shapegroup id -> its meshes


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
def shape_properties(element: Element) -> Properties:
    props = Properties(element)
    if props.take("flip_normals", "boolean", False):
        raise props.element.error("flip_normals = true: pyclray's normals point out of the shape, never flipped")
    return props


def add_shape(element: Element, reading: Reading, props: Properties, make, *args, **keys) -> None:
    material_ = shape_material(element, props, reading)
    props.finish()
    reading.shapes.append(checked(element, make, *args, name=name_of(element, reading, "shape"), material=material_,
                                  **keys))


def sphere(element: Element, reading: Reading) -> None:
    props = shape_properties(element)
    center = props.take("center", "point", np.zeros(3))
    radius = props.take("radius", "float", 1.0)
    to_world = props.take("to_world", "transform", IDENTITY)
    scale = to_world.similarity(element, "a sphere stays a sphere")
    add_shape(element, reading, props, Sphere, tuple(to_world.point(center)), radius * scale)


def flat_frame(element: Element, to_world: Transform):
    """(centre, first axis, second axis, unit normal) of Mitsuba's unit shape in z = 0 under
    to_world. Its normal is to_world's normal transform of +z, (M^-T) e_z, which is
    det(M) cross(M e_x, M e_y) / |...|: a mirroring transform turns it around."""
    columns = to_world.columns()
    normal = np.cross(columns[0], columns[1]) * math.copysign(1.0, np.linalg.det(to_world.matrix[:3, :3]))
    return to_world.point(np.zeros(3)), columns[0], columns[1], normal / np.linalg.norm(normal)


def rectangle(element: Element, reading: Reading) -> None:
    """Mitsuba's rectangle is [-1, 1]^2 in z = 0: centre, u and v are to_world's image of it; a
    mirroring to_world swaps u and v, so that cross(u, v) stays along Mitsuba's normal."""
    props = shape_properties(element)
    to_world = props.take("to_world", "transform", IDENTITY)
    center, u, v, normal = flat_frame(element, to_world)
    if np.dot(np.cross(u, v), normal) < 0:
        u, v = v, u
    add_shape(element, reading, props, Rectangle, tuple(center), tuple(u), tuple(v))


def disk(element: Element, reading: Reading) -> None:
    """Mitsuba's disk is the unit disk in z = 0: to_world must keep it round."""
    props = shape_properties(element)
    to_world = props.take("to_world", "transform", IDENTITY)
    center, u, v, normal = flat_frame(element, to_world)
    ru, rv = np.linalg.norm(u), np.linalg.norm(v)
    if abs(np.dot(u, v)) > 1e-9 * ru * rv or abs(ru - rv) > 1e-9 * max(ru, rv):
        raise element.error("to_world turns the disk into an ellipse: pyclray's disks are round")
    add_shape(element, reading, props, Disk, tuple(center), tuple(normal), float(0.5 * (ru + rv)))


def rotation_axis_angle(R: np.ndarray):
    """(axis, degrees) of a rotation matrix, via its quaternion (Shepperd's method: the largest of
    the four squared components is taken first, so no division is near zero); (None, 0) for none."""
    trace = np.trace(R)
    squares = [trace, R[0, 0], R[1, 1], R[2, 2]]
    k = int(np.argmax(squares))
    if k == 0:
        w = math.sqrt(1 + trace) / 2
        x, y, z = (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)
    else:
        i, j, m = k - 1, k % 3, (k + 1) % 3
        q = np.zeros(3)
        q[i] = math.sqrt(max(0.0, 1 + R[i, i] - R[j, j] - R[m, m])) / 2
        q[j] = (R[j, i] + R[i, j]) / (4 * q[i])
        q[m] = (R[m, i] + R[i, m]) / (4 * q[i])
        w = (R[m, j] - R[j, m]) / (4 * q[i])
        x, y, z = q
    vector = np.array([x, y, z]) * (1 if w >= 0 else -1)
    length = np.linalg.norm(vector)
    if length == 0:
        return None, 0.0
    return tuple(vector / length), math.degrees(2 * math.atan2(length, abs(w)))


def cube(element: Element, reading: Reading) -> None:
    """Mitsuba's cube is a 12-triangle mesh of [-1, 1]^3: a pyclray box where to_world keeps its
    faces square to each other (no shear) and does not mirror it (a mirror turns the mesh's
    triangles, and so its normals, inward)."""
    props = shape_properties(element)
    to_world = props.take("to_world", "transform", IDENTITY)
    columns = to_world.columns()
    half = np.linalg.norm(columns, axis=1)
    gram = columns @ columns.T / np.outer(half, half)
    if np.abs(gram - np.eye(3)).max() > 1e-9:
        raise element.error("to_world shears the cube: pyclray's boxes have square corners")
    R = (columns / half[:, None]).T  # the box's unit axes as columns
    if np.linalg.det(R) < 0:
        raise element.error("to_world mirrors the cube, which turns its triangles' normals inward; pyclray's box "
                            "has outward normals")
    axis, angle = rotation_axis_angle(R)
    add_shape(element, reading, props, Box, tuple(to_world.point(np.zeros(3))), tuple(2 * half), axis, angle)


def cylinder(element: Element, reading: Reading) -> None:
    """Mitsuba's cylinder is open (no caps): pyclray's cylinder with caps = false. Its local frame
    (to_world, then p0 and the axis p1 - p0, then the radius) must keep its cross-section round."""
    props = shape_properties(element)
    p0 = props.take("p0", "point", np.zeros(3))
    p1 = props.take("p1", "point", np.array([0.0, 0.0, 1.0]))
    radius = props.take("radius", "float", 1.0)
    to_world = props.take("to_world", "transform", IDENTITY)
    axis = p1 - p0
    if not np.any(axis):
        raise element.error("p0 and p1 are the same point")
    from ..shapes.base import frame_columns

    t1, t2, _ = frame_columns(axis / np.linalg.norm(axis))
    x, y, z = (to_world.matrix[:3, :3] @ v for v in (t1 * radius, t2 * radius, axis))
    rx, ry = np.linalg.norm(x), np.linalg.norm(y)
    if (abs(np.dot(x, y)) > 1e-9 * rx * ry or abs(rx - ry) > 1e-9 * max(rx, ry)
            or max(abs(np.dot(x, z)), abs(np.dot(y, z))) > 1e-9 * rx * np.linalg.norm(z)):
        raise element.error("to_world makes the cylinder elliptic or slanted: pyclray's cylinders are round and upright")
    add_shape(element, reading, props, Cylinder, tuple(to_world.point(p0)), tuple(to_world.point(p1)),
              float(0.5 * (rx + ry)), False)


def as_matrix(to_world: Transform):
    """A mesh's matrix key (row by row), or None for the identity."""
    return None if np.array_equal(to_world.matrix, np.eye(4)) else tuple(map(tuple, to_world.matrix.tolist()))


def mesh_file(element: Element, reading: Reading) -> None:
    """Mitsuba's obj and ply: pyclray's triangle mesh of the file (relative to the scene file's
    folder), placed by to_world. Its geometric normals are the faces' in both; face_normals (whether
    Mitsuba shades with them rather than the file's vertex normals) changes no geometry, and pyclray
    shades with the faces' normals (its smooth shading is not there yet)."""
    props = shape_properties(element)
    filename = props.take("filename", "string", required=True)
    to_world = props.take("to_world", "transform", IDENTITY)
    props.ignore.update(("face_normals", "flip_tex_coords", "maintain_order"))  # shading, textures, merging
    path = (reading.folder or Path(".")) / filename
    add_shape(element, reading, props, Mesh.load, path, matrix=as_matrix(to_world))


def shapegroup(element: Element, reading: Reading) -> None:
    """A named group of shapes, drawn only where an instance places it: its meshes are read here."""
    if "id" not in element.attrs:
        raise element.error("a shapegroup needs an id for instances to refer to")
    props = Properties(element)
    props.finish()
    group = Reading(folder=reading.folder, bsdfs=reading.bsdfs)
    for child in props.plugins:
        if child.tag != "shape":
            raise child.error("not read inside a shapegroup: pyclray reads its <shape>s")
        kind = plugin_type(child, SHAPES)
        if kind not in ("obj", "ply"):
            raise child.error(f"a {kind!r} shape in a shapegroup: pyclray instances triangle meshes (obj, ply)")
        SHAPES[kind](child, group)
    reading.groups[element.attrs["id"]] = group.shapes


def instance(element: Element, reading: Reading) -> None:
    """A shapegroup's meshes placed by to_world (after their own placement): the same triangles,
    shared, named ID_k (ID the instance's id or instance<index>)."""
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
    for k, mesh in enumerate(group):
        matrix = tuple(map(tuple, (to_world.matrix @ mesh.transform()).tolist()))
        reading.shapes.append(checked(element, mesh.placed, matrix=matrix, name=f"{name}_{k}"))


SHAPES = {"sphere": sphere, "rectangle": rectangle, "disk": disk, "cube": cube, "cylinder": cylinder,
          "obj": mesh_file, "ply": mesh_file, "shapegroup": shapegroup, "instance": instance}


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
