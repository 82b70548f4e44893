"""The camera kernel against the float64 oracle, the contract's conventions, and specialisation.

Tolerances come from the error model in pyclray.accuracy: a float32 kernel can only be trusted to
a few float32 ulps of t; an error in the ray's direction moves the hit along the surface by
1/|cos incidence| more, so depth is compared in ulps of t times |cos|, and normals (unit vectors,
same relative rounding) in absolute error times |cos|. Silhouettes (|cos| < 0.02) and near-ties
are counted apart, since there rounding may legitimately pick the other surface.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

import pyclray
from pyclray.reference import error_model
from pyclray.reference import oracle
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.engine.launch.programs import Variant, stats
from pyclray.model.shapes import Plane, Sphere

# fp32 bounds, the error model's targets (pyclray.accuracy): 8 ulps of t x 1/|cos| for depth (sx,
# sy, the normalization, the basis and the intersection each round once or twice: about 6
# roundings in the worst chain), 2e-5 / |cos| for normals (they are normalized from vectors
# accurate to a few ulps; 2e-5 leaves headroom for the 1/|cos| growth near silhouettes that the
# error model bounds only to first order).
DEPTH_ULPS = error_model.FP32_DEPTH_ULPS
NORMAL = error_model.FP32_NORMAL


def small(scene, size=96):
    return scene.with_size(size, size * scene.image.height // scene.image.width or 1)


def assert_matches_oracle(scene, frame=None, precision="fp32"):
    ref = error_model.reference(scene)
    frame = frame if frame is not None else pyclray.render(scene, precision=precision)
    result = error_model.compare(frame, ref, engine=precision)
    assert result["id_mismatch"] == 0, result
    assert result["miss_mismatch"] == 0, result
    if precision == "fp32":
        assert result["depth_ulps_max"] <= DEPTH_ULPS, result
        assert result["normal_cos_max"] <= NORMAL, result
    else:
        assert result["depth_rel_cos_max"] <= error_model.FP64_DEPTH_RELATIVE, result
    # silhouettes and near-ties: ids may differ, but a pixel that hits must hit something real
    assert np.all(np.isfinite(frame["depth"]) == (frame["id"] >= 0))
    return result


@pytest.mark.parametrize("name", ["tp02", "portrait", "room", "far"])
def test_example_scenes_match_the_oracle(scenes_dir, name):
    scene = small(pyclray.load_scene(scenes_dir / f"{name}.toml"))
    assert_matches_oracle(scene)


def test_tp02_full_size_matches_the_oracle(scenes_dir):
    scene = pyclray.load_scene(scenes_dir / "tp02.toml")
    result = assert_matches_oracle(scene)
    assert result["pixels"] > 0.9 * 512 * 512


def random_scene(seed, size=64):
    rng = np.random.default_rng(seed)
    eye = rng.uniform(-5, 5, 3) + [0, 6, 0]
    target = rng.uniform(-1, 1, 3)
    shapes = [Plane(tuple(rng.normal(size=3) * [0.3, 1, 0.3] + [0, 2, 0]), float(rng.uniform(-1, 0.5)), "ground")]
    for k in range(int(rng.integers(1, 12))):
        shapes.append(Sphere(tuple(rng.uniform(-4, 4, 3)), float(rng.uniform(0.1, 2)), f"s{k}"))
    rng.shuffle(shapes)
    camera = pyclray.Camera(tuple(eye), tuple(target), tuple(rng.normal(size=3) * 0.3 + [0, 1, 0]),
                            float(rng.uniform(20, 120)), "x" if rng.random() < 0.5 else "y")
    return pyclray.Scene(camera, pyclray.Image(size, int(rng.integers(32, 96))), tuple(shapes))


@pytest.mark.parametrize("seed", range(12))
def test_random_scenes_match_the_oracle(seed):
    assert_matches_oracle(random_scene(seed))


@pytest.mark.parametrize("seed", range(3))
def test_random_scenes_fp64(seed):
    scene = random_scene(seed)
    if not has_fp64(context_for().device):
        pytest.skip("device lacks cl_khr_fp64")
    frame = pyclray.render(scene, precision="fp64")
    assert frame["depth"].dtype == np.float64 and frame["normal"].dtype == np.float64
    assert_matches_oracle(scene, frame, precision="fp64")


def test_misses_are_inf_zero_and_minus_one():
    scene = pyclray.Scene(pyclray.Camera((0, 0, 0), (0, 0, -1), (0, 1, 0), 30), pyclray.Image(16, 8),
                          (Sphere((0, 0, 5), 1.0),))  # behind the camera
    frame = pyclray.render(scene)
    assert np.all(np.isposinf(frame["depth"]))
    assert np.all(frame["normal"] == 0)
    assert np.all(frame["id"] == -1)
    assert frame["depth"].shape == (8, 16) and frame["normal"].shape == (8, 16, 3) and frame["id"].shape == (8, 16)
    assert frame["depth"].dtype == np.float32 and frame["id"].dtype == np.int32


def test_empty_scene_renders_all_misses():
    with pytest.warns(pyclray.PyclrayWarning, match="no shapes: every pixel is a miss"):
        frame = pyclray.render(pyclray.Scene(pyclray.Camera((0, 0, 0), (0, 0, -1)), pyclray.Image(5, 3)))
    assert np.all(np.isposinf(frame["depth"])) and np.all(frame["id"] == -1)


def test_image_is_not_mirrored_and_row_zero_is_the_top():
    """A sphere up and to the left of the view centre lands in the top-left quadrant."""
    camera = pyclray.Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), 60)
    u, v, w = camera.basis()  # u points to the viewer's left, v up
    scene = pyclray.Scene(camera, pyclray.Image(40, 30), (Sphere(tuple(1.0 * u + 1.0 * v), 0.4),))
    rows, cols = np.nonzero(pyclray.render(scene)["id"] == 0)
    assert rows.max() < 15 and cols.max() < 20
    # and the world's left is -x for a camera looking down -z with +y up
    assert u[0] < 0


def test_pixel_centre_rays_follow_the_contract_formula():
    """The centre column of an odd-width image looks straight along w; its depth to a plane
    facing the camera at distance 3 is exactly 3 there, and 3 / cos elsewhere."""
    camera = pyclray.Camera((0, 0, 0), (0, 0, -1), (0, 1, 0), 90, "x")
    scene = pyclray.Scene(camera, pyclray.Image(5, 3), (Plane((0, 0, 1), 3.0),))
    depth = pyclray.render(scene)["depth"].astype(np.float64)
    assert depth[1, 2] == 3.0
    sx = 1.0 * (1 - 2 * (np.arange(5) + 0.5) / 5)  # tan(45 deg) = 1
    sy = 0.6 * (1 - 2 * (np.arange(3) + 0.5) / 3)  # scaled by the aspect ratio 3/5
    expected = 3.0 * np.sqrt(1 + sx[None, :] ** 2 + sy[:, None] ** 2)
    assert np.allclose(depth, expected, rtol=4 * 2**-24)


def test_fov_axis_y_matches_the_oracle():
    camera = pyclray.Camera((1, 2, 6), (0, 0.5, 0), (0, 1, 0), 40, "y")
    scene = pyclray.Scene(camera, pyclray.Image(48, 80), (Plane((0, 1, 0), 0.0), Sphere((0, 1, 0), 1.0)))
    assert_matches_oracle(scene)


def test_exact_ties_go_to_the_lowest_id_run_after_run():
    shapes = (Sphere((0, 1, 0), 1.0, "b"), Plane((0, 1, 0), 0.0), Sphere((0, 1, 0), 1.0, "a"), Plane((0, 5, 0), 0.0))
    scene = pyclray.Scene(pyclray.Camera((0, 2, 6), (0, 0.5, 0)), pyclray.Image(48, 48), shapes)
    frames = [pyclray.render(scene) for _ in range(3)]
    ids = frames[0]["id"]
    assert set(np.unique(ids)) <= {-1, 0, 1}  # the copies (ids 2 and 3) never win
    assert (ids == 0).sum() > 100 and (ids == 1).sum() > 100
    for other in frames[1:]:
        for name in frames[0]:
            assert np.array_equal(frames[0][name], other[name])
    # reversed order: the copies now have the lower ids (the plane 0, the sphere 1) and win
    reversed_scene = pyclray.Scene(scene.camera, scene.image, shapes[::-1])
    assert np.array_equal(pyclray.render(reversed_scene)["id"], np.select([ids == 0, ids == 1], [1, 0], -1))


def test_camera_inside_a_sphere_sees_the_far_side_with_outward_normals():
    scene = pyclray.Scene(pyclray.Camera((0, 0, 0), (0, 0, -1)), pyclray.Image(9, 9), (Sphere((0, 0, 0), 2.0),))
    frame = pyclray.render(scene)
    assert np.all(frame["id"] == 0)
    assert np.allclose(frame["depth"], 2.0, rtol=2**-22)
    _, directions = oracle.camera_rays(scene)
    # outward normal = the ray direction (the camera is at the centre): not flipped toward the eye
    assert np.allclose(frame["normal"], directions, atol=1e-6)


def test_plane_normals_are_the_given_normal_normalized_and_never_flipped():
    scene = pyclray.Scene(pyclray.Camera((0, -2, 0), (0, 0, -5)), pyclray.Image(8, 8), (Plane((0, 3, 0), -3.0),))
    frame = pyclray.render(scene)  # the eye is below the plane y = 1, looking up at it
    hit = frame["id"] == 0
    assert hit.sum() > 10
    assert np.array_equal(frame["normal"][hit], np.tile(np.float32([0, 1, 0]), (hit.sum(), 1)))


# -- what is compiled --------------------------------------------------------------------------
def test_only_the_shape_types_present_are_compiled():
    source = Variant("render", ("sphere",), ("depth",), "fp32").source()
    assert "sphere_hit" in source and "plane_hit" not in source and "Plane" not in source
    source = Variant("render", ("plane",), ("depth", "normal", "id"), "fp32").source()
    assert "plane_hit" in source and "sphere_hit" not in source


def test_a_depth_only_request_has_no_normal_or_id_buffer():
    ctx = context_for()
    from pyclray.engine.launch.programs import kernel_for

    depth_only = kernel_for(ctx, Variant("render", ("plane", "sphere"), ("depth",), "fp32"))
    everything = kernel_for(ctx, Variant("render", ("plane", "sphere"), ("depth", "normal", "id"), "fp32"))
    import pyopencl as cl

    names = lambda k: [k.get_arg_info(i, cl.kernel_arg_info.NAME) for i in range(k.num_args)]  # noqa: E731
    try:
        assert "normal_out" not in names(depth_only) and "id_out" not in names(depth_only)
        assert "normal_out" in names(everything) and "id_out" in names(everything)
    except cl.Error:  # argument info needs -cl-kernel-arg-info on some drivers: count instead
        pass
    assert everything.num_args - depth_only.num_args == 2
    defines = Variant("render", ("sphere",), ("depth",), "fp32").defines()
    assert "#define PYCLRAY_AOV_NORMAL 1" not in defines and "#define PYCLRAY_AOV_DEPTH 1" in defines


def test_fewer_aovs_give_the_same_values():
    scene = small(pyclray.load_scene("scenes/tp02.toml"), 64)
    full = pyclray.render(scene)
    for aovs in (("depth",), ("normal",), ("id",), ("depth", "id"), ("id", "normal")):
        part = pyclray.render(scene, aovs=aovs)
        assert set(part) == set(aovs)
        for name in aovs:
            assert np.array_equal(part[name], full[name]), name


def test_moving_the_camera_or_a_shape_never_recompiles():
    scene = small(pyclray.load_scene("scenes/tp02.toml"), 32)
    pyclray.render(scene)
    compiled = stats["compiled"] + stats["from_disk"]
    moved = pyclray.Scene(
        pyclray.Camera((1, 3, 5), (0.2, 0.4, 0)), scene.image,
        (Plane((0, 1, 0.1), 0.5),) + tuple(Sphere(tuple(np.add(s.center, 0.3)), s.radius * 1.1) for s in scene.shapes[1:]),
    )
    frame = pyclray.render(moved)
    assert stats["compiled"] + stats["from_disk"] == compiled
    assert_matches_oracle(moved, frame)


CROSS_PROCESS = """
import json, pyclray
from pyclray.engine.launch.programs import stats
pyclray.render(pyclray.load_scene("scenes/tp02.toml").with_size(16, 16))
print(json.dumps(stats))
"""


def test_a_second_process_loads_the_program_from_the_disk_cache(tmp_path):
    import json
    import os

    env = dict(os.environ, PYCLRAY_CACHE_DIR=str(tmp_path / "cache"))
    runs = [json.loads(subprocess.run([sys.executable, "-c", CROSS_PROCESS], env=env, check=True,
                                      capture_output=True, text=True).stdout) for _ in range(2)]
    programs = runs[0]["compiled"]  # the rays kernel and the render kernel
    assert programs >= 1 and runs[0]["from_disk"] == 0
    assert runs[1]["compiled"] == 0 and runs[1]["from_disk"] == programs
    assert len(list((tmp_path / "cache").glob("*.bin"))) == programs


def test_fp64_unavailable_is_a_clear_error(monkeypatch):
    import importlib

    render_module = importlib.import_module("pyclray.engine.queries.requests")  # the module, not the function
    monkeypatch.setattr(render_module, "has_fp64", lambda device: False)
    scene = small(pyclray.load_scene("scenes/tp02.toml"), 8)
    with pytest.raises(pyclray.DeviceError, match="cl_khr_fp64"):
        pyclray.render(scene, precision="fp64")


@pytest.mark.parametrize("aovs", [(), ("depth", "depth"), ("colour",)])
def test_bad_aov_requests(aovs):
    scene = small(pyclray.load_scene("scenes/tp02.toml"), 8)
    with pytest.raises(pyclray.PyclrayError, match="aovs"):
        pyclray.render(scene, aovs=aovs)
    with pytest.raises(pyclray.PyclrayError, match="precision"):
        pyclray.render(scene, precision="fp16")


def test_device_selection():
    from pyclray.engine.opencl.device import select_device

    default = select_device()
    if os.environ.get("PYOPENCL_CTX"):  # the user's choice wins (the suite run on another device)
        assert default.int_ptr == select_device(os.environ["PYOPENCL_CTX"]).int_ptr
    else:
        assert "portable computing language" in default.platform.name.lower()
    assert select_device("0:0").int_ptr == select_device("0").int_ptr
    assert select_device(default.name.strip()[:6]).int_ptr == default.int_ptr
    with pytest.raises(pyclray.DeviceError, match="no OpenCL device matches"):
        select_device("9:9")
    assert any(d["default"] for d in pyclray.list_devices())


# -- hardening (issue 14) ---------------------------------------------------------------------------
def test_huge_geometry_renders_right_in_fp64_and_at_the_fp32_limit():
    """Defect 3: what fp32 refuses, fp64 renders as the oracle does (a ground sphere of radius
    2e19 under the camera, as in the SceneError's advice); and fp32 renders geometry up to its
    limit (4.6e18) exactly too, without a numpy warning. Same tolerances as above."""
    import warnings

    camera = pyclray.Camera((0.0, 2.0, 6.0), (0.0, 0.5, 0.0))
    ground = pyclray.Scene(camera, pyclray.Image(48, 48), (Sphere((0.0, -2e19, 0.0), 2e19), Sphere((0.0, 1.0, 0.0), 1.0)))
    near_limit = pyclray.Scene(camera, pyclray.Image(48, 48), (Sphere((0.0, -4e18, 0.0), 4e18), Sphere((0.0, 1.0, 0.0), 1.0)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(pyclray.SceneError, match="fp64 is needed"):
            pyclray.render(ground)
        if has_fp64(context_for(None).device):
            result = assert_matches_oracle(ground, precision="fp64")
            assert result["pixels"] > 1000
        result = assert_matches_oracle(near_limit)
        assert result["pixels"] > 1000


def test_the_ball_cut_by_the_image_border_is_cut_by_it(scenes_dir):
    """Defect 6: scenes/room.toml says one ball is cut by the image border; it appeared in no pixel."""
    scene = pyclray.load_scene(scenes_dir / "room.toml")
    assert "cut by the right border" in (scenes_dir / "room.toml").read_text()
    edge = next(i for i, shape in enumerate(scene.shapes) if shape.name == "edge")
    ids = pyclray.render(scene, aovs=("id",))["id"]
    mine = ids == edge
    assert mine.sum() > 1000 and mine[:, -1].sum() > 50  # seen, and running into the right border
    assert not mine[:, 0].any() and not mine[0].any() and not mine[-1].any()


def test_renders_from_several_threads_are_those_of_one_thread(scenes_dir):
    """Renders of one program variant share its kernel object, whose arguments OpenCL does not guard:
    threads rendering different cameras at once (a Dask worker with several threads) must each get
    their own scene's images (device.launch sets the arguments and enqueues under one lock)."""
    import threading
    from dataclasses import replace

    base = pyclray.load_scene(scenes_dir / "tp02.toml").with_size(48, 40)
    scenes = [replace(base, camera=replace(base.camera, eye=(0.5 * k, 2.0 + 0.3 * k, 6.0 - 0.2 * k))) for k in range(4)]
    expected = [pyclray.render(scene) for scene in scenes]
    wrong = []

    def work(k):
        for _ in range(40):
            frame = pyclray.render(scenes[k])
            if any(frame[a].tobytes() != expected[k][a].tobytes() for a in ("depth", "normal", "id")):
                wrong.append(k)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not wrong


def test_more_shapes_than_the_kernels_can_index_is_a_scene_error(scenes_dir, monkeypatch):
    """A shape is 8 x its index + its type in a 32-bit int on the device (BVH refs, winner keys):
    beyond that the render refuses with a clear error instead of wrapping around (the limit,
    268 million shapes, is lowered here to tp02's four)."""
    import pyclray

    from pyclray.model import scene as scene_module

    monkeypatch.setattr(scene_module, "MAX_SHAPES", 3)
    scene = pyclray.load_scene(scenes_dir / "tp02.toml")
    with pytest.raises(pyclray.SceneError, match="4 shapes; pyclray renders at most 3"):
        pyclray.render(scene)
    if has_fp64(context_for(None).device):
        with pytest.raises(pyclray.SceneError, match="4 shapes; pyclray renders at most 3"):
            pyclray.cast(scene, (0, 2, 6), (0, 0, -1))
