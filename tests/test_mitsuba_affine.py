"""Issue 42 item 5: Mitsuba XML read as Mitsuba 3 renders it. A <rotate> about a non-unit axis is
Mitsuba's Transform4f::rotate with the axis as given (cos I + sin [a]x + (1 - cos) a a^T, not a
rotation: drjit's rotate does not normalise it); a cube under a general affine to_world (a shear, a
mirror) is Mitsuba's own 12-triangle mesh of [-1, 1]^3, and a rectangle under one that is not a
similarity its 2-triangle mesh; a shapegroup may hold any shape (spheres, disks, rectangles, cubes,
cylinders, meshes), each instance placing it anew. Each scene is held to what Mitsuba itself reads
and intersects (tests/test_mitsuba_xml.py's comparison: the same rays through both, within the
error model)."""
import math

import numpy as np
import pytest

import pyclray
from pyclray.model.mitsuba_xml.properties import rotation

from test_mitsuba_xml import test_pyclray_reads_the_file_as_mitsuba_does as reads_as_mitsuba

SENSOR = """<sensor type="perspective"><float name="fov" value="50"/>
  <transform name="to_world"><lookat origin="1, 4, 9" target="0, 0.5, 0" up="0, 1, 0"/></transform>
  <film type="hdrfilm"><integer name="width" value="80"/><integer name="height" value="60"/></film>
 </sensor>"""

AFFINE = f"""<scene version="3.0.0">
 {SENSOR}
 <shape type="cube" id="turned"><transform name="to_world"><scale value="0.6"/>
   <rotate x="1" y="1" z="0" angle="40"/><translate x="-2.2" y="0.8"/></transform></shape>
 <shape type="cube" id="stretched"><transform name="to_world"><scale value="0.5"/>
   <rotate x="0" y="0" z="2" angle="30"/><translate x="0" y="0.8" z="-1"/></transform></shape>
 <shape type="cube" id="mirrored"><transform name="to_world"><scale x="-0.5" y="0.7" z="0.5"/>
   <translate x="2" y="0.7"/></transform></shape>
 <shape type="rectangle" id="slanted"><transform name="to_world">
   <matrix value="1.5 0.8 0 0.5  0 0.5 1 0.8  0 -1 0.4 1.5  0 0 0 1"/></transform></shape>
 <shape type="rectangle" id="floor"><transform name="to_world"><rotate x="1" angle="-90"/><scale value="5"/></transform></shape>
</scene>
"""

GROUPS = f"""<scene version="3.0.0">
 {SENSOR}
 <shape type="shapegroup" id="ball"><shape type="sphere"><float name="radius" value="0.5"/></shape></shape>
 <shape type="instance" id="b1"><ref id="ball"/><transform name="to_world"><translate x="-2" y="0.5"/></transform></shape>
 <shape type="instance" id="b2"><ref id="ball"/><transform name="to_world"><scale value="1.5"/>
   <translate x="2" y="0.75"/></transform></shape>
 <shape type="shapegroup" id="pad"><shape type="disk"/></shape>
 <shape type="instance" id="p1"><ref id="pad"/><transform name="to_world"><rotate x="1" angle="-90"/><scale value="0.7"/>
   <translate y="0.01" z="1.5"/></transform></shape>
 <shape type="shapegroup" id="tile"><shape type="rectangle"/></shape>
 <shape type="instance" id="t1"><ref id="tile"/><transform name="to_world"><rotate x="1" angle="-90"/><scale value="5"/></transform></shape>
 <shape type="instance" id="t2"><ref id="tile"/><transform name="to_world"><matrix value="1 0.5 0 0  0 1 0 1.2  0 0 1 -3  0 0 0 1"/></transform></shape>
 <shape type="shapegroup" id="crate"><shape type="cube"><transform name="to_world"><scale value="0.4"/></transform></shape></shape>
 <shape type="instance" id="c1"><ref id="crate"/><transform name="to_world"><matrix value="1 0.6 0 0  0 1 0 0.4  0 0 1 -1.5  0 0 0 1"/></transform></shape>
 <shape type="instance" id="c2"><ref id="crate"/><transform name="to_world"><translate x="-0.8" y="0.4" z="1.2"/></transform></shape>
 <shape type="shapegroup" id="pipe"><shape type="cylinder"><float name="radius" value="0.2"/></shape></shape>
 <shape type="instance" id="y1"><ref id="pipe"/><transform name="to_world"><translate x="0.9" z="0.8"/></transform></shape>
</scene>
"""


def test_rotate_keeps_a_non_unit_axis_as_mitsuba_does():
    """Mitsuba 3.9's Transform4f.rotate([0, 0, 2], 30) is [[c, -2s, 0], [2s, c, 0], [0, 0, c + 4 (1 - c)]]."""
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    assert np.allclose(rotation((0, 0, 2), 30), [[c, -2 * s, 0], [2 * s, c, 0], [0, 0, c + 4 * (1 - c)]], atol=1e-15)
    a = np.array([1.0, 1.0, 0.0])
    expected = c * np.eye(3) + s * np.array([[0, 0, 1], [0, 0, -1], [-1, 1, 0]]) + (1 - c) * np.outer(a, a)
    assert np.allclose(rotation(a, 30), expected, atol=1e-15)


def test_general_affine_cubes_and_rectangles_are_mitsubas_meshes(tmp_path):
    path = tmp_path / "affine.xml"
    path.write_text(AFFINE)
    turned, stretched, mirrored, slanted, floor = pyclray.load_scene(path).shapes
    assert (turned.type, len(turned.faces)) == ("mesh", 12)  # sheared: Mitsuba's 12-triangle cube
    assert stretched.type == "box"  # the non-unit axis only stretches it: still square corners
    assert math.isclose(stretched.size[2], 1.0 * (math.cos(math.radians(30)) + 4 * (1 - math.cos(math.radians(30)))))
    assert (mirrored.type, len(mirrored.faces)) == ("mesh", 12)
    assert (slanted.type, len(slanted.faces)) == ("mesh", 2) and floor.type == "rectangle"
    reads_as_mitsuba(path)


def test_shapegroups_of_any_shape_are_instanced_as_mitsuba_does(tmp_path):
    path = tmp_path / "groups.xml"
    path.write_text(GROUPS)
    scene = pyclray.load_scene(path)
    assert [s.name for s in scene.shapes] == ["b1_0", "b2_0", "p1_0", "t1_0", "t2_0", "c1_0", "c2_0", "y1_0"]
    assert [s.type for s in scene.shapes] == ["sphere", "sphere", "disk", "rectangle", "mesh", "mesh", "box", "cylinder"]
    assert scene.shapes[1].radius == 0.75 and scene.shapes[1].center == (2.0, 0.75, 0.0)
    reads_as_mitsuba(path)


@pytest.mark.parametrize("body, words", [
    ('<shape type="shapegroup" id="g"><shape type="sphere"/></shape>'
     '<shape type="instance"><ref id="g"/><transform name="to_world"><scale x="2"/></transform></shape>',
     ["line 3", '<shape type="instance">', "non-uniform scale"]),
    ('<shape type="shapegroup" id="g"><shape type="disk"/></shape>'
     '<shape type="instance"><ref id="g"/><transform name="to_world"><scale x="2"/></transform></shape>',
     ["line 3", '<shape type="instance">', "ellipse"]),
    ('<shape type="shapegroup" id="g"><shape type="sphere"><float name="radius" value="-1"/></shape></shape>',
     ["line 3", '<shape type="sphere">', "radius"]),
])
def test_a_bad_group_or_instance_is_one_line_naming_it(body, words, tmp_path):
    path = tmp_path / "bad.xml"
    path.write_text(f'<scene version="3.0.0">\n{SENSOR.replace(chr(10), " ")}\n{body}\n</scene>\n')
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.load_scene(path)
    text = str(error.value)
    assert "\n" not in text and all(word in text for word in words), text
