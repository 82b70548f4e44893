"""The scene loader: good files load, every bad input raises one SceneError naming file, table and key."""
import math

import numpy as np
import pytest

import pyclray
from pyclray import SceneError

GOOD = """
[camera]
eye = [0.0, 2.0, 6.0]
target = [0.0, 0.5, 0.0]
up = [0.0, 1.0, 0.0]
fov = 45.0

[image]
width = 64
height = 48

[[shapes]]
type = "plane"
name = "floor"
normal = [0.0, 2.0, 0.0]
offset = 0.0

[[shapes]]
type = "sphere"
center = [0.0, 1.0, 0.0]
radius = 1.0
"""


def write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_good_scene_loads(tmp_path):
    scene = pyclray.load_scene(write(tmp_path, GOOD))
    assert scene.image.width == 64 and scene.image.height == 48
    assert [s.type for s in scene.shapes] == ["plane", "sphere"]
    assert scene.shapes[0].name == "floor"
    assert scene.shapes[1].name == "sphere1"  # default "<type><index>"
    assert scene.camera.fov_axis == "x"
    assert scene.shape_types() == ("plane", "sphere")


def test_every_shipped_scene_loads(scenes_dir):
    paths = sorted(scenes_dir.glob("*.toml"))
    assert any(p.name == "tp02.toml" for p in paths)
    for path in paths:
        scene = pyclray.load_scene(path)
        assert scene.shapes, path


def test_plane_point_form_equals_offset_form(tmp_path):
    text = GOOD.replace("offset = 0.0", "point = [3.0, 0.5, -2.0]")
    plane = pyclray.load_scene(write(tmp_path, text)).shapes[0]
    n, h = plane.unit()
    assert np.allclose(n, [0, 1, 0]) and h == pytest.approx(-0.5)


def test_camera_basis_is_orthonormal_and_left_handed_as_the_contract():
    camera = pyclray.Camera((0, 2, 6), (0, 0.5, 0), (0, 3, 0.1), 45)
    u, v, w = camera.basis()
    assert np.allclose(np.stack([u, v, w]) @ np.stack([u, v, w]).T, np.eye(3), atol=1e-15)
    assert np.allclose(w, np.subtract(camera.target, camera.eye) / np.linalg.norm(np.subtract(camera.target, camera.eye)))
    assert np.allclose(u, np.cross(camera.up, w) / np.linalg.norm(np.cross(camera.up, w)))
    assert np.allclose(v, np.cross(w, u))


def test_fov_axis_tangents():
    camera_x = pyclray.Camera((0, 0, 0), (0, 0, -1), (0, 1, 0), 90, "x")
    camera_y = pyclray.Camera((0, 0, 0), (0, 0, -1), (0, 1, 0), 90, "y")
    assert camera_x.tangents(200, 100) == pytest.approx((1.0, 0.5))
    assert camera_y.tangents(200, 100) == pytest.approx((2.0, 1.0))


# (what to change in GOOD, table named in the message, key named in the message)
BAD = [
    ("fov = 45.0", "fov = 45.0\nfocus = 1.0", "[camera]", "focus"),  # unknown key
    ('type = "sphere"', 'type = "cube"', "[[shapes]] #1", "type"),  # unknown shape type
    ("radius = 1.0", "radius = 1.0\nradiuss = 2.0", "[[shapes]] #1 (sphere)", "radiuss"),
    ("eye = [0.0, 2.0, 6.0]", "eye = [0.0, 2.0]", "[camera]", "eye"),  # wrong length
    ("eye = [0.0, 2.0, 6.0]", 'eye = [0.0, "2", 6.0]', "[camera]", "eye"),  # wrong type
    ("eye = [0.0, 2.0, 6.0]", "eye = [0.0, nan, 6.0]", "[camera]", "eye"),  # NaN
    ("target = [0.0, 0.5, 0.0]", "target = [0.0, inf, 0.0]", "[camera]", "target"),  # inf
    ("center = [0.0, 1.0, 0.0]", "center = 1.0", "[[shapes]] #1 (sphere)", "center"),
    ("radius = 1.0", "radius = 0.0", "[[shapes]] #1 (sphere)", "radius"),
    ("radius = 1.0", "radius = -2.0", "[[shapes]] #1 (sphere)", "radius"),
    ("radius = 1.0", 'radius = "big"', "[[shapes]] #1 (sphere)", "radius"),
    ("radius = 1.0", "radius = true", "[[shapes]] #1 (sphere)", "radius"),
    ("radius = 1.0\n", "", "[[shapes]] #1 (sphere)", "radius"),  # missing
    ("normal = [0.0, 2.0, 0.0]", "normal = [0.0, 0.0, 0.0]", "[[shapes]] #0 (plane)", "normal"),
    ("offset = 0.0", "offset = 0.0\npoint = [0.0, 0.0, 0.0]", "[[shapes]] #0 (plane)", "offset"),  # both
    ("offset = 0.0\n", "", "[[shapes]] #0 (plane)", "offset"),  # neither
    ("fov = 45.0", "fov = 0.0", "[camera]", "fov"),
    ("fov = 45.0", "fov = 180.0", "[camera]", "fov"),
    ("fov = 45.0", "fov = -10.0", "[camera]", "fov"),
    ("fov = 45.0", 'fov = 45.0\nfov_axis = "z"', "[camera]", "fov_axis"),
    ("width = 64", "width = 0", "[image]", "width"),
    ("height = 48", "height = -3", "[image]", "height"),
    ("width = 64", "width = 64.0", "[image]", "width"),
    ("target = [0.0, 0.5, 0.0]", "target = [0.0, 2.0, 6.0]", "[camera]", "target"),  # eye == target
    ("up = [0.0, 1.0, 0.0]", "up = [0.0, 0.0, 0.0]", "[camera]", "up"),  # zero up
    ("up = [0.0, 1.0, 0.0]", "up = [0.0, -1.5, -6.0]", "[camera]", "up"),  # up parallel to view
    ("target = [0.0, 0.5, 0.0]\n", "", "[camera]", "target"),  # missing (fov may be: 45, issue 42)
    ("[image]", "[imgae]", "(top level)", "imgae"),
    ('name = "floor"', "name = 3", "[[shapes]] #0 (plane)", "name"),
]


@pytest.mark.parametrize("old,new,table,key", BAD, ids=[f"{k}:{n[:24]}" for _, n, _, k in BAD])
def test_bad_input_names_file_table_and_key(tmp_path, old, new, table, key):
    assert old in GOOD
    path = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(SceneError) as caught:
        pyclray.load_scene(path)
    error = caught.value
    assert error.file == str(path)
    assert error.table == table
    assert error.key == key
    message = str(error)
    assert str(path) in message and table in message and f"'{key}'" in message
    assert "\n" not in message
    assert "expected" in message or "missing" in message or "unknown" in message


def test_camera_table_missing(tmp_path):
    with pytest.raises(SceneError, match=r"missing required table \[camera\]"):
        pyclray.load_scene(write(tmp_path, "[image]\nwidth = 4\nheight = 4\n"))


def test_shapes_not_an_array_of_tables(tmp_path):
    text = GOOD.split("[[shapes]]")[0] + "shapes = 3\n"
    with pytest.raises(SceneError, match="shapes"):
        pyclray.load_scene(write(tmp_path, text))


def test_not_toml_and_missing_file(tmp_path):
    with pytest.raises(SceneError, match="not valid TOML"):
        pyclray.load_scene(write(tmp_path, "[camera\neye = 1"))
    with pytest.raises(SceneError, match="cannot read"):
        pyclray.load_scene(tmp_path / "nope.toml")


def test_up_nearly_parallel_is_a_clear_error_only_below_the_threshold():
    w = np.array([0.0, -1.0, -1.0]) / math.sqrt(2)
    side = np.array([1.0, 0.0, 0.0])
    with pytest.raises(SceneError, match="parallel"):
        pyclray.Camera((0, 4, 4), (0, 0, 0), tuple(w + 1e-8 * side), 50)
    u, v, _ = pyclray.Camera((0, 4, 4), (0, 0, 0), tuple(w + 1e-4 * side), 50).basis()
    assert np.allclose(np.cross(u, v), w)


def test_a_fov_whose_rays_collapse_in_float32_is_an_error():
    with pytest.raises(SceneError, match="fov"):
        pyclray.Scene(pyclray.Camera((0, 0, 0), (0, 0, -1), (0, 1, 0), 1e-30), pyclray.Image(64, 64))
    pyclray.Scene(pyclray.Camera((0, 0, 0), (0, 0, -1), (0, 1, 0), 1e-20), pyclray.Image(64, 64))


def test_scenes_built_in_code_are_validated_too():
    with pytest.raises(SceneError) as caught:
        pyclray.Sphere((0, 0, 0), -1)
    assert caught.value.key == "radius"
    with pytest.raises(SceneError):
        pyclray.Scene(pyclray.Camera((0, 0, 0), (0, 0, -1)), shapes=("not a shape",))


# -- hardening (issue 14) ---------------------------------------------------------------------------
def test_a_byte_order_mark_is_not_part_of_the_text(tmp_path):
    """Defect 5: editors that write a UTF-8 BOM (was: 'Invalid statement (at line 1, column 1)')."""
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + GOOD.encode())
    with_mark, without = pyclray.load_scene(path), pyclray.load_scene(write(tmp_path, GOOD))
    assert (with_mark.camera, with_mark.image, with_mark.shapes) == (without.camera, without.image, without.shapes)


def test_render_and_cast_accept_a_path_and_say_what_they_expect(scenes_dir):
    """Defect 5: pyclray.render("scenes/tp02.toml") raised a bare AttributeError."""
    path = scenes_dir / "tp02.toml"
    scene = pyclray.load_scene(path).with_size(8, 8)
    direct = pyclray.render(pyclray.load_scene(path))
    assert np.array_equal(pyclray.render(str(path))["depth"], direct["depth"])
    assert pyclray.cast(path, (0.0, 2.0, 6.0), [[0.0, -0.25, -1.0]])["id"][0] >= 0
    for bad in (42, None, {"camera": {}}):
        with pytest.raises(pyclray.RequestError, match="scene: expected a pyclray.Scene or the path of a scene file"):
            pyclray.render(bad)
    with pytest.raises(SceneError, match="cannot read"):
        pyclray.render(str(path) + ".missing")
    assert scene.image.width == 8


def test_repeated_aovs_are_named_not_shown_as_a_tuple(scenes_dir):
    scene = pyclray.load_scene(scenes_dir / "tp02.toml").with_size(8, 8)
    with pytest.raises(pyclray.RequestError) as error:
        pyclray.render(scene, aovs=("depth", "depth"))
    assert "got depth, depth" in str(error.value) and "(" not in str(error.value).split("got")[1]


BIG = '''
[camera]
eye = [0.0, 2.0, 6.0]
target = [0.0, 0.5, 0.0]
fov = 45.0

[[shapes]]
{shape}
'''


@pytest.mark.parametrize(
    "shape,key,fp64_renders",
    [
        ('type = "sphere"\ncenter = [0.0, -2e19, 0.0]\nradius = 2e19', "center", True),
        ('type = "sphere"\ncenter = [0.0, 1.0, -3e18]\nradius = 2e19', "radius", True),
        ('type = "plane"\nnormal = [0.0, 1.0, 0.0]\noffset = 1e39', "offset", True),
        ('type = "sphere"\ncenter = [1e300, 0.0, 0.0]\nradius = 1.0', "center", False),
        ('type = "sphere"\ncenter = [-1.7e308, 0.0, 0.0]\nradius = 1.0', "center", False),
        ('type = "cylinder"\np0 = [0.0, 0.0, -3e19]\np1 = [0.0, 1.0, -3e19]\nradius = 1.0', "p0", True),
        ('type = "cylinder"\np0 = [0.0, 0.0, -3.0]\np1 = [0.0, 1.0, -3.0]\nradius = 3e19', "radius", True),
        ('type = "disk"\ncenter = [0.0, -1e39, 0.0]\nnormal = [0.0, 1.0, 0.0]\nradius = 1.0', "center", True),
        ('type = "rectangle"\ncenter = [0.0, 0.0, -3.0]\nu = [3e19, 0.0, 0.0]\nv = [0.0, 1.0, 0.0]', "u", True),
        ('type = "box"\ncenter = [0.0, 0.0, -3.0]\nsize = [1.0, 5e19, 1.0]', "size", True),
        ('type = "box"\ncenter = [1e300, 0.0, 0.0]\nsize = [1.0, 1.0, 1.0]', "center", False),
    ],
)
def test_geometry_beyond_the_precision_is_a_scene_error_naming_the_key(tmp_path, shape, key, fp64_renders):
    """Defect 3: geometry beyond float32's range rendered as silent misses with numpy warnings.
    Now a SceneError names the shape and the key and says whether fp64 is needed; no warning."""
    scene = pyclray.load_scene(write(tmp_path, BIG.format(shape=shape))).with_size(8, 8)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a raw numpy RuntimeWarning fails the test
        with pytest.raises(SceneError) as error:
            pyclray.render(scene)
        message = str(error.value)
        assert "table [[shapes]] #0" in message and f"key '{key}'" in message
        assert ("fp64 is needed" in message) == fp64_renders, message
        if not fp64_renders:
            with pytest.raises(SceneError, match="beyond fp64 too"):
                pyclray.render(scene, precision="fp64")


def test_intrinsics_and_pose_back_project_a_depth_map_onto_the_surface(scenes_dir):
    """K and the pose of a look-at camera (OpenCV's convention) turn the depth image back into the
    hit points: pose @ (depth * normalize(K^-1 [i, j, 1])) lies on the shapes, as the float64
    oracle's rays say (same rays: the directions agree to float64 rounding). K in OpenCV's pixel
    convention (centres at integers) since the sensors issue: it was [i + 0.5, j + 0.5, 1]."""
    import pyclray
    from pyclray.reference import oracle

    scene = pyclray.load_scene(scenes_dir / "tp02.toml").with_size(40, 30)
    K, pose = scene.camera.intrinsics(40, 30), scene.camera.pose()
    assert np.allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3)) and np.isclose(np.linalg.det(pose[:3, :3]), 1.0)
    j, i = np.mgrid[0:30, 0:40]
    pixels = np.stack([i, j, np.ones_like(i, dtype=float)], axis=-1)
    rays = pixels @ np.linalg.inv(K).T @ pose[:3, :3].T
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    _, directions = oracle.camera_rays(scene)
    assert np.abs(rays - directions).max() < 1e-14
