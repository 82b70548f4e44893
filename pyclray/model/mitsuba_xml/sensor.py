"""Mitsuba's sensors as pyclray cameras and an image size: each camera model that has a Mitsuba
sensor (its mitsuba_plugin) reads it (its from_mitsuba), given the properties it names, the film's
size and to_world.

Its to_world is a look-at (kept as such: the same rays as Mitsuba's own look_at) or any rotation,
translation and uniform scale. A mirroring or stretching to_world has no pyclray camera: an error.
"""
from __future__ import annotations

from functools import partial

import numpy as np

from ..camera import Image
from ..cameras import CAMERAS, CameraModel, LookAt, MitsubaSensor
from .plugins import FILM_SETTINGS, FILM_SIZE, SENSOR_SETTINGS, Reading, checked, only_plugins, plugin_type
from .properties import IDENTITY, Properties
from .tree import Element


def film(element: Element) -> tuple[int, int]:
    plugin_type(element, {"hdrfilm": None, "specfilm": None})
    props = Properties(element, ignore=FILM_SETTINGS)
    width = props.take("width", "integer", FILM_SIZE[0])
    height = props.take("height", "integer", FILM_SIZE[1])
    props.finish()
    only_plugins(element, props, ("rfilter",))
    return width, height


def sensor(model: type[CameraModel], element: Element, reading: Reading) -> None:
    """The camera (of this model) and the image size of a <sensor> of the model's mitsuba_plugin."""
    if reading.camera is not None:
        raise element.error("a second sensor: pyclray renders a scene through one camera")
    props = Properties(element, ignore=SENSOR_SETTINGS)
    values = {name: props.take(name, kind, default) for name, kind, default in model.mitsuba_properties}
    to_world = props.take("to_world", "transform", IDENTITY)
    props.finish()
    only_plugins(element, props, ("film", "sampler"))
    films = [child for child in props.plugins if child.tag == "film"]
    width, height = film(films[0]) if films else FILM_SIZE
    reading.image = checked(element, Image, width, height)
    to_world.similarity(element, "a camera's frame: anything else stretches the image")
    if np.linalg.det(to_world.matrix[:3, :3]) < 0:
        raise element.error("to_world mirrors the image (a negative determinant): pyclray's cameras do not")
    look_at = None if to_world.look_at_args is None else LookAt(*to_world.look_at_args)
    data = MitsubaSensor(model.mitsuba_plugin, values, width, height, to_world.matrix, look_at)
    reading.camera = checked(element, model.from_mitsuba, data)


# Mitsuba's sensor plugin -> its reader: one per camera model that has one
SENSORS = {model.mitsuba_plugin: partial(sensor, model) for model in CAMERAS.values() if model.mitsuba_plugin}
