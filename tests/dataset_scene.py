"""A small scene for the data set tests: two labelled meshes (a cube turned and scaled, and a wedge
placed by a matrix), a sphere without a label partly in front of them (scenery: an occluder), and a
ground plane; and the PNG reader the tests use."""
from __future__ import annotations

import zlib
import struct

import numpy as np

CUBE_VERTICES = [[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
CUBE_FACES = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
              [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
WEDGE_VERTICES = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
WEDGE_FACES = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]


def scene_text() -> str:
    return f"""
[camera]
eye = [0.3, 1.6, 4.0]
target = [0.0, 0.5, 0.0]
fov = 50.0

[image]
width = 64
height = 48

[[shapes]]
type = "plane"
name = "ground"
normal = [0.0, 1.0, 0.0]
offset = 0.0

[[shapes]]
type = "mesh"
name = "cube"
vertices = {CUBE_VERTICES}
faces = {CUBE_FACES}
scale = [0.8, 0.6, 0.7]
axis = [0.0, 1.0, 0.0]
angle = 25.0
translate = [-0.5, 0.3, 0.0]
label = 1

[[shapes]]
type = "sphere"
name = "ball"
center = [0.1, 0.4, 0.9]
radius = 0.25

[[shapes]]
type = "mesh"
name = "wedge"
vertices = {WEDGE_VERTICES}
faces = {WEDGE_FACES}
matrix = [[0.0, -0.6, 0.0, 0.6], [0.6, 0.0, 0.0, 0.01], [0.0, 0.0, 0.6, -0.2], [0.0, 0.0, 0.0, 1.0]]
label = 7
"""


def write_scene(folder) -> str:
    path = folder / "objects.toml"
    path.write_text(scene_text())
    return str(path)


def read_png(path) -> np.ndarray:
    """A PNG as written by pyclray.io.dataset.images (8/16-bit grey or 8-bit RGB, filter 0), read
    here independently: its IDAT inflated, each row's filter byte checked."""
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    at, idat, header = 8, b"", None
    while at < len(data):
        length, kind = struct.unpack(">I4s", data[at:at + 8])
        body = data[at + 8:at + 8 + length]
        assert struct.unpack(">I", data[at + 8 + length:at + 12 + length])[0] == zlib.crc32(kind + body)
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        at += 12 + length
    width, height, depth, colour = header[:4]
    channels = {0: 1, 2: 3}[colour]
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(height, -1)
    assert (raw[:, 0] == 0).all()
    pixels = raw[:, 1:]
    if depth == 16:
        pixels = pixels.copy().view(">u2").astype(np.uint16)
    return pixels.reshape(height, width, channels) if channels == 3 else pixels.reshape(height, width)
