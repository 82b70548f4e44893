"""The host path of a cast on a device of the GPU class (engine/opencl/device.py: gpu_class), forced
on PoCL by $PYCLRAY_GPU_CLASS=1: host arrays are uploaded once, checked on the device and cast in
their order (engine/queries/cast_device.py), with no per-ray work on the host. The same kernel traces
each ray on its own from the same float64 origin and direction, and the derived AOVs (primitive,
label, position) are the same operations on the device, so every result is compared bit for bit with
the CPU's host path (engine/queries/cast.py) on the same handle; bad rays raise the same one line."""
import numpy as np
import pyopencl as cl
import pytest

import pyclray
from pyclray.engine.opencl.device import gpu_class
from pyclray.engine.queries import cast as cast_module
from pyclray.engine.queries import ray_order
from pyclray.model.aovs import CAST_AOVS

from test_cast_blocks import rays
from test_cast_device import labelled_scene, same


@pytest.fixture(scope="module", params=["fp32", "fp64"])
def tracer(request):
    with pyclray.prepare(labelled_scene(), precision=request.param) as handle:
        yield handle


def both(monkeypatch, call):
    """call() on the CPU's host path, then on the GPU class's."""
    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
    host = call()
    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "1")
    return host, call()


def lines_on_both(monkeypatch, call, pattern) -> list:
    """The RequestError line of call() on the CPU's host path, then on the GPU class's: each must
    raise, its line matching pattern."""
    lines = []
    for switch in ("0", "1"):
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", switch)
        with pytest.raises(pyclray.RequestError, match=pattern) as error:
            call()
        lines.append(str(error.value))
    return lines


@pytest.mark.parametrize("count", [1, 7, 1000, 5000])  # 5000: the host path's compiled checks (COHERENT_FROM)
def test_the_gpu_class_gives_the_host_paths_bits(tracer, monkeypatch, count):
    origins, directions = rays(count, 20 + count)
    host, gpu = both(monkeypatch, lambda: tracer.cast(origins, directions, aovs=CAST_AOVS))
    assert set(gpu) == set(host) == set(CAST_AOVS)
    for name in CAST_AOVS:
        same(gpu[name], host[name])
    if count >= 1000:
        assert (host["id"] >= 0).sum() > count / 2 and (host["id"] < 0).sum() > 10  # hits and misses both
        assert len(set(host["label"].tolist())) >= 3
    host, gpu = both(monkeypatch, lambda: tracer.occluded(origins, directions))
    same(gpu, host)


def test_distances_shapes_and_one_origin(tracer, monkeypatch):
    """Per-ray and one-number tmin and tmax, one origin for every ray, a (2, N) leading shape, float32
    rays, a list of one ray, and no rays at all."""
    _, directions = rays(600, 21)
    directions = directions.reshape(2, 300, 3)
    origin = np.array([0.3, -0.2, 2.5])
    tmin = np.linspace(0.0, 1.0, 600).reshape(2, 300)
    tmax = np.linspace(2.0, 6.0, 600).reshape(2, 300)
    calls = [
        lambda: tracer.cast(origin, directions, aovs=CAST_AOVS, tmin=tmin, tmax=tmax),
        lambda: tracer.cast(origin, directions, aovs=CAST_AOVS, tmin=0.5, tmax=3.0),
        lambda: tracer.cast(origin.astype(np.float32), directions.astype(np.float32), aovs=CAST_AOVS),
        lambda: tracer.cast([[0.0, 0.0, 3.0]], [[0.0, 0.0, -1.0]], aovs=CAST_AOVS),
        lambda: tracer.cast(np.zeros((0, 3)), np.zeros((0, 3)), aovs=CAST_AOVS),
        lambda: tracer.cast(np.array([0.0, 0.0, 3.0]), np.array([0.0, 0.1, -1.0]), aovs=CAST_AOVS),  # shape ()
        lambda: {k: v.get() for k, v in tracer.cast(np.array([0.0, 0.0, 3.0]), np.array([0.0, 0.1, -1.0]),
                                                     aovs=CAST_AOVS, out="device").items()},
        lambda: {"occluded": tracer.occluded(np.array([0.0, 0.0, 3.0]), np.array([0.0, 0.1, -1.0]))},
        lambda: {"occluded": tracer.occluded(origin, directions, tmin=tmin, tmax=tmax)},
        lambda: {"occluded": tracer.occluded(origin, directions, tmax=2.5)},
    ]
    for call in calls:
        host, gpu = both(monkeypatch, call)
        assert set(gpu) == set(host)
        for name in host:
            same(np.asarray(gpu[name])[None], np.asarray(host[name])[None])  # (a leading axis: 0-d arrays too)


@pytest.mark.parametrize("count", [10, 100, 5000, 70000])  # the host path's checks: Python's floats, numpy's, numba's; the device check's loop
@pytest.mark.parametrize("bad, message", [
    (lambda o, d: (o, np.where(np.arange(len(d))[:, None] == 5, np.nan, d)), "directions: row 5 is not finite"),
    (lambda o, d: (o, np.where(np.arange(len(d))[:, None] == 2, 0.0, d)), "directions: row 2 has zero length"),
    (lambda o, d: (np.where(np.arange(len(o))[:, None] == 3, np.inf, o), d), "origins: row 3 is not finite"),
    (lambda o, d: (np.where(np.arange(len(o))[:, None] == 4, 1e300, o), d), "origins: row 4"),
    (lambda o, d: (np.array([np.nan, 0.0, 0.0]), d), "origins: row 0 is not finite"),
    (lambda o, d: (o, np.where(np.arange(len(d))[:, None] == len(d) - 1, np.inf, d)),  # the check's last group
     r"directions: row (9|99|4999|69999) is not finite"),
    (lambda o, d: (np.array([1e300, 0.0, 0.0]), d), "origins: row 0"),
])
def test_bad_rays_raise_the_host_paths_line(tracer, monkeypatch, count, bad, message):
    origins, directions = bad(*rays(count, 22))
    for query in (lambda: tracer.cast(origins, directions), lambda: tracer.occluded(origins, directions)):
        errors = lines_on_both(monkeypatch, query, message if "|" in message else message.replace("(", r"\("))
        assert errors[0] == errors[1] and "\n" not in errors[0]
    # the handle's kept buffers, which the device's check repaired, serve the next cast as before
    good_origins, good_directions = rays(count, 23)
    host, gpu = both(monkeypatch, lambda: tracer.cast(good_origins, good_directions))
    for name in host:
        same(gpu[name], host[name])


def test_bad_arguments_raise_the_host_paths_line(tracer, monkeypatch):
    origins, directions = rays(8, 24)
    cases = [
        (lambda: tracer.cast(origins, directions, tmax=np.r_[1.0, -1.0, np.ones(6)]), "tmax: expected numbers > 0"),
        (lambda: tracer.cast(origins, directions, tmin=-1.0), "tmin: expected finite numbers >= 0"),
        (lambda: tracer.cast(origins[:3], directions), "origins: expected shape"),
        (lambda: tracer.cast(origins, directions[:, :2]), r"directions: expected an array of shape \(\.\.\., 3\)"),
        (lambda: tracer.cast(origins, "rays"), "directions: expected an array"),
        # a bad ray and a bad distance: the ray's line first, as on the host
        (lambda: tracer.cast(origins, np.where(np.arange(8)[:, None] == 3, np.nan, directions), tmax=-1.0),
         "directions: row 3 is not finite"),
        (lambda: tracer.occluded(np.array([np.inf, 0.0, 0.0]), directions, tmin=np.inf), "origins: row 0 is not finite"),
    ]
    for call, message in cases:
        errors = lines_on_both(monkeypatch, call, message)
        assert errors[0] == errors[1]


def test_no_per_ray_host_work_on_the_gpu_class(tracer, monkeypatch):
    """On the GPU class the host's per-ray steps (the checks and codes, compiled or numpy's, the
    origins' box, the ray order, the host path's batch and its positions and primitives) are never
    called: each is made to raise, and casts of small and large batches still succeed."""
    def forbidden(*args, **kwargs):
        raise AssertionError("per-ray host work on the GPU class")

    origins, directions = rays(5000, 25)
    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
    expected = tracer.cast(origins, directions, aovs=CAST_AOVS)
    for module, name in [(ray_order, "scan_codes"), (ray_order, "coherent_order"), (ray_order, "_counting_sort"),
                         (cast_module, "_cast_rays"), (cast_module, "_columns_extent"), (cast_module, "RayBatch"),
                         (cast_module, "_block_primitives"), (cast_module, "label_of"), (cast_module, "run_cast")]:
        monkeypatch.setattr(module, name, forbidden)
    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "1")
    for count in (1, 1000, 5000):
        frame = tracer.cast(origins[:count], directions[:count], aovs=CAST_AOVS)
        for name in CAST_AOVS:
            same(frame[name], expected[name][:count])
        tracer.occluded(origins[:count], directions[:count])


def test_the_switch():
    from pyclray.engine.opencl.device import context_for

    device = context_for(None).device
    with pytest.MonkeyPatch.context() as patch:
        patch.delenv("PYCLRAY_GPU_CLASS", raising=False)
        assert gpu_class(device) is (not device.type & cl.device_type.CPU)  # its type (PoCL's CPU device: False)
        patch.setenv("PYCLRAY_GPU_CLASS", "1")
        assert gpu_class(device) is True
        patch.setenv("PYCLRAY_GPU_CLASS", "yes")
        with pytest.raises(pyclray.DeviceError, match="PYCLRAY_GPU_CLASS: expected 1"):
            gpu_class(device)


def test_buffers_that_are_not_host_memory(monkeypatch):
    """As on a GPU: the kept buffers are device memory (copies enqueued in, out behind the kernels,
    one wait), on a fresh handle told so; the same bits, and a bad ray the same line."""
    from pyclray.engine.opencl import buffers
    from pyclray.engine.queries import cast_device

    scene = labelled_scene()
    origins, directions = rays(3000, 26)
    with pyclray.prepare(scene) as handle:
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
        expected = handle.cast(origins, directions, aovs=CAST_AOVS)
        occluded = handle.occluded(origins, directions)
        with pytest.raises(pyclray.RequestError) as host_error:
            handle.cast(origins, np.where(np.arange(3000)[:, None] == 7, 0.0, directions))
    monkeypatch.setattr(buffers, "shares_host_memory", lambda ctx: False)
    monkeypatch.setattr(cast_device, "shares_host_memory", lambda ctx: False)
    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "1")
    with pyclray.prepare(scene) as handle:
        for count in (3000, 2, 900):
            frame = handle.cast(origins[:count], directions[:count], aovs=CAST_AOVS)
            for name in CAST_AOVS:
                same(frame[name], expected[name][:count])
            same(handle.occluded(origins[:count], directions[:count]), occluded[:count])
        with pytest.raises(pyclray.RequestError) as device_error:
            handle.cast(origins, np.where(np.arange(3000)[:, None] == 7, 0.0, directions))
        assert str(device_error.value) == str(host_error.value)
        assert all(host is None for _, host in handle.ray_buffers.buffers.values())


@pytest.mark.parametrize("count", [3, 100, 5000])  # the host path's checks: Python's floats, numpy's, numba's
def test_extreme_fine_rays_pass_every_check(tracer, monkeypatch, count):
    """Rays the checks must pass (a direction of huge, of subnormal and of mixed magnitudes, whose sum
    of magnitudes overflows or underflows nothing it must not; an origin far from the scene but within
    the precision's bound): each row's result is its own, whatever the batch and its checks' path."""
    origins, directions = rays(count, 27)
    directions[0] = (1e308, -1e308, 1e308)
    directions[1] = (5e-324, 0.0, -5e-324)
    directions[2] = (0.0, 0.0, -1e-300)
    origins[2] = (0.0, 0.0, 1e15)
    host, gpu = both(monkeypatch, lambda: tracer.cast(origins, directions, aovs=CAST_AOVS))
    one = [tracer.cast(origins[i], directions[i:i + 1], aovs=CAST_AOVS) for i in range(3)]
    for name in CAST_AOVS:
        same(gpu[name], host[name])
        for i in range(3):
            same(host[name][i:i + 1], one[i][name])
    assert host["id"][2] >= 0  # the far origin's ray hits the scene


def test_a_subnormal_direction_gives_its_unit_directions_position(tracer, monkeypatch):
    """(0, 0, -1e-320) is (0, 0, -1) once scaled by the kernel's power of two (2^1023 for a subnormal
    largest magnitude): its depth, normal and position are those bits, on either host path (the
    position's scale once overflowed to inf on the host: NaN positions)."""
    origins = np.array([[0.0, 0.0, 3.0], [-1.0, 0.1, 2.0]])
    tiny = np.array([[0.0, 0.0, -1e-320], [5e-324, 0.0, -5e-324]])
    unit = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, -1.0]])
    for switch in ("0", "1"):
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", switch)
        got = tracer.cast(origins, tiny, aovs=CAST_AOVS)
        expected = tracer.cast(origins, unit, aovs=CAST_AOVS)
        for name in CAST_AOVS:
            same(got[name], expected[name])
        assert np.isfinite(got["depth"]).all() and np.isfinite(got["position"]).all()


def test_the_hit_queries_take_no_ray_order_on_the_gpu_class(tracer, monkeypatch):
    """count_hits and all_hits (engine/queries/hits.py) of a large batch, which the CPU casts in the
    coherent order, take none on the GPU class: the same hits (each ray's are its own)."""
    origins, directions = rays(5000, 28)
    host, gpu_counts = both(monkeypatch, lambda: tracer.count_hits(origins, directions))
    same(gpu_counts, host)

    def forbidden(*args, **kwargs):
        raise AssertionError("a ray order on the GPU class")

    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
    expected = tracer.all_hits(origins, directions)
    monkeypatch.setattr(ray_order, "coherent_order", forbidden)
    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "1")
    got = tracer.all_hits(origins, directions)
    for name in expected:
        same(got[name], expected[name])
    assert (host > 1).sum() > 100


def test_calls_in_turn_through_the_kept_regions(tracer, monkeypatch):
    """Calls of other counts and AOVs in turn, each cutting the kept results buffer anew
    (KeptBuffers.regions) or keeping the last cut: each gives the host path's bits, and the arrays of
    an earlier Frame are not overwritten by a later call."""
    calls = [(300, ("depth",)), (300, ("label", "position")), (40, CAST_AOVS), (300, ("depth",)), (2000, ("id", "normal")),
             (300, ("depth",))]
    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "1")
    frames = [tracer.cast(*rays(n, n), aovs=aovs) for n, aovs in calls]
    kept = [{k: v.copy() for k, v in frame.items()} for frame in frames]
    monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
    for (n, aovs), frame, copy in zip(calls, frames, kept):
        expected = tracer.cast(*rays(n, n), aovs=aovs)
        assert set(frame) == set(expected)
        for name in expected:
            same(frame[name], expected[name])
            same(copy[name], expected[name])
