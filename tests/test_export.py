"""pyclray export: a pyclray scene as a Mitsuba 3 XML scene (pyclray.reference.mitsuba_export).

The XML is the check's own Mitsuba description (mitsuba.mitsuba_dict) written as text, so Mitsuba
loading the file and Mitsuba loading the check's dict see the very same scene: their primary rays and
intersections agree bit for bit. A round trip XML -> pyclray -> XML renders the same AOVs in Mitsuba
as the first file, within the error model's bounds for two float32 renders of one scene.
"""
import os
import re
import subprocess
import sys

import numpy as np
import pytest

import pyclray
from pyclray.apps import cli
from pyclray.reference import error_model, mitsuba, oracle
from pyclray.reference.error_model import angle_between
from pyclray.reference.mitsuba_export import export_dict, scene_xml

from conftest import SCENES
from test_mitsuba_xml import EXAMPLES, mitsuba_intersect

SIZE = (40, 30)


def pixel_hits(mi_scene, scene, intersect=mitsuba_intersect):
    """Mitsuba's primary ray of every pixel centre of the scene's image, intersected: (origins,
    directions, t, normal, the shape hit), each (height * width, ...)."""
    height, width = scene.image.height, scene.image.width
    rows, columns = (a.ravel() for a in np.meshgrid(np.arange(height), np.arange(width), indexing="ij"))
    origins, directions = mitsuba.primary_rays(mi_scene, scene, rows, columns)
    return (origins, directions, *intersect(mi_scene, scene, origins, directions))


def pixel_depths(mi_scene, scene, intersect=mitsuba_intersect):
    """Mitsuba's distance from the eye at every pixel centre (inf on a miss), its normals and the
    shape hit (pixel_hits' answers, the depth measured from the eye as pyclray's)."""
    origins, directions, t, normal, found = pixel_hits(mi_scene, scene, intersect)
    points = origins + np.where(found >= 0, t, 0)[:, None] * directions
    return np.where(found >= 0, np.linalg.norm(points - np.array(scene.camera.eye), axis=1), np.inf), normal, found


def camera_reference(scene, answers):
    """The float64 oracle's answers at the scene's pixel centres (truth), the error model's depth and
    normal bounds for a Mitsuba render of them, and the pixels apart: at a silhouette or an edge,
    where the oracle's and each of answers' (id, depth) images may rightly differ."""
    eye = np.array(scene.camera.eye)
    _, unit = oracle.camera_rays(scene)
    unit = unit.reshape(-1, 3)
    truth = oracle.trace(scene, np.broadcast_to(eye, unit.shape), unit, aovs=("depth", "normal", "id"))
    cos = oracle.incidence_cosine(scene, unit, truth["id"], truth["normal"])
    bound, normal_bound = error_model.mitsuba_tolerances(scene, truth["depth"], truth["id"], cos, cameras=True)
    radius = error_model.curvature_radii(scene)[np.maximum(truth["id"], 0)]
    apart = error_model.silhouettes(truth["id"], cos, bound, radius) | error_model.at_edges(
        scene, np.broadcast_to(eye, unit.shape), unit, [(truth["id"], truth["depth"]), *answers], 2 * bound * cos)
    return truth, bound, normal_bound, apart


def by_key(keys):
    """An intersect giving each hit's (pyclray id, part) through its Mitsuba id: keys(index, part)."""
    def intersect(mi_scene, scene, origins, directions):
        import mitsuba as mi

        parts = {keys(index, part): 1000 * index + part for index, shape in enumerate(scene.shapes)
                 for part in range(len(shape.mitsuba_shapes(scene)))}
        t, normal, found = np.full(len(origins), np.inf), np.zeros((len(origins), 3)), np.full(len(origins), -1)
        for k, (o, d) in enumerate(zip(origins, directions)):
            si = mi_scene.ray_intersect(mi.Ray3f(mi.Point3f(*o), mi.Vector3f(*d)))
            if si.is_valid():
                t[k], normal[k], found[k] = si.t, tuple(si.n), parts[si.shape.id()]
        return t, normal, found

    return intersect


@pytest.mark.parametrize("name", ["tp02-lit.toml", "shapes-lit.toml", "intrinsics.toml", "sun.toml"])
def test_the_file_is_the_checks_scene_bit_for_bit(name, tmp_path):
    """Mitsuba's scene from the written file and from the check's dict (scene_dict): the same
    camera rays and the same hits, bit for bit; pyclray reads the file back with the same camera
    and lights (the headlight written as a directional light) and every shape's colour."""
    scene = pyclray.load_scene(SCENES / name)
    scene = scene.with_size(*SIZE) if scene.camera.K is None else scene.with_size(SIZE[0], round(SIZE[0] * scene.image.height / scene.image.width))
    path = tmp_path / "scene.xml"
    assert cli.main(["export", str(SCENES / name), "-o", str(path), "--size", f"{scene.image.width}x{scene.image.height}"]) == 0
    mi = mitsuba.import_mitsuba("scalar_rgb")
    from_file = mi.load_file(str(path), optimize=False)
    from_dict = mitsuba.load_dict(mi, mitsuba.scene_dict(scene, "scalar_rgb"))
    assert len(from_file.shapes()) == len(from_dict.shapes())
    read = pyclray.load_scene(path)
    from pyclray.reference.mitsuba_export import shape_keys

    for ours, theirs in zip(pixel_hits(from_file, scene, by_key(shape_keys(scene))),
                            pixel_hits(from_dict, scene, by_key(mitsuba.shape_key))):
        assert np.array_equal(ours, theirs)
    if scene.camera.K is None:
        assert (read.camera.eye, read.camera.target, read.camera.up, read.camera.fov) == (
            scene.camera.eye, scene.camera.target, scene.camera.up, scene.camera.fov)
    else:
        assert np.allclose(read.camera.intrinsics(*SIZE[:1], read.image.height), scene.camera.intrinsics(*SIZE[:1], scene.image.height))
        assert np.allclose(read.camera.pose(), scene.camera.pose(), atol=1e-12)
    lights = [(light.type, getattr(light, "position", None) or light.direction) for light in read.lights]
    from pyclray.model.lights import effective_lights
    assert lights == [(light.type, getattr(light, "position", None) or light.direction) for light in effective_lights(scene)]
    colours = {shape.name: shape.material.color for shape in scene.shapes}
    assert all(shape.material.color == colours[shape.name.split("_")[0]] for shape in read.shapes if shape.name.split("_")[0] in colours)


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_round_trip_xml_pyclray_xml_renders_the_same_aovs_in_mitsuba(path, tmp_path):
    """Mitsuba's own file and pyclray's export of what it read from it: the same shape at every
    pixel (silhouettes and edges aside), depths from the eye within twice the error model's image
    bound (two float32 renders), the same normals."""
    scene = pyclray.load_scene(path).with_size(*SIZE)
    first = tmp_path / "first.xml"  # the file at SIZE (its film's width and height), its meshes beside it
    text = re.sub(r'name="width" value="[^"]*"', f'name="width" value="{SIZE[0]}"', path.read_text())
    first.write_text(re.sub(r'name="height" value="[^"]*"', f'name="height" value="{SIZE[1]}"', text))
    (tmp_path / "meshes").symlink_to(SCENES / "meshes")
    again = tmp_path / "again.xml"
    assert cli.main(["export", str(first), "-o", str(again)]) == 0
    mi = mitsuba.import_mitsuba("scalar_rgb")
    eye = np.array(scene.camera.eye)
    (depth_a, normal_a, id_a), (depth_b, normal_b, id_b) = (
        pixel_depths(mi.load_file(str(file), optimize=False), scene) for file in (first, again))
    truth, bound, normal_bound, apart = camera_reference(scene, [(id_a, depth_a), (id_b, depth_b)])
    assert (id_a[~apart] == id_b[~apart]).all(), np.c_[id_a, id_b, truth["id"], np.arange(len(id_a))][~apart & (id_a != id_b)][:8]
    same = ~apart & (id_a >= 0) & (id_a == id_b)
    assert same.sum() > 100
    assert (np.abs(depth_a[same] - depth_b[same]) <= 2 * bound[same]).all()
    L = error_model.world_sizes(scene, eye)[id_a[same]]
    edge = np.array([np.sort(np.ptp(shape.box(), axis=0))[1] for shape in scene.shapes])[id_a[same]]
    assert (angle_between(normal_a[same], normal_b[same]) <= 2 * normal_bound[same]
            + 2 * error_model.K_MITSUBA * error_model.EPSILON["fp32"] * L / edge).all()


def test_export_names_shapes_and_parts_and_needs_no_mitsuba(tmp_path):
    """A capped cylinder is three Mitsuba shapes (its name, name_1, name_2); scenes built in Python
    with repeated names get their index; a mesh is a ply shape of a PLY file beside the XML (its
    world vertices in float64, its faces in order); the writer runs with Mitsuba unimportable."""
    scene = pyclray.Scene(pyclray.Camera((0, 1, 5), (0, 0, 0)), pyclray.Image(16, 12),
                          (pyclray.Cylinder((0, 0, 0), (0, 1, 0), 0.5), pyclray.Sphere((1, 0, 0), 0.5)))
    keys = [k for k in export_dict(scene) if k.startswith("cylinder") or k.startswith("sphere")]
    assert keys == ["cylinder", "cylinder_1", "cylinder_2", "sphere"]
    twice = pyclray.Scene(scene.camera, scene.image, (pyclray.Sphere((0, 0, 0), 1.0), pyclray.Sphere((2, 0, 0), 1.0)))
    assert [k for k in export_dict(twice) if k.startswith("sphere")] == ["sphere_0", "sphere_1"]
    assert "<shape type=\"sphere\" id=\"sphere_1\">" in scene_xml(twice)
    code = ("import sys; sys.modules['mitsuba'] = None; sys.modules['drjit'] = None\n"
            "from pyclray.apps.cli import main; sys.exit(main())")
    result = subprocess.run([sys.executable, "-c", code, "export", str(SCENES / "shapes.toml"), "-o", str(tmp_path / "s.xml")],
                            capture_output=True, text=True, env=dict(os.environ))
    assert result.returncode == 0, result.stderr
    text = (tmp_path / "s.xml").read_text()
    assert text.count("<shape ") == 15  # 10 shapes: a cylinder's 2 caps, 5 pebbles, a mesh
    assert '<shape type="ply" id="pyramid">' in text and '<string name="filename" value="s.pyramid.ply"/>' in text
    vertices, faces, _ = __import__("pyclray.model.shapes.mesh_io", fromlist=["read_mesh"]).read_mesh(tmp_path / "s.pyramid.ply")
    pyramid = next(shape for shape in pyclray.load_scene(SCENES / "shapes.toml").shapes if shape.name == "pyramid")
    assert np.array_equal(vertices, pyramid.world_vertices()) and np.array_equal(faces, pyramid.faces)


@pytest.mark.parametrize(
    "arguments, words",
    [
        (["-o", "OUT/s.obj"], ["-o", "expected OUT.xml"]),
        (["-o", "OUT/missing/s.xml"], ["does not exist"]),
        (["-o", "SCENE"], ["the scene file itself"]),
        (["-o", "OUT/s.xml", "--size", "0x3"], ["--size"]),
    ],
)
def test_bad_input_is_one_line_and_exit_2(arguments, words, tmp_path, capsys):
    scene = tmp_path / "scene.xml"
    scene.write_text((SCENES / "mitsuba-shapes.xml").read_text())
    arguments = [a.replace("OUT", str(tmp_path)) if a != "SCENE" else str(scene) for a in arguments]
    with pytest.raises(SystemExit) if "--size" in arguments else _nothing():
        status = cli.main(["export", str(scene), *arguments])
        assert status == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and all(word in err for word in words), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.xml"]


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_a_camera_mitsuba_cannot_show_is_bad_input(tmp_path, capsys):
    """fx != fy: Mitsuba's pixels are square; one line, exit 2, nothing written."""
    K = [[500.0, 0.0, 20.0], [0.0, 400.0, 15.0], [0.0, 0.0, 1.0]]
    text = (f"[camera]\nintrinsics = {K}\npose = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n[image]\nwidth = 40\n"
            "height = 30\n[[shapes]]\ntype = \"sphere\"\ncenter = [0, 0, 5]\nradius = 1\n")
    (tmp_path / "k.toml").write_text(text)
    assert cli.main(["export", str(tmp_path / "k.toml"), "-o", str(tmp_path / "k.xml")]) == 2
    assert "square pixels" in capsys.readouterr().err
    assert not (tmp_path / "k.xml").exists()
