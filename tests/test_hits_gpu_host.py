"""count_hits and all_hits (engine/queries/hits.py) on a device of the GPU class, forced on PoCL by
$PYCLRAY_GPU_CLASS=1: host arrays uploaded once, checked on the device by cast's check kernel, the
hits' rows put in their CSR places on the device (engine/queries/cast_device.py: HitRays,
all_hits_device), with no per-ray ordering or checks on the host. The same kernels trace each ray on
its own from the same float64 origin and direction, and each ray's hits are its own in any order, so
every result (counts, offsets, ray, each AOV) is compared bit for bit with the CPU's host path on the
same handle; bad rays raise the same one line."""
import numpy as np
import pytest

import pyclray
from pyclray.engine.queries import cast as cast_module
from pyclray.engine.queries import hits as hits_module
from pyclray.engine.queries import ray_order
from pyclray.engine.queries.hits import CAPACITY, HIT_AOVS

from test_cast_blocks import rays
from test_cast_device import labelled_scene, same
from test_cast_gpu_host import both, lines_on_both


def stacked_scene():
    """labelled_scene with ten concentric spheres around the meshes: a ray through them has more than
    CAPACITY hits (all_hits' second pass)."""
    scene = labelled_scene()
    shells = pyclray.Spheres(np.zeros((10, 3)), np.linspace(2.0, 2.9, 10), name="shells")
    return pyclray.Scene(scene.camera, scene.image, scene.shapes + (shells,))


@pytest.fixture(scope="module", params=["fp32", "fp64"])
def tracer(request):
    with pyclray.prepare(stacked_scene(), precision=request.param) as handle:
        yield handle


def same_frames(got, expected):
    assert set(got) == set(expected)
    for name in expected:
        same(got[name], expected[name])


@pytest.mark.parametrize("count", [1, 7, 1000, 5000])  # 5000: the host path's compiled checks and ray order
def test_the_gpu_class_gives_the_host_paths_bits(tracer, monkeypatch, count):
    origins, directions = rays(count, 40 + count)
    origins *= 2.0  # some from outside the shells, some from within
    host, gpu = both(monkeypatch, lambda: tracer.count_hits(origins, directions))
    same(gpu, host)
    host, gpu = both(monkeypatch, lambda: tracer.all_hits(origins, directions, aovs=HIT_AOVS))
    same_frames(gpu, host)
    same(np.diff(host["offsets"]).astype(np.int32), tracer.count_hits(origins, directions))
    if count >= 1000:  # rays of no hits, of a few, and of more than the first pass's room
        counts = np.diff(host["offsets"])
        assert (counts == 0).sum() > 5 and (counts > CAPACITY).sum() > 10 and ((counts > 0) & (counts <= CAPACITY)).sum() > 100


def test_distances_shapes_and_one_origin(tracer, monkeypatch):
    """Per-ray and one-number tmin and tmax, one origin for every ray (the second pass too), a
    (2, N) leading shape, float32 rays, a list of one ray, one ray of shape (3,), and no rays."""
    _, directions = rays(600, 41)
    directions = directions.reshape(2, 300, 3)
    origin = np.array([0.3, -0.2, 3.5])
    tmin = np.linspace(0.0, 1.0, 600).reshape(2, 300)
    tmax = np.linspace(4.0, 8.0, 600).reshape(2, 300)
    arguments = [
        (origin, directions, tmin, tmax),
        (origin, directions, 0.5, 6.0),
        (origin.astype(np.float32), directions.astype(np.float32), 0.0, None),
        ([[0.0, 0.0, 3.5]], [[0.0, 0.1, -1.0]], 0.0, None),
        (np.array([0.0, 0.0, 3.5]), np.array([0.0, 0.1, -1.0]), 0.0, None),
        (np.zeros((0, 3)), np.zeros((0, 3)), 0.0, None),
    ]
    for o, d, lo, hi in arguments:
        host, gpu = both(monkeypatch, lambda: tracer.count_hits(o, d, tmin=lo, tmax=hi))
        same(np.asarray(gpu)[None], np.asarray(host)[None])  # (a leading axis: 0-d arrays too)
        host, gpu = both(monkeypatch, lambda: tracer.all_hits(o, d, tmin=lo, tmax=hi, aovs=HIT_AOVS))
        same_frames(gpu, host)
    assert (np.diff(host["offsets"]) >= 0).all()


@pytest.mark.parametrize("count", [10, 5000, 70000])  # the host path's checks: numpy's, numba's; the device check's loop
@pytest.mark.parametrize("bad, message", [
    (lambda o, d: (o, np.where(np.arange(len(d))[:, None] == 5, np.nan, d)), "directions: row 5 is not finite"),
    (lambda o, d: (o, np.where(np.arange(len(d))[:, None] == 2, 0.0, d)), "directions: row 2 has zero length"),
    (lambda o, d: (np.where(np.arange(len(o))[:, None] == 3, np.inf, o), d), "origins: row 3 is not finite"),
    (lambda o, d: (np.where(np.arange(len(o))[:, None] == 4, 1e300, o), d), "origins: row 4"),
    (lambda o, d: (np.array([np.nan, 0.0, 0.0]), d), "origins: row 0 is not finite"),
    (lambda o, d: (np.array([1e300, 0.0, 0.0]), d), "origins: row 0"),
])
def test_bad_rays_raise_the_host_paths_line(tracer, monkeypatch, count, bad, message):
    origins, directions = bad(*rays(count, 42))
    for query in (lambda: tracer.count_hits(origins, directions), lambda: tracer.all_hits(origins, directions)):
        errors = lines_on_both(monkeypatch, query, message)
        assert errors[0] == errors[1] and "\n" not in errors[0]


def test_bad_arguments_raise_the_host_paths_line(tracer, monkeypatch):
    origins, directions = rays(8, 43)
    cases = [
        (lambda: tracer.count_hits(origins, directions, tmax=np.r_[1.0, -1.0, np.ones(6)]), "tmax: expected numbers > 0"),
        (lambda: tracer.all_hits(origins, directions, tmin=-1.0), "tmin: expected finite numbers >= 0"),
        (lambda: tracer.all_hits(origins[:3], directions), "origins: expected shape"),
        (lambda: tracer.count_hits(origins, directions[:, :2]), r"directions: expected an array of shape \(\.\.\., 3\)"),
        (lambda: tracer.all_hits(origins, "rays"), "directions: expected an array"),
        # a bad ray and a bad distance: the ray's line first, as on the host
        (lambda: tracer.count_hits(origins, np.where(np.arange(8)[:, None] == 3, np.nan, directions), tmax=-1.0),
         "directions: row 3 is not finite"),
        (lambda: tracer.all_hits(np.array([np.inf, 0.0, 0.0]), directions, tmin=np.inf), "origins: row 0 is not finite"),
    ]
    for call, message in cases:
        errors = lines_on_both(monkeypatch, call, message)
        assert errors[0] == errors[1]


def test_no_per_ray_host_work_on_the_gpu_class(tracer, monkeypatch):
    """On the GPU class the host's per-ray steps (the checks and codes, compiled or numpy's, the
    origins' box, the ray order, the host path's batch and its rows' gathering) are never called:
    each is made to raise, and the queries of small and large batches still give the same bits."""
    def forbidden(*args, **kwargs):
        raise AssertionError("per-ray host work on the GPU class")

    origins, directions = rays(5000, 44)
    origins *= 2.0
    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
    counts = tracer.count_hits(origins, directions)
    expected = [tracer.all_hits(origins[:n], directions[:n], aovs=HIT_AOVS) for n in (1, 1000, 5000)]
    for module, name in [(ray_order, "scan_codes"), (ray_order, "coherent_order"), (ray_order, "_counting_sort"),
                         (cast_module, "_cast_rays"), (cast_module, "_columns_extent"), (cast_module, "RayBatch"),
                         (hits_module, "RayBatch"), (hits_module, "_stored"), (hits_module, "_gather")]:
        monkeypatch.setattr(module, name, forbidden)
    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "1")
    for n, frame in zip((1, 1000, 5000), expected):
        same(tracer.count_hits(origins[:n], directions[:n]), counts[:n])
        same_frames(tracer.all_hits(origins[:n], directions[:n], aovs=HIT_AOVS), frame)


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_at_lane_width_one(monkeypatch, precision):
    """The program a GPU builds (PYCLRAY_LANES=1: the pair nodes, one ray per work-item) on the GPU
    class's host path: the bits of the CPU's host path at the CPU's own lane width."""
    origins, directions = rays(3000, 45)
    origins *= 2.0
    with pyclray.prepare(stacked_scene(), precision=precision) as handle:
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
        counts = handle.count_hits(origins, directions)
        expected = handle.all_hits(origins, directions, aovs=HIT_AOVS)
    monkeypatch.setenv("PYCLRAY_LANES", "1")
    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "1")
    with pyclray.prepare(stacked_scene(), precision=precision) as handle:
        same(handle.count_hits(origins, directions), counts)
        same_frames(handle.all_hits(origins, directions, aovs=HIT_AOVS), expected)
    assert (counts > CAPACITY).sum() > 10


@pytest.mark.parametrize("switch", ["0", "1"])  # the CPU's class and the GPU's: device rays take the device path on both
def test_device_rays(tracer, monkeypatch, switch):
    """Rays given as pyopencl arrays (float64 and float32, one origin or one each, either array on the
    device): the bits of the same rays given as host arrays (float32 rays: their exact float64
    widening) on the CPU's host path; a bad device ray the host path's line."""
    import pyopencl.array as cl_array

    queue = tracer.ctx.queue
    origins, directions = rays(3000, 46)
    origins *= 2.0
    origin = np.array([0.2, 0.1, 3.5])
    cases = [(origins, directions, np.float64), (origins, directions, np.float32), (origin, directions, np.float64)]
    for o, d, dtype in cases:
        o, d = o.astype(dtype), d.astype(dtype)
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
        counts = tracer.count_hits(o, d, tmax=np.linspace(3.0, 9.0, len(d)))
        expected = tracer.all_hits(o, d, tmax=np.linspace(3.0, 9.0, len(d)), aovs=HIT_AOVS)
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", switch)
        for given in [(cl_array.to_device(queue, o), cl_array.to_device(queue, d)), (o, cl_array.to_device(queue, d)),
                      (cl_array.to_device(queue, o), d)]:
            same(tracer.count_hits(*given, tmax=np.linspace(3.0, 9.0, len(d))), counts)
            same_frames(tracer.all_hits(*given, tmax=np.linspace(3.0, 9.0, len(d)), aovs=HIT_AOVS), expected)
        assert (counts > CAPACITY).sum() > 10  # the second pass's rays (read back from the device)
    bad = np.where(np.arange(3000)[:, None] == 17, np.nan, directions)
    for query in ("count_hits", "all_hits"):
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
        with pytest.raises(pyclray.RequestError) as host_error:
            getattr(tracer, query)(origins, bad)
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", switch)
        with pytest.raises(pyclray.RequestError) as device_error:
            getattr(tracer, query)(cl_array.to_device(queue, origins), cl_array.to_device(queue, bad))
        assert str(device_error.value) == str(host_error.value) and "row 17" in str(host_error.value)
        with pytest.raises(pyclray.RequestError) as device_error:  # a bad ray before a bad distance, as on the host
            getattr(tracer, query)(cl_array.to_device(queue, origins), cl_array.to_device(queue, bad), tmin=-1.0)
        assert str(device_error.value) == str(host_error.value)
