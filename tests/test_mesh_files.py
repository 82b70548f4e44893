"""Mesh files and bad input: every format (written here by hand or with trimesh's exporters) keeps
the file's vertex and face order, fans polygons (0, i, i + 1) in place and makes a multi-object file
one mesh; every bad key and file of the contract is a SceneError naming the shape and the key, and
on the command line one line, exit status 2, no output file."""
import subprocess
import sys

import numpy as np
import pytest

import pyclray
from pyclray.model.shapes.mesh_shapes import torus

QUAD_VERTICES = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0.5, 0], [0.5, 0.5, 1]], np.float64)
# a quad, a triangle, a pentagon: fanned (0, i, i + 1) in place
POLYGONS = [[0, 1, 2, 3], [1, 4, 2], [0, 1, 4, 2, 5]]
FANNED = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 2], [0, 1, 4], [0, 4, 2], [0, 2, 5]])


def write_off(path, vertices, polygons):
    lines = ["OFF", f"{len(vertices)} {len(polygons)} 0"] + [" ".join(map(repr, map(float, v))) for v in vertices]
    lines += [" ".join(map(str, [len(p), *p])) for p in polygons]
    path.write_text("\n".join(lines) + "\n")


def write_obj(path, vertices, polygons, split=None):
    lines = ["# two objects", "o first"]
    for k, v in enumerate(vertices):
        lines.append("v " + " ".join(map(repr, map(float, v))))
    for k, p in enumerate(polygons):
        if split is not None and k == split:
            lines.append("o second")
        lines.append("f " + " ".join(f"{i + 1}//{i + 1}" for i in p))
    path.write_text("\n".join(lines) + "\n")


def write_ply_ascii(path, vertices, polygons):
    lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}", "property float x", "property float y",
             "property float z", f"element face {len(polygons)}", "property list uchar int vertex_indices", "end_header"]
    lines += [" ".join(map(repr, map(float, v))) for v in vertices]
    lines += [" ".join(map(str, [len(p), *p])) for p in polygons]
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("writer,suffix", [(write_off, ".off"), (write_obj, ".obj"), (write_ply_ascii, ".ply")])
def test_polygons_are_fanned_in_place(tmp_path, writer, suffix):
    path = tmp_path / f"polygons{suffix}"
    writer(path, QUAD_VERTICES, POLYGONS)
    mesh = pyclray.Mesh.load(path)
    assert np.array_equal(mesh.faces, FANNED)
    assert np.allclose(mesh.vertices, QUAD_VERTICES)


def test_obj_objects_are_one_mesh_in_file_order(tmp_path):
    path = tmp_path / "two.obj"
    write_obj(path, QUAD_VERTICES, POLYGONS, split=1)
    assert np.array_equal(pyclray.Mesh.load(path).faces, FANNED)


@pytest.mark.parametrize("suffix", [".stl", ".ply", ".glb", ".gltf", ".obj", ".off"])
def test_every_format_renders_the_same_torus(tmp_path, suffix):
    """The torus exported by trimesh to each format renders the same ids and, up to the float32
    rounding some formats store vertices in, the same depths as the arrays themselves; formats that
    keep indices keep the face order (the primitive images are equal)."""
    import trimesh

    vertices, faces = torus(16, 10)
    path = tmp_path / f"torus{suffix}"
    trimesh.Trimesh(vertices, faces, process=False).export(path)
    loaded = pyclray.Mesh.load(path)
    direct = pyclray.Mesh(loaded.vertices, loaded.faces)  # the file's own vertices
    scene = pyclray.Scene(pyclray.Camera((0, 2, 3), (0, 0, 0)), pyclray.Image(48, 32), (loaded,))
    a = pyclray.render(scene, aovs=("depth", "id", "primitive"))
    b = pyclray.render(pyclray.Scene(scene.camera, scene.image, (direct,)), aovs=("depth", "id", "primitive"))
    assert np.array_equal(a["depth"], b["depth"])
    assert np.abs(loaded.world_vertices() - vertices[: len(loaded.vertices)] if suffix != ".stl" else 0).max() < 1e-6
    if suffix != ".stl":  # STL has no indices: trimesh's reader keeps the triangle order only
        assert np.array_equal(loaded.faces, faces)
    assert len(loaded.faces) == len(faces)


def test_the_committed_bunny(scenes_dir):
    mesh = pyclray.load_scene(scenes_dir / "mesh.toml").shapes[1]
    assert isinstance(mesh, pyclray.Mesh) and len(mesh.faces) == 5000 and len(mesh.vertices) == 2502


def test_a_file_is_read_once(tmp_path):
    path = tmp_path / "t.off"
    write_off(path, QUAD_VERTICES, POLYGONS)
    a, b = pyclray.Mesh.load(path), pyclray.Mesh.load(path).placed(translate=(1, 0, 0))
    assert a.vertices is b.vertices and a.faces is b.faces


BASE = """[camera]
eye = [0.0, 1.0, 4.0]
target = [0.0, 0.0, 0.0]
fov = 40.0
[image]
width = 16
height = 16
[[shapes]]
type = "mesh"
name = "thing"
"""
INLINE = 'vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]\nfaces = [[0, 1, 2]]\n'


@pytest.mark.parametrize("table,key,message", [
    ('file = "missing.ply"\n', "file", "cannot read missing.ply"),
    ('file = "empty.off"\n', "file", "expected an OFF header"),
    ('file = "notriangles.off"\n', "file", "holds no triangles"),
    ('file = "garbage.ply"\n', "file", "not a PLY file"),
    ('file = "thing.xyz"\n', "file", "expected a mesh file"),
    ('file = "folder.obj"\n', "file", "is a folder"),
    ('file = "tri.off"\n' + INLINE, "file", "not both"),
    ('vertices = [[0.0, 0.0, 0.0]]\n', "faces", "expected 'file'"),
    ('vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]\nfaces = [[0, 1, 3]]\n', "faces", "expected indices 0 .. 2"),
    ('vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, nan], [0.0, 1.0, 0.0]]\nfaces = [[0, 1, 2]]\n', "vertices", "finite"),
    ('vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]\nfaces = []\n', "faces", "at least one triangle"),
    ('vertices = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]\nfaces = [[0, 1, 2]]\n', "vertices", "shape (V, 3)"),
    (INLINE + 'matrix = [[1,0,0,0],[0,1,0,0],[0,0,0,0],[0,0,0,1]]\n', "matrix", "singular"),
    (INLINE + 'matrix = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]]\n', "matrix", "affine"),
    (INLINE + 'matrix = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\nscale = 2.0\n', "matrix", "not both"),
    (INLINE + 'scale = [1.0, 0.0, 1.0]\n', "scale", "non-zero"),
    (INLINE + 'axis = [0.0, 0.0, 0.0]\nangle = 10.0\n', "axis", "non-zero"),
    (INLINE + 'smooth = 1\n', "smooth", "true or false"),
    (INLINE + 'colour = [1.0, 0.0, 0.0]\n', "colour", "unknown key"),
])
def test_bad_input_names_the_shape_and_key(tmp_path, table, key, message):
    (tmp_path / "empty.off").write_text("")
    (tmp_path / "notriangles.off").write_text("OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n")
    (tmp_path / "garbage.ply").write_bytes(b"\x00\x01 not a ply")
    (tmp_path / "thing.xyz").write_text("")
    (tmp_path / "folder.obj").mkdir()
    write_off(tmp_path / "tri.off", QUAD_VERTICES, POLYGONS)
    path = tmp_path / "scene.toml"
    path.write_text(BASE + table)
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.load_scene(path)
    text = str(error.value)
    assert error.value.key == key and "mesh" in text and message in text, text


def test_cli_bad_mesh_is_one_line_exit_2(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(BASE + 'file = "missing.obj"\n')
    out = tmp_path / "out.exr"
    run = subprocess.run([sys.executable, "-m", "pyclray", "render", str(path), "-o", str(out)],
                         capture_output=True, text=True)
    assert run.returncode == 2
    assert len(run.stderr.strip().splitlines()) == 1 and "key 'file'" in run.stderr and "missing.obj" in run.stderr
    assert not out.exists()


def write_ply_binary(path, vertices, polygons, order, count_type="u1", index_type="i4", extra=False):
    """A binary PLY (order '<' or '>') whose faces mix polygon sizes, written byte by byte here (not
    with plyfile, the reader under test): count_type and index_type are the list's numpy types."""
    names = {"u1": "uchar", "i1": "char", "u2": "ushort", "i2": "short", "u4": "uint", "i4": "int"}
    endian = "binary_little_endian" if order == "<" else "binary_big_endian"
    header = ["ply", f"format {endian} 1.0", "comment mixed polygons", f"element vertex {len(vertices)}",
              "property double x", "property double y", "property double z"]
    if extra:
        header += ["property uchar red"]
    header += [f"element face {len(polygons)}",
               f"property list {names[count_type]} {names[index_type]} vertex_indices"]
    if extra:
        header += ["property list uchar float texcoord"]
    header += ["end_header"]
    body = bytearray()
    for v in vertices:
        body += np.asarray(v, order + "f8").tobytes()
        if extra:
            body += b"\x07"
    for p in polygons:
        body += np.asarray(len(p), order + count_type).tobytes() + np.asarray(p, order + index_type).tobytes()
        if extra:
            body += np.asarray(2, "u1").tobytes() + np.asarray([0.5, 0.25], order + "f4").tobytes()
    path.write_bytes(("\n".join(header) + "\n").encode() + bytes(body))


@pytest.mark.parametrize("order", ["<", ">"])
@pytest.mark.parametrize("count_type,index_type,extra", [
    ("u1", "i4", False), ("u1", "u4", True), ("u2", "i2", False), ("i1", "u2", True), ("u4", "i4", False)])
def test_binary_ply_with_mixed_polygons_reads_and_fans(tmp_path, order, count_type, index_type, extra):
    """Issue 42 item 3: quads, triangles and a pentagon in one binary file (either byte order, any
    list types, other properties beside the lists) are read and fanned as OBJ and OFF are."""
    path = tmp_path / "mixed.ply"
    write_ply_binary(path, QUAD_VERTICES, POLYGONS, order, count_type, index_type, extra)
    mesh = pyclray.Mesh.load(path)
    assert np.array_equal(mesh.faces, FANNED)
    assert np.array_equal(mesh.vertices, QUAD_VERTICES)  # doubles kept to the bit


def test_binary_ply_of_triangles_only_and_vertex_normals(tmp_path):
    path = tmp_path / "tri.ply"
    header = ("ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              "property float z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face 1\n"
              "property list uchar uint vertex_index\nend_header\n")
    rows = np.array([[0, 0, 0, 0, 0, 1], [1, 0, 0, 0, 0, 1], [0, 1, 0, 0, 0, 1]], ">f4")
    path.write_bytes(header.encode() + rows.tobytes() + b"\x03" + np.array([0, 1, 2], ">u4").tobytes())
    mesh = pyclray.Mesh.load(path)
    assert np.array_equal(mesh.faces, [[0, 1, 2]]) and np.array_equal(mesh.normals, rows[:, 3:])


@pytest.mark.parametrize("contents,message", [
    (b"this is a text file, not a mesh\n", "not a PLY file: expected 'ply' on the first line"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
     b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n",
     "not a readable PLY file"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nend_header\n0 0\n1 0\n0 1\n",
     "expected the vertex properties x, y, z"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
     b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
     "face 0 is [0, 1, 7]"),
])
def test_a_bad_ply_is_one_clear_line(tmp_path, contents, message):
    """Issue 42 item 7: a text file named .ply says what is wrong in one line (not 'list index out
    of range')."""
    path = tmp_path / "bad.ply"
    path.write_bytes(contents)
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.Mesh.load(path)
    text = str(error.value)
    assert message in text and "\n" not in text and "index out of range" not in text, text


@pytest.mark.parametrize("suffix,message", [
    (".ply", "not a PLY file"), (".off", "expected an OFF header"), (".obj", "holds no triangles"),
    (".stl", "holds no triangle mesh"), (".glb", "not a GLB file"), (".gltf", "not a glTF file")])
def test_a_text_file_of_any_mesh_suffix_is_one_clear_line(tmp_path, suffix, message):
    path = tmp_path / f"notes{suffix}"
    path.write_text("this is a text file, not a mesh\n")
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.Mesh.load(path)
    text = str(error.value)
    assert message in text and f"notes{suffix}" in text and "\n" not in text, text
