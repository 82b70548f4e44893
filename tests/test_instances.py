"""Mesh instances (model/shapes/instance.py, engine/scene/instances.py, kernels/instance.cl): meshes that
share their arrays render as one copy of the triangles and one BVH in object space plus a transform
per instance. Each test says why it can fail: a wrong inverse, normal matrix or box unit shows as
depth, normal, id or primitive off the float64 oracle (within the one error model), or as images
that differ from the same meshes flattened (copies of the arrays: no instancing)."""
import numpy as np
import pytest

import pyclray
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.engine.scene.instances import instance_bytes
from pyclray.engine.api import tracer_for
from pyclray.model.shapes.mesh_shapes import grid, perturbed_sphere
from pyclray.reference import oracle

from oracle_checks import assert_agrees_with_oracle, assert_primitives_agree, judge

AOVS = ("depth", "normal", "id", "primitive", "barycentric")


def need(precision):
    if precision == "fp64" and not has_fp64(context_for().device):
        pytest.skip("device lacks cl_khr_fp64")


def field(offset=0.0, count=4):
    """A perturbed sphere placed count x count times around offset: rotations, non-uniform scale
    and mirroring (a negative scale turns the winding, so the normal), on a floor grid."""
    rng = np.random.default_rng(7)
    v, f = perturbed_sphere(10, 14, 0.8, 0.25, rng)
    base = pyclray.Mesh(v, f)
    shift = np.array([offset, -0.5 * offset, 0.25 * offset])
    shapes = []
    for i in range(count):
        for j in range(count):
            scale = [(1.0, 1.0, 1.0), (1.3, 0.6, 0.9), (-1.0, 1.0, 1.0), (0.5, 0.5, 0.5)][(i + j) % 4]
            shapes.append(base.placed(scale=scale, axis=tuple(rng.normal(size=3)), angle=float(rng.uniform(0, 360)),
                                      translate=tuple(shift + [2.2 * (i - count / 2 + 0.5), 0.8, 2.2 * (j - count / 2 + 0.5)])))
    v, f = grid(6, 6, 12.0)
    shapes.append(pyclray.Mesh(v, f, translate=tuple(shift)))
    camera = pyclray.Camera(tuple(shift + [0.0, 6.0, 9.0]), tuple(shift + [0.0, 0.5, 0.0]))
    return pyclray.Scene(camera, pyclray.Image(64, 48), tuple(shapes))


def flattened(scene):
    """The same scene with each mesh's arrays copied: nothing shared, no instances."""
    shapes = tuple(pyclray.Mesh(np.array(s.vertices), np.array(s.faces), scale=s.scale, axis=s.axis, angle=s.angle,
                                translate=s.translate, name=s.name) for s in scene.shapes)
    return pyclray.Scene(scene.camera, scene.image, shapes)


def test_shared_meshes_are_packed_once():
    """Sixteen placements of one mesh: one instance entry each, the triangles and the BVH once
    (the floor, alone, stays triangles), and no shared copy in the flattened scene."""
    scene = field()
    prepared = tracer_for(scene, context_for(), "fp32").prepared
    kind = prepared.kinds["instance"]
    mesh = scene.shapes[0]
    vertices, faces = kind.shared_host[0], kind.shared_host[1]  # instances.SHARED's order
    assert kind.count == 16 and len(vertices) == len(mesh.vertices) and len(faces) == len(mesh.faces)
    assert sorted(np.where(faces[:, 3] >= 0, faces[:, 3], ~faces[:, 3])) == list(range(len(mesh.faces)))  # each triangle once
    assert np.array_equal(np.sort(faces[:, :3], axis=1), np.sort(mesh.faces[np.where(faces[:, 3] >= 0, faces[:, 3], ~faces[:, 3])], axis=1))
    assert set(kind.world["root"]) == {0} and set(kind.world["first"]) == {0}
    assert prepared.kinds["mesh"].count == len(scene.shapes[-1].faces)
    assert "instance" not in tracer_for(flattened(scene), context_for(), "fp32").prepared.kinds


def test_bytes_per_instance():
    """Each instance costs at most 1 KB of its own (world entry, per-view entry, its share of the
    top-level tree), whatever its mesh's size; the mesh is paid for once, at most 64 bytes a triangle
    as a mesh of the scene (its vertices, faces and tree: issue 23's memory target)."""
    scene = field(count=10)
    cost = instance_bytes(tracer_for(scene, context_for(), "fp32").prepared)
    assert cost["instances"] == 100 and cost["bytes_per_instance"] <= 1024
    assert cost["shared_bytes"] <= 64 * len(scene.shapes[0].faces)


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("offset", [0.0, 1e6])
def test_instances_agree_with_the_oracle(precision, offset):
    """Depth and normal within the error model (the instance's direction rounding, a few eps of
    the direction, is far inside its K eps (t + L)), ids and primitives right wherever judged,
    barycentrics as the flattened meshes' within float rounding, near the origin and 1e6 away."""
    need(precision)
    scene = field(offset)
    frame = pyclray.render(scene, aovs=AOVS, precision=precision, acceleration="bvh")
    origins, directions = oracle.camera_rays(scene)
    origins, directions = origins.reshape(-1, 3), directions.reshape(-1, 3)
    result = {k: frame[k].reshape(len(directions), *frame[k].shape[2:]) for k in ("depth", "normal", "id")}
    truth, _, judged, _, _, _ = judge(scene, origins, directions, result, precision, scene.camera.eye)
    assert_agrees_with_oracle(scene, origins, directions, result, precision, reference_point=scene.camera.eye)
    assert_primitives_agree(scene, origins, directions, frame, truth, judged)
    assert (frame["id"] < 16).sum() > 0.3 * frame["id"].size  # the instances are most of the image
    flat = pyclray.render(flattened(scene), aovs=AOVS, precision=precision, acceleration="bvh")
    same = (flat["primitive"] == frame["primitive"]) & (frame["id"] >= 0)
    eps = np.finfo(np.float32 if precision == "fp32" else np.float64).eps
    # (u, v) of the same triangle: the vertices from_world in object space instead of world space; the
    # flattened meshes' world vertices carry float64 rounding of their coordinates' size (offset),
    # about 2^-53 offset / (a triangle's size, > 0.01 here) in (u, v)
    tolerance = 1e4 * eps + 100 * 2.0**-53 * offset / 0.01
    assert np.abs(flat["barycentric"][same] - frame["barycentric"][same]).max() < tolerance


@pytest.mark.parametrize("acceleration", ["bvh", "tiles"])
def test_same_images_as_the_flattened_meshes(acceleration):
    """Through the top-level BVH or tile lists, the instanced scene's ids and primitives are the
    flattened scene's but where either answer is right (a ray within rounding of a shared edge or
    a silhouette: the oracle's judge explains it), depth within the error model."""
    scene = field()
    frame = pyclray.render(scene, aovs=AOVS, acceleration=acceleration)
    flat = pyclray.render(flattened(scene), aovs=AOVS, acceleration=acceleration)
    origins, directions = oracle.camera_rays(scene)
    result = {k: frame[k].reshape(-1, *frame[k].shape[2:]) for k in ("depth", "normal", "id")}
    _, _, judged, _, depth_tolerance, _ = judge(scene, origins.reshape(-1, 3), directions.reshape(-1, 3), result, "fp32",
                                                scene.camera.eye)
    assert np.array_equal(frame["id"].reshape(-1)[judged], flat["id"].reshape(-1)[judged])
    assert np.array_equal(frame["primitive"].reshape(-1)[judged], flat["primitive"].reshape(-1)[judged])
    error = np.abs(frame["depth"].reshape(-1)[judged].astype(np.float64) - flat["depth"].reshape(-1)[judged])
    assert (error <= 2 * depth_tolerance[judged]).all()  # each within the tolerance of the truth


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("offset", [0.0, 1e6])
def test_cast_and_occluded_through_instances(precision, offset):
    """cast and occluded enter the instances too (each ray from_world on its own origin in object
    space): the oracle's hits within the error model, the flattened meshes' ids and occlusion,
    and a ray stopped short of its hit is not occluded."""
    need(precision)
    scene = field(offset)
    assert "instance" in tracer_for(scene, context_for(), precision).prepared.types
    rng = np.random.default_rng(2)
    origins = np.array(scene.camera.eye) + rng.normal(size=(1500, 3)) * 0.5
    aim = np.array(scene.camera.target) + rng.normal(size=(1500, 3)) * 3.0
    result = pyclray.cast(scene, origins, aim - origins, precision=precision)
    assert_agrees_with_oracle(scene, origins, aim - origins, result, precision)
    flat = pyclray.cast(flattened(scene), origins, aim - origins, precision=precision)
    assert np.array_equal(result["id"], flat["id"])
    hit = np.isfinite(result["depth"])
    assert pyclray.occluded(scene, origins, aim - origins, precision=precision)[hit].all()
    short = 0.5 * result["depth"][hit]
    assert not pyclray.occluded(scene, origins[hit], (aim - origins)[hit], tmax=short, precision=precision).any()


def test_host_and_device_rebase_agree():
    """The per-view entries of instances from the host (Instances._rebase) and from the device
    (kernels/instance.cl's instance_rebase) are the same bits."""
    from pyclray.engine.launch.programs import Variant, kernels_for
    import pyopencl as cl

    ctx = context_for()
    if not has_fp64(ctx.device):
        pytest.skip("device lacks cl_khr_fp64")
    prepared = tracer_for(field(1e6), ctx, "fp32").prepared
    kind = prepared.kinds["instance"]
    eye, rows = np.array([1e6 + 0.3, -5e5 + 6.1, 2.5e5 + 9.7]), pyclray.Camera((0, 6, 9), (0, 0.5, 0)).basis()
    host = kind.cls.rebase(kind.world, eye, rows, "fp32", kind.ids, kind.primitives)
    kernels = kernels_for(ctx, Variant("rebase", prepared.types, (), "fp32"))
    world = cl.Buffer(ctx.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=kind.world)
    out = np.zeros_like(host)
    out_buffer = cl.Buffer(ctx.context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=out)
    frame = [np.append(v, 0.0).view(cl.cltypes.double4)[0] for v in (eye, *rows)]
    kernels["rebase_instance"](ctx.queue, (kind.count,), None, world, out_buffer, np.int32(kind.count), *frame)
    cl.enqueue_copy(ctx.queue, out, out_buffer)
    out["id"], out["primitive"] = host["id"], host["primitive"]
    for name in host.dtype.names:  # field by field (the device may leave the struct's padding as it likes)
        assert out[name].tobytes() == host[name].tobytes(), name


def test_export_writes_shapegroup_and_instances_that_read_back_shared(tmp_path):
    """pyclray export writes the shared bunny once (a shapegroup, one PLY) and an instance per
    placement; Mitsuba's render of that file has pyclray's depths within twice the error model's
    Mitsuba bound (its instances apply their float32 transforms) away from silhouettes and edges;
    pyclray reads the file back with the 25 bunnies sharing one copy (instances again)."""
    pytest.importorskip("mitsuba")
    from conftest import SCENES
    from pyclray.apps import cli
    from pyclray.reference import mitsuba
    from test_export import camera_reference, pixel_depths

    scene = pyclray.load_scene(SCENES / "instanced.toml").with_size(40, 30)
    path = tmp_path / "field.xml"
    assert cli.main(["export", str(SCENES / "instanced.toml"), "-o", str(path), "--size", "40x30"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["field.group_bunny0.ply", "field.xml"]
    text = path.read_text()
    assert text.count('type="shapegroup"') == 1 and text.count('type="instance"') == 25
    mi = mitsuba.import_mitsuba("scalar_rgb")

    def hits(mi_scene, scene, origins, directions):  # Mitsuba's distances (its instances name no pyclray id)
        t = np.full(len(origins), np.inf)
        for k, (o, d) in enumerate(zip(origins, directions)):
            si = mi_scene.ray_intersect(mi.Ray3f(mi.Point3f(*o), mi.Vector3f(*d)))
            t[k] = si.t if si.is_valid() else np.inf
        return t, None, np.where(np.isfinite(t), 0, -1)

    depth, _, _ = pixel_depths(mi.load_file(str(path), optimize=False), scene, hits)
    ours = pyclray.render(scene, aovs=("depth", "id"))
    mine = ours["depth"].reshape(-1).astype(np.float64)
    _, bound, _, apart = camera_reference(scene, [(ours["id"].reshape(-1), mine)])
    both = ~apart & np.isfinite(depth) & np.isfinite(mine)
    assert both.sum() > 500
    assert (np.abs(depth[both] - mine[both]) <= 2 * bound[both]).all()
    read = pyclray.load_scene(path)
    prepared = tracer_for(read, context_for(), "fp32").prepared
    assert prepared.kinds["instance"].count == 25 and len(prepared.kinds["instance"].shared_host[1]) == 5000


def test_check_passes_on_the_instanced_field(scenes_dir):
    """pyclray check's images on scenes/instanced.toml (25 instances of the bunny on a plane, one
    mirrored; 64x48): depth, normal, id and primitives against Mitsuba (each placement its own
    mi.Mesh) and the float64 oracle, within the error model; the bunnies are instances there."""
    pytest.importorskip("mitsuba")
    from pyclray.reference import check

    scene = pyclray.load_scene(scenes_dir / "instanced.toml").with_size(64, 48)
    assert tracer_for(scene, context_for(), "fp32").prepared.kinds["instance"].count == 25
    images = check.cross_check(scene, "scalar_rgb")
    assert images.passed, images.failures
    assert images.counts["primitives against the float64 oracle"] > 300, images.counts
    assert images.counts["  of which differ"] == 0


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_smooth_instances_match_the_float64_shading_model(precision):
    """Smooth placements of one mesh (turned, non-uniformly scaled, mirrored; one flat among them)
    are instances, lit by their vertex normals through each placement's normal matrix: the shaded
    image agrees with the float64 model (tests/test_shading.py's compare_shaded, the error model's
    tolerance) on every judged pixel, and differs from the flat placements' (a kernel that ignored
    smooth here would fail)."""
    need(precision)
    from pyclray.model.lights import PointLight, Shading
    from test_shading import compare_shaded

    v, f = perturbed_sphere(12, 16, 1.0, 0.08, np.random.default_rng(7))
    base = pyclray.Mesh(v, f, smooth=True)
    placements = [dict(translate=(-2.2, 0, 0)), dict(scale=(1.3, 0.7, 1.0), axis=(1, 2, 0), angle=30.0),
                  dict(scale=(-1.0, 1.0, 1.0), translate=(2.2, 0, 0)), dict(translate=(0, 2.2, -1), smooth=False)]

    def scene_of(smooth):
        shapes = (pyclray.Plane((0, 1, 0), 1.3),) + tuple(base.placed(**{"smooth": smooth, **p}) for p in placements)
        light = PointLight(position=(3.0, 4.0, 3.0), intensity=(20.0, 20.0, 20.0))
        return pyclray.Scene(pyclray.Camera((0.5, 1.5, 7), (0, 0.3, 0)), pyclray.Image(96, 72), shapes,
                             lights=(light,), shading=Shading(shadows=False))

    scene = scene_of(True)
    prepared = tracer_for(scene, context_for(), precision).prepared
    assert prepared.kinds["instance"].count == 4 and "instance" in prepared.smooth
    counts = compare_shaded(scene, precision)
    assert counts["lit"] > 1500, counts
    flat = pyclray.render(scene_of(False), aovs=("shaded",), precision=precision)["shaded"]
    smooth_ids = counts["ref"]["id"]
    on_smooth = (smooth_ids >= 1) & (smooth_ids <= 3)
    assert (np.abs(counts["frame"]["shaded"] - flat).max(axis=-1)[on_smooth] > 1e-3).mean() > 0.5
    on_flat = smooth_ids == 4
    assert on_flat.sum() > 100 and np.array_equal(counts["frame"]["shaded"][on_flat], flat[on_flat])


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_shadows_through_instances_match_the_float64_model(precision):
    """Shadow rays enter instances (each lane from its own point, the winner's own triangle skipped,
    not its instance): the shaded image with shadows cast by and onto instances agrees with the
    float64 shading model and visibility (tests/test_shading.py's compare_shaded) on every judged
    pixel, and with the flattened meshes' wherever both see the same shape."""
    need(precision)
    from pyclray.model.lights import PointLight, Shading
    from test_shading import compare_shaded

    base = field(count=3)
    light = PointLight(position=(3.0, 8.0, 3.0), intensity=(60.0, 60.0, 60.0))
    scene = pyclray.Scene(base.camera, base.image, base.shapes, lights=(light,), shading=Shading(shadows=True))
    assert "instance" in tracer_for(scene, context_for(), precision).prepared.types
    counts = compare_shaded(scene, precision)
    assert counts["lit"] > 1000 and counts["shadowed"] > 100, counts
    flat = flattened(scene)
    flat = pyclray.Scene(flat.camera, flat.image, flat.shapes, lights=scene.lights, shading=scene.shading)
    theirs = pyclray.render(flat, aovs=("shaded", "id"), precision=precision)
    same = counts["frame"]["id"] == theirs["id"]
    eps = np.finfo(np.float32 if precision == "fp32" else np.float64).eps
    assert same.mean() > 0.99 and np.abs(counts["frame"]["shaded"] - theirs["shaded"])[same].max() < 1e4 * eps
