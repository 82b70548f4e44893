"""`pyclray dataset --format bop`: every file BOP's docs/bop_datasets_format.md names, checked field by
field as the BOP toolkit's inout.py reads it and its calc_gt_info.py / calc_gt_coco.py compute it;
COCO masks decoded by pycocotools are exactly the rendered id image's pixels; depth back-projected
with cam_K, cam_R_w2c, cam_t_w2c lands on the meshes' triangles within the uint16 quantisation."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image as PilImage

import pyclray
from pyclray.io.dataset import Placement, view_cameras
from pyclray.io.dataset.models import diameter
from tests.dataset_scene import CUBE_VERTICES, read_png, write_scene

VIEWS = 6
UNIT = 0.5  # metres per scene unit: every length in the files is scene units * 500 mm
DEPTH_SCALE = 0.25  # mm per depth level


def cli(*args):
    return subprocess.run([sys.executable, "-m", "pyclray", *map(str, args)], capture_output=True, text=True,
                          env=dict(os.environ))


@pytest.fixture(scope="module")
def bop(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bop")
    scene_path = write_scene(folder)
    out = folder / "out"
    result = cli("dataset", scene_path, "-o", out, "--views", VIEWS, "--seed", 3, "--unit", UNIT,
                 "--depth-scale", DEPTH_SCALE, "--radius", "2.5:3.5", "--elevation", "15:60")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("dataset ") and "views/s" in result.stdout
    scene = pyclray.load_scene(scene_path)
    cameras = view_cameras(scene, Placement("hemisphere", (2.5, 3.5), (15.0, 60.0), 3), VIEWS)
    return out, scene, cameras


def load(path):
    with open(path) as f:
        return json.load(f, object_hook=lambda d: {int(k) if k.lstrip("-").isdigit() else k: v for k, v in d.items()})


def test_layout(bop):
    out, scene, _ = bop
    root = out / "train" / "000000"
    assert sorted(p.name for p in out.iterdir()) == [".pyclray-dataset", "camera.json", "models", "train"]
    assert sorted(p.name for p in root.iterdir()) == ["depth", "mask", "mask_visib", "rgb", "scene_camera.json",
                                                      "scene_gt.json", "scene_gt_coco.json", "scene_gt_info.json"]
    names = [f"{k:06d}.png" for k in range(VIEWS)]
    assert sorted(p.name for p in (root / "rgb").iterdir()) == names
    assert sorted(p.name for p in (root / "depth").iterdir()) == names
    masks = [f"{k:06d}_{g:06d}.png" for k in range(VIEWS) for g in range(2)]  # two objects: gt 0 cube, 1 wedge
    assert sorted(p.name for p in (root / "mask").iterdir()) == masks
    assert sorted(p.name for p in (root / "mask_visib").iterdir()) == masks
    assert sorted(p.name for p in (out / "models").iterdir()) == ["models_info.json", "obj_000001.ply", "obj_000007.ply"]
    assert not [p for p in out.rglob(".*.tmp")]


def test_json_files_are_the_toolkits_save_json(bop):
    """inout.save_json: '{', one line per key in order ('  "k": ' + json.dumps(v, sort_keys=True)), '}'."""
    out, _, _ = bop
    for name in ("scene_camera.json", "scene_gt.json", "scene_gt_info.json"):
        text = (out / "train/000000" / name).read_text()
        content = json.loads(text)
        lines = [f'  "{k}": {json.dumps(content[str(k)], sort_keys=True)}' for k in range(VIEWS)]
        assert text == "{\n" + ",\n".join(lines) + "\n}"


def test_scene_camera(bop):
    out, scene, cameras = bop
    scene_camera = load(out / "train/000000/scene_camera.json")
    assert sorted(scene_camera) == list(range(VIEWS))
    for k, camera in enumerate(cameras):
        entry = scene_camera[k]
        assert sorted(entry) == ["cam_K", "cam_R_w2c", "cam_t_w2c", "depth_scale"]
        assert len(entry["cam_K"]) == 9 and len(entry["cam_R_w2c"]) == 9 and len(entry["cam_t_w2c"]) == 3
        K = np.array(entry["cam_K"]).reshape(3, 3)
        assert np.array_equal(K, camera.intrinsics(64, 48))  # the camera model's own K, row-major
        R = np.array(entry["cam_R_w2c"]).reshape(3, 3)
        t = np.array(entry["cam_t_w2c"])
        pose = camera.pose()
        np.testing.assert_allclose(R, pose[:3, :3].T, atol=1e-15)
        np.testing.assert_allclose(t, -pose[:3, :3].T @ pose[:3, 3] * 1000 * UNIT, rtol=1e-12, atol=1e-9)
        assert entry["depth_scale"] == DEPTH_SCALE
        # the camera looks at the labelled shapes' centre, from 2.5 to 3.5 units away
        centre = (np.min([s.box()[0] for s in scene.shapes if s.label], axis=0)
                  + np.max([s.box()[1] for s in scene.shapes if s.label], axis=0)) / 2
        centre_in_camera = R @ centre * 1000 * UNIT + t
        assert abs(centre_in_camera[0]) < 1e-6 and abs(centre_in_camera[1]) < 1e-6
        assert 2.5 * 500 - 1e-6 <= centre_in_camera[2] <= 3.5 * 500 + 1e-6
    camera_json = json.loads((out / "camera.json").read_text())
    K = scene.camera.intrinsics(64, 48)
    assert camera_json == {"cx": K[0, 2], "cy": K[1, 2], "depth_scale": DEPTH_SCALE, "fx": K[0, 0], "fy": K[1, 1],
                           "height": 48, "width": 64}


def ply(path):
    """The toolkit's load_ply, for our ASCII files: header, vertices x y z nx ny nz, faces '3 a b c'."""
    lines = Path(path).read_text().splitlines()
    end = lines.index("end_header")
    header = lines[:end]
    assert header[:2] == ["ply", "format ascii 1.0"]
    vertex_count = int(next(l for l in header if l.startswith("element vertex")).split()[-1])
    face_count = int(next(l for l in header if l.startswith("element face")).split()[-1])
    assert [l for l in header if l.startswith("property")] == [
        "property float x", "property float y", "property float z", "property float nx", "property float ny",
        "property float nz", "property list uchar int vertex_indices"]
    rows = np.array([[float(x) for x in l.split()] for l in lines[end + 1:end + 1 + vertex_count]])
    faces = np.array([[int(x) for x in l.split()] for l in lines[end + 1 + vertex_count:]])
    assert faces.shape == (face_count, 4) and (faces[:, 0] == 3).all()
    return rows[:, :3], rows[:, 3:], faces[:, 1:]


def test_models_and_poses(bop):
    """models/obj_ID.ply in mm and scene_gt's cam_R_m2c, cam_t_m2c: R_m2c p + t_m2c is each model
    vertex in the camera's frame (mm), where the scene puts it (world vertices through the pose)."""
    out, scene, cameras = bop
    scene_gt = load(out / "train/000000/scene_gt.json")
    objects = [s for s in scene.shapes if s.label is not None]
    models = {s.label: ply(out / f"models/obj_{s.label:06d}.ply") for s in objects}
    for vertices, normals, faces in models.values():
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-9)
    info = load(out / "models/models_info.json")
    # the PLY holds float32 (9 digits), models_info and the poses the float64 model: within float32's rounding
    f32 = 2.0**-24
    assert sorted(info) == [1, 7]
    for obj_id, (vertices, _, _) in models.items():
        entry = info[obj_id]
        assert sorted(entry) == ["diameter", "min_x", "min_y", "min_z", "size_x", "size_y", "size_z"]
        brute = max(np.linalg.norm(a - b) for a in vertices for b in vertices)
        scale = np.abs(vertices).max()
        assert entry["diameter"] == pytest.approx(brute, abs=4 * f32 * scale)
        for i, axis in enumerate("xyz"):
            assert entry[f"min_{axis}"] == pytest.approx(vertices[:, i].min(), abs=f32 * scale)
            assert entry[f"size_{axis}"] == pytest.approx(np.ptp(vertices[:, i]), abs=2 * f32 * scale)
    # the cube's model is the file's cube with its scale baked in: 0.8 x 0.6 x 0.7 units, in mm
    cube = models[1][0]
    np.testing.assert_allclose(cube, np.array(CUBE_VERTICES) * [0.8, 0.6, 0.7] * 500, rtol=f32)
    scene_camera = load(out / "train/000000/scene_camera.json")
    for k in range(VIEWS):
        assert [g["obj_id"] for g in scene_gt[k]] == [1, 7]  # every object, in the scene's order
        R_w2c = np.array(scene_camera[k]["cam_R_w2c"]).reshape(3, 3)
        t_w2c = np.array(scene_camera[k]["cam_t_w2c"])
        for g, shape in zip(scene_gt[k], objects):
            assert sorted(g) == ["cam_R_m2c", "cam_t_m2c", "obj_id"]
            R = np.array(g["cam_R_m2c"]).reshape(3, 3)
            t = np.array(g["cam_t_m2c"])
            np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
            assert np.linalg.det(R) == pytest.approx(1.0)
            in_camera = models[shape.label][0] @ R.T + t
            expected = shape.world_vertices() * 500 @ R_w2c.T + t_w2c
            np.testing.assert_allclose(in_camera, expected, atol=4 * f32 * 500)


def render_ids(scene, camera):
    return pyclray.render(scene, aovs=("id", "zdepth", "primitive"), camera=camera)


def test_masks_and_gt_info(bop):
    """mask_visib is the rendered id image's pixels of the object; mask the object rendered alone
    (a superset); scene_gt_info's counts, boxes and fraction as calc_gt_info computes them."""
    out, scene, cameras = bop
    root = out / "train/000000"
    info = load(root / "scene_gt_info.json")
    ids_of = [i for i, s in enumerate(scene.shapes) if s.label is not None]
    for k, camera in enumerate(cameras):
        frame = render_ids(scene, camera)
        depth = read_png(root / f"depth/{k:06d}.png")
        for gt_id, shape_id in enumerate(ids_of):
            visib = read_png(root / f"mask_visib/{k:06d}_{gt_id:06d}.png")
            mask = read_png(root / f"mask/{k:06d}_{gt_id:06d}.png")
            assert set(np.unique(visib)) <= {0, 255} and set(np.unique(mask)) <= {0, 255}
            assert np.array_equal(visib == 255, frame["id"] == shape_id)
            alone = pyclray.render(pyclray.Scene(camera, scene.image, (scene.shapes[shape_id],)), aovs=("id",))["id"] >= 0
            assert np.array_equal(mask == 255, alone)
            entry = info[k][gt_id]
            assert sorted(entry) == ["bbox_obj", "bbox_visib", "px_count_all", "px_count_valid", "px_count_visib",
                                     "visib_fract"]
            visible = visib == 255
            assert entry["px_count_visib"] == visible.sum()
            assert entry["px_count_valid"] == ((mask == 255) & (depth > 0)).sum()
            assert entry["px_count_all"] >= (mask == 255).sum()
            assert entry["visib_fract"] == (visible.sum() / entry["px_count_all"] if entry["px_count_all"] else 0.0)
            if visible.any():
                ys, xs = np.nonzero(visible)
                assert entry["bbox_visib"] == [xs.min(), ys.min(), xs.max() - xs.min(), ys.max() - ys.min()]
                ys, xs = np.nonzero(mask == 255)
                x, y, w, h = entry["bbox_obj"]
                assert x <= xs.min() and y <= ys.min() and x + w >= xs.max() and y + h >= ys.max()
                if entry["px_count_all"] == (mask == 255).sum():
                    assert entry["bbox_obj"] == [xs.min(), ys.min(), xs.max() - xs.min(), ys.max() - ys.min()]
            else:
                assert entry["bbox_visib"] == [-1, -1, -1, -1] and entry["bbox_obj"] == [-1, -1, -1, -1]
    assert any(info[k][g]["visib_fract"] < 1 for k in range(VIEWS) for g in range(2))  # the ball hides some


def test_truncated_object_counts_pixels_beyond_the_image(tmp_path):
    """An object cut by the image's edge: px_count_all counts its whole silhouette (a render on a
    canvas three times the image's size, as calc_gt_info), bbox_obj reaches beyond the image."""
    scene_path = write_scene(tmp_path)
    scene = pyclray.load_scene(scene_path)
    cube = scene.shapes[1]
    K = scene.camera.intrinsics(64, 48)
    from pyclray.io.dataset.placement import look_pose
    pose = look_pose(np.array([-0.5 + 0.6, 0.3, 0.0]), np.array([0, 1.0, 0]), 1.2, 0.0, 45.0)
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps([{"K": K.tolist(), "pose": pose.tolist()}]))
    out = tmp_path / "out"
    result = cli("dataset", scene_path, "-o", out, "--poses", poses)
    assert result.returncode == 0, result.stderr
    entry = load(out / "train/000000/scene_gt_info.json")[0][0]
    camera = pyclray.Camera.from_intrinsics(K, pose, 64, 48)
    big_K = K.copy()
    big_K[:2, 2] += [64, 48]
    alone = pyclray.Scene(pyclray.Camera.from_intrinsics(big_K, pose, 192, 144), pyclray.Image(192, 144), (cube,))
    canvas = pyclray.render(alone, aovs=("id",))["id"] >= 0
    inside = pyclray.render(pyclray.Scene(camera, scene.image, (cube,)), aovs=("id",))["id"] >= 0
    outside = canvas.copy()
    outside[48:96, 64:128] = False
    assert outside.any() and inside.any()
    assert entry["px_count_all"] == inside.sum() + outside.sum()
    ys, xs = np.nonzero(canvas)
    assert entry["bbox_obj"][0] < 0 or entry["bbox_obj"][1] < 0 or entry["bbox_obj"][0] + entry["bbox_obj"][2] > 63
    assert entry["bbox_obj"] == [xs.min() - 64, ys.min() - 48, xs.max() - xs.min(), ys.max() - ys.min()]


def test_depth_back_projects_onto_the_meshes(bop):
    """Each depth pixel d (mm = d * depth_scale) back-projected with cam_K, cam_R_w2c, cam_t_w2c
    (p_c = z K^-1 [u, v, 1] at the pixel's centre in K's convention; p_w = R^T (p_c - t)) lies on
    the plane of the triangle the ray hit, within the quantisation: |z - z_true| <= depth_scale / 2
    plus float32's rounding of z (2^-23 z), times |K^-1 [u, v, 1]| along the ray."""
    out, scene, cameras = bop
    root = out / "train/000000"
    scene_camera = load(root / "scene_camera.json")
    checked = 0
    for k, camera in enumerate(cameras):
        entry = scene_camera[k]
        K = np.array(entry["cam_K"]).reshape(3, 3)
        R, t = np.array(entry["cam_R_w2c"]).reshape(3, 3), np.array(entry["cam_t_w2c"])
        depth = read_png(root / f"depth/{k:06d}.png").astype(np.float64) * entry["depth_scale"]
        frame = render_ids(scene, camera)
        # the pixel centre in K's convention: the camera model's own rays say where it is
        _, directions = camera.rays(64, 48)
        for shape_id, shape in enumerate(scene.shapes):
            if shape.object_model() is None:
                continue
            a, b, c = (corner * 1000 * UNIT for corner in shape.corners())
            hit = (frame["id"] == shape_id) & (depth > 0)
            js, is_ = np.nonzero(hit)
            rays_c = directions[js, is_] @ R.T  # OpenCV camera frame
            rays_c /= rays_c[:, 2:3]  # K^-1 [u, v, 1]: z = 1
            uv = rays_c @ K.T
            offset = uv[:, :2] - np.stack([is_, js], axis=1)
            assert np.allclose(offset, offset[0], atol=1e-9) and np.all(np.isin(np.round(offset[0], 9), (0.0, 0.5)))
            p_c = depth[js, is_][:, None] * rays_c
            p_w = (p_c - t) @ R
            primitive = frame["primitive"][js, is_]
            n = np.cross(b[primitive] - a[primitive], c[primitive] - a[primitive])
            n /= np.linalg.norm(n, axis=1, keepdims=True)
            distance = np.abs(np.einsum("ij,ij->i", p_w - a[primitive], n))
            z = frame["zdepth"][js, is_].astype(np.float64) * 1000 * UNIT
            bound = (entry["depth_scale"] / 2 + 2.0**-23 * z * 2) * np.linalg.norm(rays_c, axis=1)
            assert (distance <= bound).all(), (k, shape_id, float((distance / bound).max()))
            checked += len(distance)
    assert checked > 500


def test_coco_masks_decode_to_the_rendered_ids(bop):
    """The COCO API reads the file (pycocotools.coco.COCO, annToMask) and pycocotools.mask decodes
    each segmentation as it is: exactly the rendered id image's pixels; the counts are the string
    pycocotools.mask.encode makes of that mask."""
    from pycocotools import mask as coco_mask
    from pycocotools.coco import COCO

    out, scene, cameras = bop
    path = out / "train/000000/scene_gt_coco.json"
    coco = json.loads(path.read_text())
    api = COCO(str(path))
    assert sorted(coco) == ["annotations", "categories", "images", "info", "licenses"]
    assert coco["categories"] == [{"id": 1, "name": "1", "supercategory": "pyclray"},
                                  {"id": 7, "name": "7", "supercategory": "pyclray"}]
    assert [im["id"] for im in coco["images"]] == list(range(VIEWS))
    assert all(im["file_name"] == f"rgb/{im['id']:06d}.png" and (im["width"], im["height"]) == (64, 48)
               for im in coco["images"])
    ids_of = {1: 1, 7: 3}  # category -> the shape's id
    found = 0
    for k, camera in enumerate(cameras):
        frame = render_ids(scene, camera)
        annotations = [a for a in coco["annotations"] if a["image_id"] == k]
        for gt_id, label in enumerate((1, 7)):
            expected = frame["id"] == ids_of[label]
            mine = [a for a in annotations if a["category_id"] == label]
            if not expected.any():
                assert not mine
                continue
            (annotation,) = mine
            assert annotation["id"] == k * 2 + gt_id + 1 and annotation["iscrowd"] == 0
            rle = annotation["segmentation"]
            assert rle["size"] == [48, 64]
            assert rle["counts"] == coco_mask.encode(np.asfortranarray(expected.astype(np.uint8)))["counts"].decode()
            assert np.array_equal(coco_mask.decode(rle).astype(bool), expected)
            assert np.array_equal(api.annToMask(api.anns[annotation["id"]]).astype(bool), expected)
            assert annotation["area"] == expected.sum() == int(coco_mask.area(rle))
            ys, xs = np.nonzero(expected)
            assert annotation["bbox"] == [xs.min(), ys.min(), xs.max() - xs.min() + 1, ys.max() - ys.min() + 1]
            assert list(coco_mask.toBbox(rle)) == annotation["bbox"]
            found += 1
    assert found >= VIEWS


def test_rgb_is_the_shaded_preview(bop):
    from pyclray.io.png import srgb_preview

    out, scene, cameras = bop
    frame = pyclray.render(scene, aovs=("shaded",), camera=cameras[0])
    rgb = np.array(PilImage.open(out / "train/000000/rgb/000000.png"))
    assert rgb.shape == (48, 64, 3) and np.array_equal(rgb, srgb_preview(frame["shaded"]))
    depth = np.array(PilImage.open(out / "train/000000/depth/000000.png"))
    assert np.array_equal(depth.astype(np.uint16), read_png(out / "train/000000/depth/000000.png"))


def test_diameter_is_exact():
    rng = np.random.default_rng(5)
    for points in (rng.normal(size=(300, 3)), rng.normal(size=(40, 3)) * [5, 1, 0.1], np.zeros((1, 3))):
        brute = max((np.linalg.norm(a - b) for a in points for b in points), default=0.0)
        assert diameter(points) == pytest.approx(brute, rel=1e-12)


def test_diameter_of_many_points_is_every_pairs_largest():
    """Sets of thousands of points (diameter passes over the pairs of runs of nearby points that
    cannot hold the largest distance): on a sphere (every point on the hull, near-ties all over),
    a torus and a circle with exact antipodes, a grid (many equal pairs), a flat square, a line,
    and a spread cloud: the largest of all pairs' distances, measured one by one."""
    rng = np.random.default_rng(7)
    sphere = rng.normal(size=(3000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    angles = np.linspace(0, 2 * np.pi, 1200, endpoint=False)
    u, v = np.meshgrid(angles[::20], angles[::40], indexing="ij")
    torus = np.stack([(1 + 0.3 * np.cos(v)) * np.cos(u), (1 + 0.3 * np.cos(v)) * np.sin(u), 0.3 * np.sin(v)], -1)
    grid = np.stack(np.meshgrid(*[np.arange(12.0)] * 3), -1)
    sets = (sphere * 7.5 + 100.0, torus.reshape(-1, 3), np.c_[np.cos(angles), np.sin(angles), np.zeros(1200)],
            grid.reshape(-1, 3), np.c_[rng.uniform(size=(2000, 2)), np.zeros(2000)],
            np.outer(rng.uniform(size=1500), [1.0, -2.0, 0.5]), rng.standard_cauchy(size=(2500, 3)))
    for points in sets:
        brute = max(float(np.sqrt(((points[i] - points) ** 2).sum(axis=1)).max()) for i in range(len(points)))
        assert diameter(points) == pytest.approx(brute, rel=1e-12)


def test_coco_rle_is_pycocotools_encode():
    """Random masks of several sizes and densities, and masks starting with a run of 1s: the counts
    string and size are exactly pycocotools.mask.encode's."""
    from pycocotools import mask as coco_mask

    from pyclray.io.dataset.bop import coco_rle

    rng = np.random.default_rng(0)
    for shape, density in (((48, 64), 0.5), ((120, 160), 0.02), ((7, 3), 0.9), ((30, 30), 0.0), ((5, 5), 1.0)):
        for _ in range(10):
            mask = rng.random(shape) < density
            expected = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
            assert coco_rle(mask) == {"size": list(expected["size"]), "counts": expected["counts"].decode()}
    big = np.zeros((480, 640), bool)
    big[100:300, 200:500] = True  # runs beyond 2^15 and differences of both signs
    assert coco_rle(big)["counts"] == coco_mask.encode(np.asfortranarray(big.astype(np.uint8)))["counts"].decode()
    # given the columns that hold the 1s (the writer passes its visible box's): the same string, for
    # masks whose 1s start in the first row, end in the last, or fill their columns
    for _ in range(200):
        height, width = rng.integers(1, 13, 2)
        mask = np.zeros((height, width), bool)
        (x0, x1), (y0, y1) = sorted(rng.integers(0, width, 2)), sorted(rng.integers(0, height, 2))
        mask[y0:y1 + 1, x0:x1 + 1] = rng.random((y1 - y0 + 1, x1 - x0 + 1)) < rng.choice([0.3, 0.9, 1.0])
        expected = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))["counts"].decode()
        for columns in ((x0, x1), (0, width - 1), (x0, width - 1)):
            assert coco_rle(mask, columns)["counts"] == expected, (mask, columns)


def torus(rings=24, sides=12, major=1.0, minor=0.35):
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, rings, endpoint=False), np.linspace(0, 2 * np.pi, sides, endpoint=False),
                       indexing="ij")
    vertices = np.stack([(major + minor * np.cos(v)) * np.cos(u), (major + minor * np.cos(v)) * np.sin(u),
                         minor * np.sin(v)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rings), np.arange(sides), indexing="ij")
    a, b = i * sides + j, ((i + 1) % rings) * sides + j
    c, d = ((i + 1) % rings) * sides + (j + 1) % sides, i * sides + (j + 1) % sides
    return vertices, np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])


def test_amodal_masks_are_the_objects_rendered_alone():
    """A view's amodal masks come from the scene's render (its visible pixels) and renders of each
    object alone only over the pixels where it may lie hidden, and, where its box reaches beyond the
    image, over the canvas outside the image (views.py: _start_alone): each mask equals the object
    rendered alone over the whole image, and its outside count and box the object alone on the whole
    three-times canvas less the image, bit for bit. Interlocked tori hide each other, a ball (scenery)
    hides them, the ground cuts one; near cameras see them cut by the image's edges, one from inside
    an object's box (corners behind the camera)."""
    from pyclray.io.dataset import DatasetViews, make_format

    vertices, faces = torus()
    shapes = (pyclray.Plane((0.0, 1.0, 0.0), 0.0, name="ground"),
              pyclray.Mesh(vertices, faces, scale=0.5, axis=(1.0, 0.0, 0.0), angle=90.0, translate=(0.0, 0.15, 0.0),
                           name="flat", label=1),
              pyclray.Mesh(vertices, faces, scale=0.5, translate=(0.5, 0.5, 0.0), name="upright", label=2),
              pyclray.Sphere((-0.2, 0.35, 0.7), 0.25, name="ball"),
              pyclray.Mesh(vertices, faces, scale=0.4, axis=(0.0, 1.0, 0.0), angle=40.0, translate=(-0.7, 0.1, -0.5),
                           name="sunk", label=3))
    image = pyclray.Image(80, 60)
    scene = pyclray.Scene(pyclray.Camera((0.0, 2.0, 3.0), (0.0, 0.3, 0.0), fov=50.0), image, shapes,
                          lights=(pyclray.PointLight((2.0, 4.0, 3.0), (20.0, 20.0, 20.0)),))
    cameras = view_cameras(scene, Placement("hemisphere", (0.9, 3.5), (5.0, 80.0), 5), 14)
    cameras.append(pyclray.Camera((0.5, 0.5, 0.1), (0.5, 0.5, 3.0), fov=60.0))  # inside the upright torus's box
    work = DatasetViews(scene, cameras, make_format("bop"))
    hidden = reaching_out = 0
    try:
        for view in work.views(range(len(cameras))):
            camera = view.camera
            K, pose = camera.intrinsics(80, 60), camera.pose()
            big_K = K.copy()
            big_K[:2, 2] += [80, 60]
            canvas_camera = pyclray.Camera.from_intrinsics(big_K, pose, 240, 180)
            for shape_id, (mask, count, box) in zip((1, 2, 4), view.alone):
                alone = pyclray.render(pyclray.Scene(camera, image, (shapes[shape_id],)), aovs=("id",))["id"] >= 0
                assert np.array_equal(mask, alone), (view.index, shape_id)
                canvas = pyclray.render(pyclray.Scene(canvas_camera, pyclray.Image(240, 180), (shapes[shape_id],)),
                                        aovs=("id",))["id"] >= 0
                canvas[60:120, 80:160] = False
                ys, xs = np.nonzero(canvas)
                assert count == len(xs)
                assert box == ((xs.min() - 80, ys.min() - 60, xs.max() - 80, ys.max() - 60) if len(xs) else None)
                hidden += int((alone & (view.images["id"] != shape_id)).any())
                reaching_out += int(count > 0)
    finally:
        work.close()
    assert hidden >= 20 and reaching_out >= 10, (hidden, reaching_out)  # the cases the test is for did happen


def test_object_space_box_holds_the_object():
    """The box the hidden pixels are bounded by (views.py: _object_space): a turned mesh's model box
    in its own space holds its world vertices taken there, and is tighter than its world box; a shape
    without a model (a sphere) has its world box and the identity."""
    from pyclray.io.dataset.views import _object_space

    vertices, faces = torus()
    mesh = pyclray.Mesh(vertices, faces, scale=(0.5, 0.3, 0.2), axis=(1.0, 1.0, 0.0), angle=35.0, translate=(1.0, 2.0, 3.0))
    low, high, object_from_world = _object_space(mesh)
    world = mesh.world_vertices()
    local = world @ object_from_world[:3, :3].T + object_from_world[:3, 3]
    assert np.allclose(local.min(axis=0), low) and np.allclose(local.max(axis=0), high)
    box = mesh.box()
    assert np.prod(high - low) * abs(np.linalg.det(mesh.object_pose()[:3, :3])) < 0.7 * np.prod(box[1] - box[0])
    sphere = pyclray.Sphere((1.0, 2.0, 3.0), 0.5)
    low, high, object_from_world = _object_space(sphere)
    assert np.array_equal(np.stack([low, high]), sphere.box()) and np.array_equal(object_from_world, np.eye(4))


def test_a_views_error_comes_after_the_views_before_it(tmp_path):
    """The scene's renders run two views ahead (views.py: DatasetViews.views): a view whose render
    cannot start (a camera beyond fp32's range from the shapes) raises its error in its turn, after
    every view before it was handed over, as Tracer.render_views does."""
    from pyclray.io.dataset import DatasetViews, make_format

    scene = pyclray.load_scene(write_scene(tmp_path))
    cameras = view_cameras(scene, Placement("hemisphere", seed=1), 5)
    cameras[3] = pyclray.Camera((1e30, 0.0, 0.0), (0.0, 0.0, 0.0), fov=50.0)
    work = DatasetViews(scene, cameras, make_format("bop"))
    handed = []
    try:
        with pytest.raises(pyclray.SceneError, match="from the eye"):
            for view in work.views(range(5)):
                handed.append(view.index)
    finally:
        work.close()
    assert handed == [0, 1, 2]
