"""Reading a triangle mesh's file: OBJ, PLY, STL, OFF, glTF/GLB.

What the contract asks (scene-format.md, "Triangle meshes"): the file's vertex and face order kept,
a polygon of k vertices becoming the k - 2 triangles (0, i, i + 1) in its place, a multi-object file
one mesh with its objects in file order. trimesh reads the binary formats (STL, glTF/GLB) with
``process=False, maintain_order=True``; its triangulation of polygons is neither a fan nor in place
(a quad's second triangles all go after the first ones), so the formats that hold polygons (OBJ, OFF,
PLY) have their faces read here (PLY through plyfile: any list types, mixed polygon sizes, ASCII and
both binary byte orders) and fanned.

Every failure is a SceneError at the key 'file' that says what is wrong with which file. A file is
read once per (path, size, modification time): scenes that name the same file share its arrays.
"""
from __future__ import annotations

import os
import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np

from ..errors import SceneError, _shown

FORMATS = (".obj", ".ply", ".stl", ".off", ".gltf", ".glb")
_cache: OrderedDict = OrderedDict()
_CACHE_MAX = 16
_lock = threading.Lock()


class _Bad(Exception):
    """A file's contents are not what its format says (turned into a SceneError with the file's name)."""


def read_mesh(path, folder=None):
    """(vertices (V, 3) float64, faces (F, 3) int64, normals (V, 3) float64 or None) of a mesh file,
    its objects one mesh in the file's order; read-only arrays shared by every caller that names the
    same unchanged file."""
    return _read(path, folder)[:3]


def read_mesh_objects(path, folder=None) -> tuple:
    """The objects of a mesh file, one (name, vertices, faces, normals) each in the file's order
    (OBJ's `o` and `g` groups, glTF's nodes with their transforms applied; any other file is one
    object): each object's own vertices (those its faces use, in the file's order) and its faces
    fanned in place. Names are the file's (an unnamed object takes the file's stem), made unique
    with _2, _3 ... Read-only arrays, shared by every caller that names the same unchanged file."""
    read = _read(path, folder)
    stem = Path(read[4][0]).stem
    key = ("objects",) + read[4]
    with _lock:
        if key in _cache:
            _cache.move_to_end(key)
            return _cache[key]
    vertices, faces, normals, objects, _ = read
    out, taken = [], set()
    for name, start, stop in objects:
        used = np.unique(faces[start:stop])  # sorted: the file's vertex order kept
        own = (vertices[used], np.searchsorted(used, faces[start:stop]), None if normals is None else normals[used])
        for array in own:
            if array is not None:
                array.setflags(write=False)
        out.append((_unique(name or stem, taken), *own))
    out = tuple(out)
    with _lock:
        _cache[key] = out
        while len(_cache) > _CACHE_MAX:
            _cache.popitem(last=False)
    return out


def _unique(name: str, taken: set) -> str:
    unique, k = name, 1
    while unique in taken:
        k += 1
        unique = f"{name}_{k}"
    taken.add(unique)
    return unique


def _read(path, folder):
    """(vertices, faces, normals, objects: ((name or None, first face, face stop), ...), cache key)."""
    if not isinstance(path, (str, os.PathLike)) or isinstance(path, bytes):
        raise SceneError(f"expected the path of a mesh file ({', '.join(FORMATS)}), got {_shown(path)}", key="file")
    full = Path(folder or ".") / path
    suffix = full.suffix.lower()
    if suffix not in FORMATS:
        raise SceneError(f"{path}: expected a mesh file ending in {', '.join(FORMATS)}", key="file")
    try:
        stat = full.stat()
    except OSError as error:
        raise SceneError(f"cannot read {path}: {(error.strerror or str(error)).lower()}", key="file") from None
    if full.is_dir():
        raise SceneError(f"cannot read {path}: is a folder", key="file")
    key = (str(full.resolve()), stat.st_size, stat.st_mtime_ns)
    with _lock:
        if key in _cache:
            _cache.move_to_end(key)
            return _cache[key]
    try:
        read = _READERS[suffix](full)
    except _Bad as error:
        raise SceneError(f"{path}: {error}", key="file") from None
    except OSError as error:
        raise SceneError(f"cannot read {path}: {(error.strerror or str(error)).lower()}", key="file") from None
    except Exception as error:  # a parser's own failure on a malformed file
        raise SceneError(f"{path}: not a readable {suffix[1:].upper()} file ({type(error).__name__}: "
                         f"{_one_line(error)})", key="file") from None
    vertices, faces, normals = read[:3]
    vertices = np.ascontiguousarray(vertices, np.float64).reshape(-1, 3)
    faces = np.ascontiguousarray(faces, np.int64).reshape(-1, 3)
    objects = tuple(read[3]) if len(read) > 3 else ((None, 0, len(faces)),)
    objects = tuple(o for o in objects if o[2] > o[1])  # an object without faces is none
    if not len(faces):
        raise SceneError(f"{path}: the file holds no triangles", key="file")
    bad = ((faces < 0) | (faces >= len(vertices))).any(axis=1)
    if bad.any():  # (said here of the file, before its objects are cut out of it)
        index = int(np.argmax(bad))
        raise SceneError(f"{path}: triangle {index} is {faces[index].tolist()}: expected vertex indices 0 .. "
                         f"{len(vertices) - 1} (the file has {len(vertices)} vertices)", key="file")
    if normals is not None:
        normals = np.ascontiguousarray(normals, np.float64).reshape(-1, 3)
        if len(normals) != len(vertices) or not np.isfinite(normals).all():
            normals = None  # unusable normals: the smooth shading computes its own
    for array in (vertices, faces, normals):
        if array is not None:
            array.setflags(write=False)
    out = (vertices, faces, normals, objects, key)
    with _lock:
        _cache[key] = out
        while len(_cache) > _CACHE_MAX:
            _cache.popitem(last=False)
    return out


def fan(polygons) -> np.ndarray:
    """The triangles (0, i, i + 1) of each polygon (a sequence of index sequences), in place."""
    sizes = np.fromiter((len(p) for p in polygons), np.int64, len(polygons))
    if len(sizes) and (sizes == 3).all():
        return np.array(polygons, np.int64).reshape(-1, 3)
    flat = np.concatenate([np.asarray(p, np.int64).reshape(-1) for p in polygons]) if len(sizes) else np.zeros(0, np.int64)
    return fan_flat(flat, sizes)


def fan_flat(flat: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """fan of polygons given as their indices one after another (flat) and their vertex counts."""
    if len(sizes) and (sizes < 3).any():
        index = int(np.argmax(sizes < 3))
        raise _Bad(f"face {index} has {int(sizes[index])} vertices (a face needs at least 3)")
    starts = np.cumsum(sizes) - sizes
    counts = sizes - 2  # triangles per polygon
    first = np.repeat(starts, counts)
    step = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)  # 0 .. k-3 in each
    return np.stack([flat[first], flat[first + step + 1], flat[first + step + 2]], axis=1).reshape(-1, 3)


def _read_off(path: Path):
    """OFF (and NOFF, COFF): counts, vertex lines (x y z [nx ny nz] [colour]), face lines (k i_0 .. i_k-1 [colour])."""
    lines = []
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            lines.append(line)
    if not lines or not lines[0].split()[0].upper().endswith("OFF"):
        raise _Bad("expected an OFF header ('OFF' on the first line)")
    header = lines[0].split()
    with_normals = header[0].upper().startswith(("NOFF", "CNOFF"))
    rest = header[1:] or lines[1].split()
    body = lines[1:] if header[1:] else lines[2:]
    try:
        n_vertices, n_faces = int(rest[0]), int(rest[1])
    except (IndexError, ValueError):
        raise _Bad("expected the counts 'vertices faces edges' after the header") from None
    if len(body) < n_vertices + n_faces:
        raise _Bad(f"expected {n_vertices} vertex and {n_faces} face lines, the file ends after {len(body)}")
    rows = [line.split() for line in body[:n_vertices]]
    try:
        vertices = np.array([row[:3] for row in rows], np.float64).reshape(-1, 3)
        normals = np.array([row[3:6] for row in rows], np.float64).reshape(-1, 3) if with_normals else None
        polygons = []
        for line in body[n_vertices:n_vertices + n_faces]:
            fields = line.split()
            count = int(fields[0])
            polygons.append([int(v) for v in fields[1:1 + count]])
            if len(polygons[-1]) != count:
                raise _Bad(f"face {len(polygons) - 1}: expected {count} vertex indices, got {len(polygons[-1])}")
    except ValueError as error:
        raise _Bad(f"expected numbers ({error})") from None
    return vertices, fan(polygons), normals


def _read_obj(path: Path):
    """OBJ: 'v x y z' and 'f a b c ...' (a/t/n forms, negative indices from the end); every object and
    group of the file (an 'o' or 'g' line starts one) in file order, as one mesh or (split) one each."""
    vertices, polygons, objects = [], [], [[None, 0]]
    for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        try:
            if fields[0] == "v":
                vertices.append([float(c) for c in fields[1:4]])
                if len(vertices[-1]) != 3:
                    raise ValueError("a vertex needs 3 coordinates")
            elif fields[0] == "f":
                count = len(vertices)
                indices = [int(f.split("/")[0]) for f in fields[1:]]
                polygons.append([i - 1 if i > 0 else count + i for i in indices])
            elif fields[0] in ("o", "g"):
                objects.append([" ".join(fields[1:]) or None, len(polygons)])
        except ValueError as error:
            raise _Bad(f"line {number}: {error}") from None
    triangles = fan(polygons)
    # each object's polygons become its triangles: (polygon k's first triangle) = sum of sizes - 2 before it
    first = np.concatenate([[0], np.cumsum([len(p) - 2 for p in polygons])])
    bounds = [int(first[start]) for _, start in objects] + [len(triangles)]
    spans = [(name, bounds[k], bounds[k + 1]) for k, (name, _) in enumerate(objects)]
    return np.array(vertices, np.float64).reshape(-1, 3), triangles, None, spans


def _read_ply(path: Path):
    """PLY (ASCII, binary little- or big-endian) through plyfile: the vertex element's x, y, z (and
    nx, ny, nz), the face element's index lists of any list types and sizes, fanned here."""
    import plyfile

    with open(path, "rb") as handle:
        if handle.read(4).rstrip(b"\r\n") != b"ply":
            raise _Bad("not a PLY file: expected 'ply' on the first line")
        handle.seek(0)
        try:
            data = plyfile.PlyData.read(handle)
        except plyfile.PlyHeaderParseError as error:
            raise _Bad(f"not a PLY file: {_one_line(error)}") from None
        except (plyfile.PlyElementParseError, ValueError, EOFError, IndexError) as error:
            raise _Bad(f"not a readable PLY file ({_one_line(error)})") from None
    names = [element.name for element in data.elements]
    if "vertex" not in names:
        raise _Bad("expected a 'vertex' element")
    vertex = data["vertex"].data
    fields = vertex.dtype.names or ()
    if not all(k in fields for k in ("x", "y", "z")):
        raise _Bad(f"expected the vertex properties x, y, z, got {', '.join(fields) or 'none'}")
    vertices = np.stack([np.asarray(vertex[k], np.float64) for k in ("x", "y", "z")], axis=1)
    normals = None
    if all(k in fields for k in ("nx", "ny", "nz")):
        normals = np.stack([np.asarray(vertex[k], np.float64) for k in ("nx", "ny", "nz")], axis=1)
    face = data["face"].data if "face" in names else None
    key = next((k for k in ("vertex_indices", "vertex_index") if face is not None and k in (face.dtype.names or ())),
               None)
    if key is None:
        raise _Bad("expected a 'face' element with 'vertex_indices'")
    lists = face[key]
    sizes = np.fromiter(map(len, lists), np.int64, len(lists))
    flat = np.concatenate(lists).astype(np.int64) if len(lists) else np.zeros(0, np.int64)
    bad = (flat < 0) | (flat >= len(vertices))
    if bad.any():
        index = int(np.searchsorted(np.cumsum(sizes), int(np.argmax(bad)), side="right"))
        polygon = np.asarray(lists[index], np.int64).tolist()
        raise _Bad(f"face {index} is {polygon}: expected indices 0 .. {len(vertices) - 1} "
                   f"(the file has {len(vertices)} vertices)")
    return vertices, fan_flat(flat, sizes), normals


def _one_line(error) -> str:
    """An exception's message on one line (plyfile's name the line and column on a second one)."""
    return " ".join(str(error).split()) or type(error).__name__


def _read_trimesh(path: Path):
    """STL, glTF and GLB through trimesh (triangles only): a scene's meshes with their nodes'
    transforms applied, in the order of the file's nodes (a node's primitives together, one object
    named as its node), one after the other."""
    import trimesh

    suffix = path.suffix.lower()
    if suffix == ".glb":
        with open(path, "rb") as handle:
            if handle.read(4) != b"glTF":
                raise _Bad("not a GLB file: expected 'glTF' at its start")
    elif suffix == ".gltf" and not isinstance(_gltf_header(path), dict):
        raise _Bad("not a glTF file: expected a JSON object")
    loaded = trimesh.load(str(path), process=False, maintain_order=True)
    if isinstance(loaded, trimesh.Scene):
        parts = _scene_parts(loaded, path)
    else:
        parts = [(None, loaded, None)]
    parts = [(name, part, transform) for name, part, transform in parts if isinstance(part, trimesh.Trimesh)]
    if not parts:
        raise _Bad("the file holds no triangle mesh")
    vertices, faces, normals, spans, offset, start = [], [], [], [], 0, 0
    for name, part, transform in parts:
        points = np.asarray(part.vertices, np.float64)
        # the file's own vertex normals only (trimesh computes them when asked, into its cache)
        own = part._cache.cache.get("vertex_normals") if hasattr(part._cache, "cache") else None
        own = None if own is None else np.asarray(own, np.float64)
        if transform is not None:
            points = points @ transform[:3, :3].T + transform[:3, 3]
            if own is not None:  # normals turn with the inverse transpose
                own = own @ np.linalg.inv(transform[:3, :3])
                with np.errstate(invalid="ignore", divide="ignore"):
                    own = own / np.linalg.norm(own, axis=1, keepdims=True)
        vertices.append(points)
        faces.append(np.asarray(part.faces, np.int64) + offset)
        spans.append((name, start, start + len(part.faces)))
        offset += len(points)
        start += len(part.faces)
        normals.append(own)
    normals = None if any(n is None for n in normals) else np.concatenate(normals)
    return np.concatenate(vertices), np.concatenate(faces), normals, _merged(spans)


def _merged(spans):
    """Adjacent spans of one object (a node's primitives) as one."""
    out = []
    for name, start, stop in spans:
        if out and out[-1][0] == name and name is not None and out[-1][2] == start:
            out[-1] = (name, out[-1][1], stop)
        else:
            out.append((name, start, stop))
    return out


def _scene_parts(scene, path: Path):
    """(object name, mesh, world transform) of each of a trimesh Scene's geometry nodes, in the
    order of the glTF file's nodes: trimesh's graph keeps no order of its own. A node's name is the
    file's (its mesh's, else node<index>, where it has none); a primitive of a node of several is
    one of trimesh's child frames, ordered and named as its node."""
    graph = scene.graph
    header = _gltf_header(path) if path.suffix.lower() in (".gltf", ".glb") else None
    nodes = header.get("nodes") if isinstance(header, dict) else None
    nodes = nodes if isinstance(nodes, list) else None
    index = {}  # trimesh's node name -> the file's node index (trimesh's own naming, repeated)
    if nodes is not None:
        from trimesh.util import unique_name

        counts: dict = {}
        for i, node in enumerate(nodes):
            index[unique_name(node.get("name", str(i)), index, counts=counts)] = i
    parents = graph.transforms.parents
    parts = []
    for position, node in enumerate(graph.nodes_geometry):
        transform, geometry = graph[node]
        owner = node
        while owner not in index and owner in parents:  # a primitive's object: its node's
            owner = parents[owner]
        i = index.get(owner)
        if i is None:
            order, name = (len(index), position), node
        else:
            order = (i, position)
            own = nodes[i]
            name = own.get("name") or _gltf_mesh_name(header, own) or f"node{i}"
        parts.append((order, name, scene.geometry[geometry], np.asarray(transform, np.float64)))
    parts.sort(key=lambda part: part[0])
    return [(name, mesh, transform) for _, name, mesh, transform in parts]


def _gltf_header(path: Path):
    """A glTF file's JSON (a .gltf's text, a .glb's first chunk), or None."""
    import json
    import struct

    try:
        raw = path.read_bytes()
        if raw[:4] == b"glTF":
            length, kind = struct.unpack("<II", raw[12:20])
            return json.loads(raw[20:20 + length]) if kind == 0x4E4F534A else None
        return json.loads(raw)
    except (ValueError, struct.error, OSError):
        return None


def _gltf_mesh_name(header, node) -> str | None:
    try:
        return header["meshes"][node["mesh"]].get("name")
    except (KeyError, IndexError, TypeError):
        return None


_READERS = {".off": _read_off, ".obj": _read_obj, ".ply": _read_ply, ".stl": _read_trimesh,
            ".gltf": _read_trimesh, ".glb": _read_trimesh}
