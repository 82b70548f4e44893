"""Mitsuba 3 XML scenes read by pyclray (pyclray.model.mitsuba_xml; scene-format.md, "Mitsuba scenes").

What pyclray reads is checked against what Mitsuba itself reads from the same file: Mitsuba's own
primary rays (its sensor, as it parsed the file) against pyclray's camera, and the very same rays cast
through both (pyclray.cast and Mitsuba's ray_intersect), held to the error model's bounds. The files
are Mitsuba's example scenes (tests/data/mitsuba, from mitsuba-data) and scenes/mitsuba-shapes.xml,
written in Mitsuba's documented syntax with every plugin pyclray reads.
"""
import math

import numpy as np
import pytest

import pyclray
from pyclray.apps import cli
from pyclray.reference import error_model, mitsuba, oracle
from pyclray.reference.error_model import angle_between

from conftest import REPO, SCENES

EXAMPLES = sorted((REPO / "tests/data/mitsuba").glob("*.xml")) + [SCENES / "mitsuba-shapes.xml", SCENES / "mitsuba-meshes.xml"]


def mitsuba_intersect(mi_scene, scene, origins, directions):
    """Mitsuba's ray_intersect (scalar variant) of each ray: t (inf on a miss), geometric normal, and
    the pyclray id of the shape hit (-1 on a miss): Mitsuba's shapes are in an order of its own (its
    meshes last), so each is matched by its id (pyclray's name) or else by its bounding box's centre."""
    import mitsuba as mi

    centres = np.array([shape.box().mean(axis=0) for shape in scene.shapes])
    names = [shape.name for shape in scene.shapes]
    position = {}
    for shape in mi_scene.shapes():
        box = shape.bbox()
        centre = (np.array(box.min, np.float64) + np.array(box.max, np.float64)) / 2
        position[id(shape)] = names.index(shape.id()) if shape.id() in names else int(
            np.argmin(np.linalg.norm(centres - centre, axis=1)))
    t, normal, found = np.full(len(origins), np.inf), np.zeros((len(origins), 3)), np.full(len(origins), -1)
    for k, (o, d) in enumerate(zip(origins, directions)):
        si = mi_scene.ray_intersect(mi.Ray3f(mi.Point3f(*o), mi.Vector3f(*d)))
        if si.is_valid():
            hit = si.instance if si.instance is not None else si.shape  # an instance's meshes are its
            t[k], normal[k], found[k] = si.t, tuple(si.n), position[id(hit)]
    return t, normal, found


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_pyclray_reads_the_file_as_mitsuba_does(path):
    """Mitsuba's primary rays of a grid of pixels are pyclray's camera rays within the camera bound
    (3 eps (1 + S)); on those very rays pyclray and Mitsuba hit the same shapes at depths within the
    error model's same-ray bound 6 eps (t + L) / cos (silhouettes and edges aside): the sensor, the
    transforms (composed in Mitsuba's order) and every shape mean what Mitsuba makes of them."""
    scene = pyclray.load_scene(path)
    mi = mitsuba.import_mitsuba("scalar_rgb")
    mi_scene = mi.load_file(str(path), optimize=False)  # one Mitsuba shape per shape (no merged meshes)
    assert len(mi_scene.shapes()) == len(scene.shapes)
    width, height = scene.image.width, scene.image.height
    rows, columns = np.meshgrid(np.linspace(0, height - 1, 30).astype(int), np.linspace(0, width - 1, 40).astype(int))
    rows, columns = rows.ravel(), columns.ravel()
    origins, directions = mitsuba.primary_rays(mi_scene, scene, rows, columns)
    _, pixel_rays = oracle.camera_rays(scene)
    assert angle_between(directions, pixel_rays[rows, columns]).max() <= error_model.camera_angle_tolerance(scene)

    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    t, normal, found = mitsuba_intersect(mi_scene, scene, origins, directions)
    ours = pyclray.cast(scene, origins, directions)
    truth = oracle.trace(scene, origins, unit, aovs=("depth", "normal", "id", "second"))
    cos = oracle.incidence_cosine(scene, unit, truth["id"], truth["normal"])
    depth_bound, normal_bound = error_model.mitsuba_tolerances(scene, truth["depth"], truth["id"], cos, cameras=False,
                                                               origin_scale=np.linalg.norm(origins, axis=1))
    reach = depth_bound * cos
    apart = error_model.silhouettes(truth["id"], cos, depth_bound, error_model.curvature_radii(scene)[np.maximum(truth["id"], 0)])
    apart |= error_model.at_edges(scene, origins, unit, [(truth["id"], truth["depth"]), (found, t)], reach)
    judged = ~apart
    assert (found[judged] == ours["id"][judged]).all()
    same = judged & (found >= 0)
    assert same.sum() > 50  # the shape fills part of the view
    assert (np.abs(ours["depth"][same] - t[same]) <= depth_bound[same]).all()
    # Mitsuba's cube is a float32 mesh: its face normals come from float32 world vertices, off by a
    # few eps L over the edge's length l (the error model's K eps L, seen from across the face)
    L = error_model.world_sizes(scene, scene.camera.eye)[found[same]]
    edge = np.array([np.sort(np.ptp(shape.box(), axis=0))[1] for shape in scene.shapes])[found[same]]  # not a flat one's 0
    angle = angle_between(ours["normal"][same], normal[same])
    bad = angle > normal_bound[same] + error_model.K_MITSUBA * error_model.EPSILON["fp32"] * L / edge
    assert not bad.any(), (ours["normal"][same][bad][:3], normal[same][bad][:3], found[same][bad][:3])


def test_a_scene_in_mitsubas_syntax_reads_as_written():
    """Every plugin and property pyclray reads, with the values Mitsuba's documentation gives them:
    defaults and $name, fov_axis smaller, a lookat, a top-level bsdf by reference, a twosided one,
    Mitsuba's default reflectance 0.5, a cube as a box, an open cylinder, both emitters."""
    scene = pyclray.load_scene(SCENES / "mitsuba-shapes.xml")
    assert (scene.image.width, scene.image.height) == (64, 48)
    camera = scene.camera
    assert (camera.eye, camera.target, camera.up, camera.fov, camera.fov_axis) == (
        (0.0, 2.0, 8.0), (0.0, 0.5, 0.0), (0.0, 1.0, 0.0), 40.0, "y")  # smaller: the height
    ball, floor, disk, cube, tube = scene.shapes
    assert (ball.name, ball.center, ball.radius, ball.material.color) == ("ball", (0.0, 1.0, 0.0), 1.0, (0.8, 0.1, 0.1))
    assert floor.material.color == (0.5, 0.5, 0.5) and np.allclose(floor.u, (5, 0, 0)) and np.allclose(floor.v, (0, 0, -5))
    assert (disk.center, disk.normal, disk.radius) == ((2.0, 0.01, 0.0), (0.0, 0.0, 1.0), 0.5)  # scale, then translate
    assert cube.type == "box" and cube.size == (1.0, 0.6, 0.4) and cube.axis == (0.0, 1.0, 0.0)
    assert math.isclose(cube.angle, 30.0) and cube.center == (-2.0, 0.3, 0.0)
    assert (tube.type, tube.p0, tube.p1, tube.radius, tube.caps) == ("cylinder", (1.5, 0.0, -1.0), (1.5, 1.5, -1.0), 0.3, False)
    key, sun = scene.lights
    assert (key.position, key.intensity) == ((2.0, 4.0, 3.0), (10.0, 10.0, 10.0))
    assert (sun.direction, sun.irradiance) == ((-1.0, -2.0, -1.0), (1.0, 1.0, 1.0))


SENSOR = ('<sensor type="perspective"><float name="fov" value="45"/><transform name="to_world">'
          '<lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform></sensor>')


@pytest.mark.parametrize(
    "body, words",
    [
        ('<shape type="torus"/>', ["line 3", '<shape type="torus">', "unknown shape plugin 'torus'", "sphere"]),
        ('<shape type="obj"><string name="filename" value="a.obj"/></shape>', ["line 3", '<shape type="obj">', "a.obj",
                                                                                "no such file"]),
        ('<shape type="ply"/>', ["line 3", "missing property 'filename'"]),
        ('<shape type="serialized"/>', ["line 3", "unknown shape plugin 'serialized'"]),
        ('<shape type="instance"><ref id="g"/></shape>', ["line 3", "no <shape type=\"shapegroup\" id=\"g\">"]),
        ('<shape type="shapegroup" id="g"><shape type="shapegroup" id="h"/></shape>', ["line 3", "a shapegroup inside a shapegroup"]),
        ('<shape type="sphere"><float value="1"/></shape>', ["line 3", "<float>", "missing attribute 'name'"]),
        ('<shape type="sphere"><float name="radius"/></shape>', ["line 3", "missing attribute 'value'"]),
        ('<shape type="sphere"><float name="radius" value="big"/></shape>', ["line 3", "expected numbers, got 'big'"]),
        ('<shape type="sphere"><float name="raduis" value="1"/></shape>', ["line 3", "unknown property 'raduis'"]),
        ('<shape type="sphere"><transform name="to_world"><rotate angle="30"/></transform></shape>',
         ["line 3", "<rotate>", "non-zero rotation axis"]),
        ('<shape type="sphere"><transform name="to_world"><matrix value="1 2 3"/></transform></shape>',
         ["line 3", "<matrix>", "expected 16 (or 9) numbers"]),
        ('<shape type="sphere"><transform name="to_world"><scale x="0"/></transform></shape>',
         ["line 3", "invertible"]),
        ('<shape type="sphere"><transform name="to_world"><shear/></transform></shape>',
         ["line 3", "<shear>", "unknown transform operation"]),
        ('<shape type="sphere"><transform name="to_world"><scale x="2"/></transform></shape>',
         ["line 3", "non-uniform scale"]),
        ('<shape type="cylinder"><transform name="to_world"><matrix value="1 1 0 0 0 1 0 0 0 0 1 0 0 0 0 1"/></transform></shape>',
         ["line 3", "elliptic or slanted"]),
        ('<shape type="disk"><transform name="to_world"><scale x="2"/></transform></shape>', ["line 3", "ellipse"]),
        ('<shape type="sphere"><emitter type="area"/></shape>', ["line 3", '<emitter type="area">', "area light"]),
        ('<shape type="sphere"><bsdf type="conductor"/></shape>', ["line 3", "unknown bsdf plugin 'conductor'"]),
        ('<shape type="sphere"><ref id="nothing"/></shape>', ["line 3", "no <bsdf id=\"nothing\">"]),
        ('<emitter type="envmap"/>', ["line 3", "unknown emitter plugin 'envmap'", "directional"]),
        ('<include filename="other.xml"/>', ["line 3", "<include>", "not read by pyclray"]),
        ('<shape type="sphere"><float name="radius" value="$r"/></shape>', ["line 3", "$r is not defined"]),
        ('<shape type="sphere" flip_normals="x"><boolean name="flip_normals" value="true"/></shape>',
         ["line 3", "flip_normals"]),
    ],
)
def test_an_element_pyclray_cannot_read_is_one_line_naming_it(body, words, tmp_path, capsys):
    """Unknown plugins, missing attributes, bad values and transforms, shapes pyclray cannot express:
    one line on stderr (file, line, element, what was expected), exit status 2, nothing written."""
    path = tmp_path / "bad.xml"
    path.write_text(f'<scene version="3.0.0">\n{SENSOR}\n{body}\n</scene>\n')
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.load_scene(path)
    for word in [str(path)] + words:
        assert word in str(error.value), (word, str(error.value))
    status = cli.main(["render", str(path), "-o", str(tmp_path / "out.exr")])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and words[-1] in err
    assert not (tmp_path / "out.exr").exists()


@pytest.mark.parametrize(
    "text, words",
    [
        ("this is not XML", ["not valid XML", "line 1"]),
        ("", ["not valid XML", "no element found"]),
        ('<scene version="3.0.0">\n<shape type="sphere">\n</scene>', ["not valid XML", "mismatched tag", "line 3"]),
        ('<?xml version="1.0"?>\n<!DOCTYPE scene [<!ENTITY a "aaaa">]>\n<scene/>', ["line 2", "document type"]),
        ('<shape type="sphere"/>', ["line 1", "expected a Mitsuba scene"]),
        ('<scene version="3.0.0"><shape type="sphere"/></scene>', ["no <sensor", "camera"]),
        (f'<scene version="3.0.0">{SENSOR}{SENSOR}</scene>', ["a second sensor"]),
        ('<scene version="3.0.0"><sensor type="perspective"><float name="fov" value="45"/><transform name="to_world">'
         '<scale x="-1"/></transform></sensor></scene>', ["mirrors the image"]),
        ('<scene version="3.0.0"><sensor type="thinlens"/></scene>', ["unknown sensor plugin 'thinlens'"]),
    ],
)
def test_a_file_that_is_not_a_scene_is_one_line(text, words, tmp_path):
    path = tmp_path / "bad.xml"
    path.write_text(text)
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.load_scene(path)
    message = str(error.value)
    assert "\n" not in message and message.startswith(str(path))
    for word in words:
        assert word in message, (word, message)


def test_transforms_compose_in_mitsubas_order(tmp_path):
    """<translate/><rotate/><scale/> is S R T: the sphere's centre (1, 0, 0) turns about y to
    (0, 0, -1) and doubles, its radius doubles (Mitsuba reads the same, test above)."""
    path = tmp_path / "order.xml"
    path.write_text(f'<scene version="3.0.0">{SENSOR}<shape type="sphere"><transform name="to_world">'
                    '<translate x="1"/><rotate y="1" angle="90"/><scale value="2"/></transform></shape></scene>')
    sphere = pyclray.load_scene(path).shapes[0]
    assert np.allclose(sphere.center, (0, 0, -2), atol=1e-15) and sphere.radius == 2.0


def test_fov_axes_and_a_principal_point(tmp_path):
    """diagonal becomes x through tan(fov_x / 2) = tan(fov / 2) w / sqrt(w^2 + h^2); a principal
    point offset makes a camera from intrinsics with the optical axis at (0.5 - offset) of the film
    (the film's corner at 0: K's cx is that less 1/2, OpenCV's pixel convention since the sensors issue)."""
    def sensor(extra):
        path = tmp_path / "s.xml"
        path.write_text('<scene version="3.0.0"><sensor type="perspective"><float name="fov" value="50"/>'
                        f'{extra}<film type="hdrfilm"><integer name="width" value="40"/><integer name="height" '
                        'value="30"/></film></sensor></scene>')
        return pyclray.load_scene(path).camera

    diagonal = sensor('<string name="fov_axis" value="diagonal"/>')
    assert diagonal.fov_axis == "x"
    assert math.isclose(math.tan(math.radians(diagonal.fov) / 2), math.tan(math.radians(25)) * 40 / 50)
    assert sensor('<string name="fov_axis" value="larger"/>').fov_axis == "x"
    shifted = sensor('<float name="principal_point_offset_x" value="0.1"/>')
    K = shifted.intrinsics(40, 30)
    assert math.isclose(K[0, 2], 40 * 0.4 - 0.5) and math.isclose(K[1, 2], 14.5)
    assert math.isclose(K[0, 0], 20 / math.tan(math.radians(25)))


def test_render_and_check_accept_xml(tmp_path, capsys):
    """Every command takes an .xml scene: a render, and a check against Mitsuba that passes."""
    assert cli.main(["render", str(SCENES / "mitsuba-shapes.xml"), "-o", str(tmp_path / "o.npz"), "--aov", "id"]) == 0
    ids = np.load(tmp_path / "o.npz")["id"]
    assert set(np.unique(ids)) == {-1, 0, 1, 2, 3, 4}  # every shape in view
    status = cli.main(["check", str(SCENES / "mitsuba-shapes.xml"), "--rays", "128"])
    out = capsys.readouterr().out
    assert status == 0, out
