"""A pyclray scene as a Mitsuba 3 XML scene (``pyclray export``), written without Mitsuba.

The description is the check's (``mitsuba.mitsuba_dict``: the same sensor, the same shapes' counterparts)
with, for a picture, each shape's colour as a two-sided diffuse BSDF, the lights as point and
directional emitters (the headlight where the scene has none), and the aov integrator around the
direct integrator (Mitsuba renders the picture and pyclray's AOVs together). Shapes keep their names
as Mitsuba ids (a shape of several Mitsuba parts: name_1, name_2, ...). pyclray's specular term, ambient
light and background colour have no counterpart in Mitsuba's diffuse model and are not written.
Numbers are written as Python's repr of the float64 (the shortest text that reads back the same).
"""
from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from ..model.cameras import CAMERAS, LookAt
from ..model.lights import effective_lights
from .mitsuba import AOV_SPEC, emitter_dict, mitsuba_dict

# the element a plugin of each type is written as (a sensor: each camera model's Mitsuba plugin)
TAGS = {
    **{model.mitsuba_plugin: "sensor" for model in CAMERAS.values() if model.mitsuba_plugin},
    "hdrfilm": "film", "stratified": "sampler", "independent": "sampler", "box": "rfilter",
    "aov": "integrator", "direct": "integrator", "path": "integrator", "twosided": "bsdf", "diffuse": "bsdf",
    "sphere": "shape", "disk": "shape", "rectangle": "shape", "cube": "shape", "cylinder": "shape",
    "obj": "shape", "ply": "shape", "point": "emitter", "directional": "emitter",
    "shapegroup": "shape", "instance": "shape",
}
VECTORS = ("direction",)  # 3-vectors written as <vector>; the others are <point>s
MESH_ARRAYS = ("vertex_positions", "faces")  # a mesh's arrays: written to its PLY file, not the XML


def shape_keys(scene):
    """key(index, part): a shape's name as its Mitsuba id (its index added where names repeat, as
    in scenes built in Python); the parts after the first get _1, _2, ..."""
    names = [shape.name for shape in scene.shapes]
    unique = len(set(names)) == len(names)

    def key(index: int, part: int = 0) -> str:
        name = names[index] if unique else f"{names[index]}_{index}"
        return name if part == 0 else f"{name}_{part}"

    return key


def export_dict(scene, mesh_file=lambda key: f"{key}.ply") -> dict:
    """The Mitsuba scene description that ``pyclray export`` writes (plain values, see mitsuba_dict).
    A triangle mesh becomes a ``ply`` shape of the file mesh_file(its id) (face normals: the check's
    mi.Mesh has no vertex normals), its world vertices and faces under "vertex_positions" and "faces"
    for the writer (export_files), which leaves them out of the XML."""
    key = shape_keys(scene)
    out = mitsuba_dict(scene, AOV_SPEC, key)
    for name, value in out.items():
        if isinstance(value, dict) and value.get("type") == "mesh":
            out[name] = {"type": "ply", "filename": mesh_file(name), "face_normals": True,
                         "vertex_positions": value["vertex_positions"], "faces": value["faces"]}
    out["integrator"]["inner"] = {"type": "direct"}
    for index, shape in enumerate(scene.shapes):
        bsdf = {"type": "twosided", "bsdf": {"type": "diffuse",
                                             "reflectance": {"type": "rgb", "value": list(shape.material.color)}}}
        part = 0
        while key(index, part) in out:
            out[key(index, part)]["bsdf"] = bsdf
            part += 1
    for index, light in enumerate(effective_lights(scene)):
        out[f"emitter:{light.name}"] = emitter_dict(light)
    return instanced(scene, out, key, mesh_file)


def instanced(scene, out: dict, key, mesh_file) -> dict:
    """The description with the meshes that share their arrays (as pyclray instances them) written as
    Mitsuba's shapegroup (one PLY of the object-space vertices, before its first instance) and one
    instance each (its to_world): Mitsuba's instances share their group's BSDF (its first mesh's
    colour). The check itself builds each mesh on its own (mitsuba.mitsuba_dict)."""
    from ..model.shapes.mesh_sharing import shared_key

    groups: dict = {}
    for index, shape in enumerate(scene.shapes):
        if shape.mitsuba_in_groups and key(index) in out:  # a shape Mitsuba's shapegroups hold (a mesh)
            groups.setdefault(shared_key(shape), []).append(index)
    placed = {}
    for members in (m for m in groups.values() if len(m) > 1):
        first = scene.shapes[members[0]]
        name = f"group_{key(members[0])}"
        mesh = {"type": "ply", "filename": mesh_file(name), "face_normals": True,
                "vertex_positions": first.vertices, "faces": first.faces, "bsdf": out[key(members[0])]["bsdf"]}
        for n, index in enumerate(members):
            placed[key(index)] = ((name, {"type": "shapegroup", "mesh": mesh}) if n == 0 else None,
                                  {"type": "instance", "shapegroup": {"type": "ref", "id": name},
                                   "to_world": scene.shapes[index].transform()})
    result = {}
    for name, value in out.items():
        if name in placed:
            group, value = placed[name]
            if group is not None:
                result[group[0]] = group[1]
        result[name] = value
    return result


def _number(value) -> str:
    return repr(float(value))


def _element(tag: str, name: str | None, body: dict, indent: str, identifier: str | None = None) -> list[str]:
    """<tag type=...> with the properties and nested plugins of a plugin dict."""
    attributes = f" type={quoteattr(body['type'])}"
    if identifier is not None:
        attributes += f" id={quoteattr(identifier)}"
    if name is not None:
        attributes += f" name={quoteattr(name)}"
    inner = [line for key, value in body.items() if key not in ("type", *MESH_ARRAYS)
             for line in _property(key, value, indent + "    ")]
    if not inner:
        return [f"{indent}<{tag}{attributes}/>"]
    return [f"{indent}<{tag}{attributes}>", *inner, f"{indent}</{tag}>"]


def _property(name: str, value, indent: str) -> list[str]:
    """One property: a value (float, integer, boolean, string, point, vector, rgb, transform) or a
    nested plugin."""
    label = quoteattr(name)
    if isinstance(value, LookAt):
        look = " ".join(f"{k}={quoteattr(', '.join(map(_number, getattr(value, k))))}" for k in ("origin", "target", "up"))
        return [f"{indent}<transform name={label}>", f"{indent}    <lookat {look}/>", f"{indent}</transform>"]
    if isinstance(value, np.ndarray) and value.shape == (4, 4):
        numbers = " ".join(map(_number, value.ravel()))
        return [f"{indent}<transform name={label}>", f"{indent}    <matrix value=\"{numbers}\"/>", f"{indent}</transform>"]
    if isinstance(value, dict) and value.get("type") == "ref":  # a shapegroup's, in an instance
        return [f"{indent}<ref id={quoteattr(value['id'])}/>"]
    if isinstance(value, dict) and value.get("type") == "rgb":
        return [f"{indent}<rgb name={label} value=\"{', '.join(map(_number, value['value']))}\"/>"]
    if isinstance(value, dict):
        return _element(TAGS[value["type"]], None, value, indent)
    if isinstance(value, (bool, np.bool_)):
        return [f"{indent}<boolean name={label} value=\"{'true' if value else 'false'}\"/>"]
    if isinstance(value, (int, np.integer)):
        return [f"{indent}<integer name={label} value=\"{int(value)}\"/>"]
    if isinstance(value, (float, np.floating)):
        return [f"{indent}<float name={label} value=\"{_number(value)}\"/>"]
    if isinstance(value, str):
        return [f"{indent}<string name={label} value={quoteattr(value)}/>"]
    kind = "vector" if name in VECTORS else "point"
    return [f"{indent}<{kind} name={label} value=\"{', '.join(map(_number, value))}\"/>"]


def to_xml(description: dict, comment: str | None = None) -> str:
    """The XML text of a plain Mitsuba scene description (mitsuba_dict, export_dict)."""
    lines = ['<?xml version="1.0" encoding="utf-8"?>']
    if comment:
        lines.append(f"<!-- {comment.replace('--', '- -')} -->")
    lines.append('<scene version="3.0.0">')
    used = set(description)
    for key, value in description.items():
        if key == "type":
            continue
        tag = TAGS[value["type"]]
        if key.startswith("emitter:"):  # its name as its id, unless a shape has that id
            name = key.removeprefix("emitter:")
            lines += _element(tag, None, value, "    ", None if name in used else name)
        elif tag == "shape":
            lines += _element(tag, None, value, "    ", key)
        else:
            lines += _element(tag, None, value, "    ")
    lines.append("</scene>")
    return "\n".join(lines) + "\n"


def scene_xml(scene, mesh_file=lambda key: f"{key}.ply") -> str:
    """The Mitsuba 3 XML text of a pyclray scene (export_dict; its meshes' PLY files: export_files)."""
    source = f" from {scene.source}" if scene.source else ""
    return to_xml(export_dict(scene, mesh_file), f"written by pyclray export{source}")


def ply_bytes(vertices, faces) -> bytes:
    """A binary PLY file of triangles: float64 vertices (Mitsuba rounds them once to float32, as the
    check's mi.Mesh of the same arrays) and int32 vertex indices."""
    vertices = np.ascontiguousarray(vertices, "<f8").reshape(-1, 3)
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    header = ("ply\nformat binary_little_endian 1.0\ncomment written by pyclray export\n"
              f"element vertex {len(vertices)}\nproperty double x\nproperty double y\nproperty double z\n"
              f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    rows = np.zeros(len(faces), dtype=[("n", "u1"), ("v", "<i4", 3)])
    rows["n"], rows["v"] = 3, faces
    return header + vertices.tobytes() + rows.tobytes()


def export_files(scene, path) -> dict:
    """{path: bytes} of every file ``pyclray export SCENE -o path`` writes: the XML, and beside it one
    PLY file per triangle mesh, named STEM.ID.ply (STEM: the XML's, ID: the mesh's id)."""
    from pathlib import Path

    path = Path(path)
    description = export_dict(scene, lambda key: f"{path.stem}.{key}.ply")
    source = f" from {scene.source}" if scene.source else ""
    files = {path: to_xml(description, f"written by pyclray export{source}").encode("utf-8")}
    for value in description.values():
        value = value.get("mesh", value) if isinstance(value, dict) and value.get("type") == "shapegroup" else value
        if isinstance(value, dict) and value.get("type") == "ply":
            files[path.with_name(value["filename"])] = ply_bytes(value["vertex_positions"], value["faces"])
    return files
