"""Issue 42 item 4: a file of several objects (OBJ `o`/`g` groups, glTF/GLB nodes) read with
`split = true` (TOML) or `Mesh.load(path, split=True)` is one shape per object, in the file's
order: each its own name (the object's, made unique, after the table's name where it has one) and
id, with its node's transform applied, so that instance masks separate them; the table's other keys
(placement, label, colour, smooth) apply to every object alike. Without split the file stays one
mesh, the objects' triangles in the same order."""
import numpy as np
import pytest

import pyclray

# three objects: a quad 'floor' (fanned), a triangle in an unnamed-then-named group, and a second
# 'floor' (a duplicate name); vertices are shared across objects the way OBJ numbers them
OBJ = """# several objects
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 1
v 3 0 1
v 2 1 1
o floor
f 1 2 3 4
g roof part
f 5 6 7
o floor
f 2 6 3
"""


def write(path, text):
    path.write_text(text)
    return path


def test_obj_objects_split_in_file_order_with_unique_names(tmp_path):
    path = write(tmp_path / "things.obj", OBJ)
    whole = pyclray.Mesh.load(path)
    parts = pyclray.Mesh.load(path, split=True, smooth=True, label=3)
    assert isinstance(parts, tuple) and [p.name for p in parts] == ["floor", "roof part", "floor_2"]
    assert all(isinstance(p, pyclray.Mesh) and p.smooth and p.label == 3 for p in parts)
    # each object keeps its own vertices only, in the file's order, and its faces fanned in place
    assert np.array_equal(parts[0].vertices, whole.vertices[:4]) and np.array_equal(parts[0].faces, [[0, 1, 2], [0, 2, 3]])
    assert np.array_equal(parts[1].vertices, whole.vertices[4:]) and np.array_equal(parts[1].faces, [[0, 1, 2]])
    assert np.array_equal(parts[2].vertices, whole.vertices[[1, 2, 5]]) and np.array_equal(parts[2].faces, [[0, 2, 1]])
    # the same triangles as the one mesh, in the same order
    triangles = np.concatenate([p.world_vertices()[p.faces] for p in parts])
    assert np.array_equal(triangles, whole.world_vertices()[whole.faces])


def glb_of_three_nodes(path):
    import trimesh

    scene = trimesh.Scene()
    box = trimesh.creation.box()
    ball = trimesh.creation.icosphere(1)
    scene.add_geometry(box, node_name="body", transform=trimesh.transformations.translation_matrix([2.0, 0.0, 0.0]))
    scene.add_geometry(ball, node_name="wheel", transform=trimesh.transformations.scale_matrix(0.5))
    turned = trimesh.transformations.rotation_matrix(np.pi / 3, [0, 0, 1])
    turned[:3, 3] = (0.0, 3.0, 0.0)
    scene.add_geometry(ball, node_name="wheel.b", transform=turned)
    scene.export(path)
    return {"body": (box, trimesh.transformations.translation_matrix([2.0, 0.0, 0.0])),
            "wheel": (ball, trimesh.transformations.scale_matrix(0.5)), "wheel.b": (ball, turned)}


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_gltf_nodes_split_with_their_transforms(tmp_path, suffix):
    path = tmp_path / f"car{suffix}"
    made = glb_of_three_nodes(path)
    parts = pyclray.Mesh.load(path, split=True, name="car")
    assert [p.name for p in parts] == ["car.body", "car.wheel", "car.wheel.b"]  # the nodes' order in the file
    for part, (name, (geometry, transform)) in zip(parts, made.items()):
        expected = geometry.vertices @ transform[:3, :3].T + transform[:3, 3]
        assert np.allclose(part.world_vertices(), expected, atol=1e-6), name  # (float32 in the file)
        assert np.array_equal(part.faces, geometry.faces), name
    whole = pyclray.Mesh.load(path)  # one mesh: the same triangles, objects in the same order
    triangles = np.concatenate([p.world_vertices()[p.faces] for p in parts])
    assert np.array_equal(triangles, whole.world_vertices()[whole.faces])


SCENE = """[camera]
eye = [0.0, 1.0, 9.0]
target = [1.0, 1.0, 0.0]
[image]
width = 48
height = 32
[[shapes]]
type = "sphere"
center = [-3.0, 1.0, 0.0]
radius = 0.5
[[shapes]]
type = "mesh"
file = "car.glb"
split = true
{name}translate = [0.0, 0.0, -1.0]
label = 7
color = [0.2, 0.4, 0.6]
[[shapes]]
type = "sphere"
name = "after"
center = [5.0, 1.0, 0.0]
radius = 0.5
"""


def test_a_split_table_is_several_shapes_with_their_ids(tmp_path):
    made = glb_of_three_nodes(tmp_path / "car.glb")
    scene = pyclray.load_scene(write(tmp_path / "s.toml", SCENE.format(name='name = "car"\n')))
    assert [s.name for s in scene.shapes] == ["sphere0", "car.body", "car.wheel", "car.wheel.b", "after"]
    parts = scene.shapes[1:4]
    assert all(p.label == 7 and p.material.color == (0.2, 0.4, 0.6) and p.translate == (0.0, 0.0, -1.0) for p in parts)
    _, transform = made["wheel.b"]
    assert np.allclose(parts[2].world_vertices(), made["wheel.b"][0].vertices @ transform[:3, :3].T + transform[:3, 3]
                       + (0.0, 0.0, -1.0), atol=1e-6)
    frame = pyclray.render(scene, aovs=("id", "label"))
    ids = set(np.unique(frame["id"]).tolist())
    assert {1, 2, 3} <= ids and ids <= {-1, 0, 1, 2, 3, 4}  # every object its own id (the far sphere off screen)
    assert set(np.unique(frame["label"][(frame["id"] >= 1) & (frame["id"] <= 3)]).tolist()) == {7}
    # without a name the objects' own names
    plain = pyclray.load_scene(write(tmp_path / "p.toml", SCENE.format(name="")))
    assert [s.name for s in plain.shapes[1:4]] == ["body", "wheel", "wheel.b"]


@pytest.mark.parametrize("change,key,message", [
    (('split = true', 'split = "yes"'), "split", "expected true or false"),
    (('file = "car.glb"', 'vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]\nfaces = [[0, 1, 2]]'),
     "split", "expected 'file'"),
    (('name = "after"', 'name = "car.wheel"'), "name", "already used by [[shapes]] #1"),
])
def test_bad_split_tables_name_the_table_and_key(tmp_path, change, key, message):
    glb_of_three_nodes(tmp_path / "car.glb")
    path = write(tmp_path / "s.toml", SCENE.format(name='name = "car"\n').replace(*change))
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.load_scene(path)
    text = str(error.value)
    assert error.value.key == key and message in text, text
    table = "#2 (sphere)" if key == "name" else "#1 (mesh)"
    assert f"[[shapes]] {table}" in text, text


def test_a_render_error_after_a_split_names_the_files_table(tmp_path):
    """The range check names the table of the file (#2), not the shape's position (#4)."""
    glb_of_three_nodes(tmp_path / "car.glb")
    text = SCENE.format(name="").replace("center = [5.0, 1.0, 0.0]\nradius = 0.5", "center = [5.0, 1.0, 0.0]\nradius = 1e30")
    scene = pyclray.load_scene(write(tmp_path / "s.toml", text))
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.render(scene)
    assert "table [[shapes]] #2 (sphere)" in str(error.value), str(error.value)


def test_a_single_object_file_splits_into_one_shape_named_by_the_file(tmp_path):
    path = write(tmp_path / "tri.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    (part,) = pyclray.Mesh.load(path, split=True)
    assert part.name == "tri" and np.array_equal(part.faces, [[0, 1, 2]])


@pytest.mark.parametrize("split", [False, True])
def test_an_obj_face_past_the_vertices_is_one_line_naming_the_file(tmp_path, split):
    path = write(tmp_path / "bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\no a\nf 1 2 3\no b\nf 1 2 9\n")
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.Mesh.load(path, split=split)
    text = str(error.value)
    assert error.value.key == "file" and "bad.obj" in text and "[0, 1, 8]" in text and "0 .. 2" in text, text


def test_a_gltf_node_of_several_primitives_is_one_object_and_unnamed_nodes_get_names(tmp_path):
    """A node's primitives together (one object), nodes in the file's order (a child before a later
    root), an unnamed node of an unnamed mesh named node<index>; the transforms of its parents applied."""
    import base64
    import json

    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    blob = positions.tobytes() + np.array([0, 1, 2], np.uint16).tobytes() + b"\0\0"
    primitive = {"attributes": {"POSITION": 0}, "indices": 1}
    gltf = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
        "meshes": [{"name": "two parts", "primitives": [primitive, primitive]}, {"primitives": [primitive]}],
        "nodes": [{"mesh": 1, "translation": [5, 0, 0]}, {"name": "car", "mesh": 0, "translation": [0, 2, 0]},
                  {"name": "root", "children": [0], "translation": [0, 0, 1]}],
        "scenes": [{"nodes": [1, 2]}], "scene": 0,
    }
    path = write(tmp_path / "parts.gltf", json.dumps(gltf))
    first, car = pyclray.Mesh.load(path, split=True)
    assert (first.name, car.name) == ("node0", "car")
    assert np.array_equal(first.world_vertices(), positions + (5, 0, 1))
    assert len(car.faces) == 2 and np.array_equal(car.world_vertices()[car.faces[1]], positions + (0, 2, 0))
