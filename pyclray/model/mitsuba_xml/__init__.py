"""Mitsuba 3 XML scenes read as pyclray scenes (scene-format.md, "Mitsuba scenes"; docs/mitsuba.md).

No Mitsuba is imported: the file is parsed with expat (tree.py), its properties and transforms read
as Mitsuba's parser reads them (properties.py), and each plugin built by its entry in PLUGINS
(plugins.py, sensor.py). Anything pyclray has no counterpart for is a SceneError naming the file,
the element and its line.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..scene import Scene
from .plugins import BSDFS, EMITTERS, SHAPES, Reading, material, plugin_type
from .sensor import SENSORS
from .tree import Element, parse, substitute

# render settings with no meaning for pyclray's casts (one unjittered ray per pixel centre)
IGNORED = ("integrator", "sampler")

# element -> {plugin type -> builder(element, reading)}: a new plugin is one entry
PLUGINS = {"sensor": SENSORS, "shape": SHAPES, "emitter": EMITTERS}


def top_level_bsdf(element: Element, reading: Reading) -> None:
    """A named <bsdf id=...> that shapes refer to with <ref id=.../>."""
    plugin_type(element, BSDFS)
    if "id" not in element.attrs:
        raise element.error("a <bsdf> outside a shape needs an id for shapes to refer to")
    reading.bsdfs[element.attrs["id"]] = material(element, reading)


def scene_from_tree(root: Element, source: str | None = None) -> Scene:
    if root.tag != "scene":
        raise root.error("expected a Mitsuba scene: the root element <scene version=...>")
    substitute(root)
    reading = Reading(folder=Path(source).parent if source else None)
    for element in root.children:
        if element.tag in IGNORED:
            continue
        if element.tag == "bsdf":
            top_level_bsdf(element, reading)
        elif element.tag in PLUGINS:
            table = PLUGINS[element.tag]
            builder = table[plugin_type(element, table)]
            try:
                # numbers that overflow once placed (a point at 1e308 minus another): one line, not
                # a numpy warning and an inf or NaN shape
                with np.errstate(over="raise", invalid="raise", divide="raise"):
                    builder(element, reading)
            except FloatingPointError:
                raise element.error("its numbers overflow once placed (beyond float64's range)") from None
        else:
            known = ", ".join(f"<{tag}>" for tag in (*PLUGINS, "bsdf", *IGNORED, "default"))
            raise element.error(f"not read by pyclray (it reads {known}; docs/mitsuba.md)")
    if reading.camera is None:
        raise root.error('no <sensor type="perspective">: pyclray needs the camera')
    names = {}
    for index, shape in enumerate(reading.shapes):
        if shape.name in names:
            raise SceneError(f"two shapes named {shape.name!r} (shapes #{names[shape.name]} and #{index})")
        names[shape.name] = index
    return Scene(reading.camera, reading.image, tuple(reading.shapes), source, tuple(reading.lights))


def load_xml(raw: bytes, source: str | None = None) -> Scene:
    """The Scene of a Mitsuba 3 XML file's bytes; a SceneError naming the file, element and line."""
    try:
        return scene_from_tree(parse(raw), source)
    except SceneError as error:
        raise error.within(file=source) from None
    except RecursionError:
        raise SceneError("not a scene: elements nested too deeply", file=source) from None
