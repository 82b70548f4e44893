"""Reading scenes: TOML files (scene-format.md) into a Scene; Mitsuba 3 XML files through mitsuba_xml."""
from __future__ import annotations

import os
import tomllib
from pathlib import Path

from .animation import Animation
from .camera import Image
from .cameras import CAMERAS, DEFAULT_MODEL, CameraModel
from .errors import RequestError, SceneError, no_unknown_keys, text, typed_table
from .lidar import Lidar
from .lights import Shading, lights_from_list
from .scene import Scene
from .shapes import REGISTRY


def as_scene(value) -> Scene:
    """A Scene, or the path of a scene file (loaded); anything else is a RequestError."""
    if isinstance(value, Scene):
        return value
    if isinstance(value, (str, os.PathLike)):
        return load_scene(value)
    raise RequestError(f"scene: expected a pyclray.Scene or the path of a scene file, got {type(value).__name__}")


def _table(data: dict, key: str, *, required: bool) -> dict:
    if key not in data:
        if required:
            raise SceneError(f"missing required table [{key}]")
        return {}
    if not isinstance(data[key], dict):
        raise SceneError(f"expected a table [{key}], got {type(data[key]).__name__}", key=key)
    return data[key]


def camera_from_table(table: dict) -> CameraModel:
    """The [camera] table: its model (default perspective; scene-format.md, "Camera models") reads
    the other keys (the perspective camera: eye, target, up, fov, fov_axis, or intrinsics and pose)."""
    model = text("model", table.get("model", DEFAULT_MODEL))
    if model not in CAMERAS:
        raise SceneError(f"unknown camera model {model!r} (expected one of: {', '.join(CAMERAS)})", key="model")
    return CAMERAS[model].from_table({key: value for key, value in table.items() if key != "model"})


def scene_from_dict(data: dict, source: str | None = None) -> Scene:
    """A Scene from the parsed contents of a scene file (see scene-format.md)."""
    if not isinstance(data, dict):
        raise SceneError(f"expected a table of [camera], [image] and [[shapes]], got {type(data).__name__}", file=source)
    try:
        no_unknown_keys(data, ("camera", "image", "shapes", "lights", "shading", "animation", "lidar", "lidars"),
                        required=())
    except SceneError as error:
        raise error.within(file=source, table="(top level)") from None
    lidars = lidars_from_data(data, source)
    try:
        if "camera" not in data and lidars:  # a sensor's scene: the camera looks where its first sensor does
            camera = sensor_camera(lidars[0])
        else:
            camera = camera_from_table(_table(data, "camera", required=True))
    except SceneError as error:
        raise error.within(file=source, table="[camera]") from None
    try:
        table = _table(data, "image", required=False)
        no_unknown_keys(table, ("width", "height"))
        image = Image(**table)
    except SceneError as error:
        raise error.within(file=source, table="[image]") from None

    entries = data.get("shapes", [])
    if not isinstance(entries, list):
        raise SceneError("expected an array of tables [[shapes]]", key="shapes", file=source)
    shapes, seen, tables = [], {}, []
    for index, entry in enumerate(entries):
        where = f"[[shapes]] #{index}"
        try:
            kind = typed_table(entry, REGISTRY, "shape")
            where = f"[[shapes]] #{index} ({kind})"
            made = REGISTRY[kind].from_table(entry, index, Path(source).parent if source else None)
            for shape in made if isinstance(made, tuple) else (made,):  # a table may make several (split)
                # names are unique, as the lights' (a name is what an animation key targets; the
                # defaults "<type><index>" are unique)
                if shape.name in seen:
                    raise SceneError(f"the name {shape.name!r} is already used by [[shapes]] #{seen[shape.name]}",
                                     key="name")
                seen[shape.name] = index
                shapes.append(shape)
                tables.append(index)
        except SceneError as error:
            raise error.within(file=source, table=where) from None
    lights = lights_from_list(data.get("lights", []), source)
    try:
        shading = Shading.from_table(_table(data, "shading", required=False))
    except SceneError as error:
        raise error.within(file=source, table="[shading]") from None
    try:
        animation = Animation.from_table(data["animation"]) if "animation" in data else None
    except SceneError as error:
        raise error.within(file=source, table="[animation]") from None
    # each shape's table in the file, for messages, where a table made several shapes (ids != tables)
    tables = None if tables == list(range(len(tables))) else tuple(tables)
    return Scene(camera, image, tuple(shapes), source, lights, shading, animation=animation, tables=tables,
                 lidars=lidars)


def sensor_camera(lidar: Lidar) -> CameraModel:
    """The camera of a scene file without [camera] but with a sensor: at the sensor's origin, looking
    along its x axis (forward), its z axis up, a 90 degree field of view."""
    pose = lidar.world_from_sensor
    eye = pose[:3, 3]
    return CAMERAS[DEFAULT_MODEL].from_table({"eye": eye.tolist(), "target": (eye + pose[:3, 0]).tolist(),
                                             "up": pose[:3, 2].tolist(), "fov": 90.0})


def lidars_from_data(data: dict, source: str | None = None) -> tuple:
    """The scene file's sensors: one [lidar] table or an array of [[lidars]] tables (not both),
    scene-format.md "LiDAR"; a SceneError naming the table and the key."""
    if "lidar" in data and "lidars" in data:
        raise SceneError("expected one [lidar] table or an array of [[lidars]] tables, not both", key="lidars",
                         file=source, table="(top level)")
    if "lidar" in data:
        entries, tables = [data["lidar"]], ["[lidar]"]
        if not isinstance(data["lidar"], dict):
            raise SceneError("expected a table [lidar] (several sensors: [[lidars]])", key="lidar", file=source,
                             table="(top level)")
    else:
        entries = data.get("lidars", [])
        if not isinstance(entries, list):
            raise SceneError("expected an array of tables [[lidars]]", key="lidars", file=source, table="(top level)")
        tables = [f"[[lidars]] #{index}" for index in range(len(entries))]
    lidars = []
    for index, (entry, table) in enumerate(zip(entries, tables)):
        try:
            lidars.append(Lidar.from_table(entry, f"lidar{index}"))
        except SceneError as error:
            raise error.within(file=source, table=table) from None
    return tuple(lidars)


def load_scene(path) -> Scene:
    """Read and validate a scene file (TOML, or Mitsuba 3 XML for a .xml file); raises SceneError
    naming the file, table and key (an XML file's element and line)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as error:
        raise SceneError(f"cannot read the scene file: {(error.strerror or str(error)).lower()}", file=path) from None
    if path.suffix.lower() == ".xml":
        from .mitsuba_xml import load_xml

        return load_xml(raw, source=str(path))
    try:
        # a UTF-8 byte order mark (as some editors write) is not part of the text
        data = tomllib.loads(raw.removeprefix(b"\xef\xbb\xbf").decode("utf-8"))
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"not valid TOML: {error}", file=path) from None
    except UnicodeDecodeError as error:
        raise SceneError(f"not valid UTF-8 text: {error}", file=path) from None
    except RecursionError:
        raise SceneError("not a scene: arrays or tables nested too deeply", file=path) from None
    return scene_from_dict(data, source=str(path))
