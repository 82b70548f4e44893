"""A handle's cast and occluded of rays given as pyopencl arrays, and results left on the device
(out="device"; engine/queries/cast_device.py), and its small casts through kept buffers
(engine/opencl/buffers.py: KeptBuffers): each gives the bits of the host path's cast of the same rays
(the same kernel over the same float64 rays; the host's derived AOVs, primitive, label and position,
computed by device kernels in the same operations), so the tests compare bit for bit."""
from dataclasses import replace

import numpy as np
import pyopencl as cl
import pyopencl.array as cl_array
import pytest

import pyclray
from pyclray.engine.queries import cast as cast_module
from pyclray.model.aovs import CAST_AOVS

from test_cast_blocks import mixed_scene, rays


def labelled_scene():
    """mixed_scene with labels on some shapes (label's lookup) and none on others."""
    scene = mixed_scene()
    shapes = tuple(replace(shape, label=i + 3) if i % 2 == 0 else shape for i, shape in enumerate(scene.shapes))
    return pyclray.Scene(scene.camera, scene.image, shapes)


def same(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape
    assert np.array_equal(a.view(np.uint8), b.view(np.uint8))  # bits, NaN and signed zero included


@pytest.fixture(scope="module")
def tracer():
    with pyclray.prepare(mixed_scene()) as handle:
        yield handle


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("out", ["host", "device"])
def test_device_rays_give_the_host_paths_bits(tracer, dtype, out):
    origins, directions = rays(3000, 7)
    origins, directions = origins.astype(dtype), directions.astype(dtype)
    queue = tracer.ctx.queue
    expected = tracer.cast(origins, directions, aovs=CAST_AOVS)
    frame = tracer.cast(cl_array.to_device(queue, origins), cl_array.to_device(queue, directions), aovs=CAST_AOVS,
                        out=out)
    assert set(frame) == set(expected)
    for name in CAST_AOVS:
        got = frame[name]
        assert isinstance(got, cl_array.Array) == (out == "device")
        same(got.get() if out == "device" else got, expected[name])
    assert (expected["id"] >= 0).sum() > 1000 and (expected["id"] < 0).sum() > 50  # hits and misses both
    blocked = expected["primitive"][expected["id"] >= 0]
    assert blocked.min() >= 0  # every block's key was turned into its triangle's index
    occluded = tracer.occluded(cl_array.to_device(queue, origins), cl_array.to_device(queue, directions), out=out)
    same(occluded.get() if out == "device" else occluded, tracer.occluded(origins, directions))


def test_host_rays_with_device_results_and_one_shared_origin(tracer):
    """out="device" of host arrays; one origin for every ray; per-ray tmin and tmax; a (2, N) shape."""
    _, directions = rays(400, 8)
    directions = directions.reshape(2, 200, 3)
    origin = np.array([0.3, -0.2, 2.5])
    tmin = np.linspace(0.0, 1.0, 400).reshape(2, 200)
    tmax = np.linspace(2.0, 6.0, 400).reshape(2, 200)
    expected = tracer.cast(origin, directions, aovs=CAST_AOVS, tmin=tmin, tmax=tmax)
    frame = tracer.cast(origin, directions, aovs=CAST_AOVS, tmin=tmin, tmax=tmax, out="device")
    for name in CAST_AOVS:
        assert frame[name].shape == expected[name].shape
        same(frame[name].get(), expected[name])


def test_labels_on_the_device():
    scene = labelled_scene()
    origins, directions = rays(500, 9)
    with pyclray.prepare(scene) as handle:
        expected = handle.cast(origins, directions, aovs=("label", "id"))
        frame = handle.cast(origins, directions, aovs=("label", "id"), out="device")
        same(frame["label"].get(), expected["label"])
        assert len(set(expected["label"].tolist())) >= 3  # labels, and -1 for misses and unlabelled shapes


def test_no_rays_and_a_loop_on_the_device(tracer):
    queue = tracer.ctx.queue
    empty = tracer.cast(cl_array.empty(queue, (0, 3), np.float64), cl_array.empty(queue, (0, 3), np.float64),
                        out="device")
    assert empty["depth"].shape == (0,)
    # a loop that stays on the device: the hit points of one cast are the next cast's origins
    origins, directions = rays(256, 10)
    d_origins, d_directions = cl_array.to_device(queue, origins), cl_array.to_device(queue, directions)
    h_origins = origins
    for _ in range(3):
        frame = tracer.cast(d_origins, d_directions, aovs=("position", "depth"), out="device")
        expected = tracer.cast(h_origins, directions, aovs=("position", "depth"))
        same(frame["position"].get(), expected["position"].astype(np.float32))
        d_origins = frame["position"].astype(np.float64)
        h_origins = expected["position"].astype(np.float64)


@pytest.mark.parametrize("bad, message", [
    (lambda o, d: (o, np.where(np.arange(len(d))[:, None] == 5, np.nan, d)), "directions: row 5 is not finite"),
    (lambda o, d: (o, np.where(np.arange(len(d))[:, None] == 2, 0.0, d)), "directions: row 2 has zero length"),
    (lambda o, d: (np.where(np.arange(len(o))[:, None] == 3, np.inf, o), d), "origins: row 3 is not finite"),
    (lambda o, d: (np.where(np.arange(len(o))[:, None] == 4, 1e300, o), d), "origins: row 4"),
])
def test_bad_device_rays_are_refused_as_on_the_host(tracer, bad, message):
    origins, directions = bad(*rays(10, 11))
    queue = tracer.ctx.queue
    with pytest.raises(pyclray.RequestError, match=message.replace("(", r"\(")) as host:
        tracer.cast(origins, directions)
    with pytest.raises(pyclray.RequestError) as device:
        tracer.cast(cl_array.to_device(queue, origins), cl_array.to_device(queue, directions))
    assert str(device.value) == str(host.value)


def test_device_arrays_of_another_type_or_shape_and_a_bad_out(tracer):
    queue = tracer.ctx.queue
    origins, directions = rays(10, 12)
    with pytest.raises(pyclray.RequestError, match="directions: expected a device array of float32 or float64"):
        tracer.cast(origins, cl_array.to_device(queue, directions.astype(np.int32)))
    with pytest.raises(pyclray.RequestError, match=r"directions: expected an array of shape \(..., 3\)"):
        tracer.cast(origins, cl_array.to_device(queue, directions[:, :2].copy()))
    with pytest.raises(pyclray.RequestError, match="origins: expected shape"):
        tracer.cast(cl_array.to_device(queue, origins[:4].copy()), cl_array.to_device(queue, directions))
    with pytest.raises(pyclray.RequestError, match="out: expected one of host, device, got 'gpu'"):
        tracer.cast(origins, directions, out="gpu")
    other = cl.Context([tracer.ctx.device])
    with pytest.raises(pyclray.RequestError, match="directions: a pyopencl array on another context"):
        tracer.cast(origins, cl_array.to_device(cl.CommandQueue(other), directions))


def test_kept_buffers_grow_and_give_the_new_buffers_bits(tracer, monkeypatch):
    """Casts below KEPT_BELOW through the handle's kept buffers (a larger one after a smaller: they
    grow; a smaller after a larger: its rows only), against the same casts through new buffers."""
    sizes = (1, 700, 3, 2000, 5)
    kept = []
    for size in sizes:
        origins, directions = rays(size, size)
        kept.append((tracer.cast(origins, directions, aovs=CAST_AOVS), tracer.occluded(origins, directions)))
    assert tracer.ray_buffers.nbytes() > 0
    monkeypatch.setattr(cast_module, "KEPT_BELOW", 0)
    for size, (frame, occluded) in zip(sizes, kept):
        origins, directions = rays(size, size)
        expected = tracer.cast(origins, directions, aovs=CAST_AOVS)
        for name in CAST_AOVS:
            same(frame[name], expected[name])
        same(occluded, tracer.occluded(origins, directions))


def test_the_hit_queries_refuse_device_distances_clearly(tracer):
    """The hit queries take device rays (tests/test_hits_gpu_host.py), but tmin and tmax stay numbers
    or host arrays."""
    origins, directions = rays(10, 13)
    queue = tracer.ctx.queue
    with pytest.raises(pyclray.RequestError, match="tmax: expected a number or a numpy array"):
        tracer.all_hits(origins, cl_array.to_device(queue, directions), tmax=cl_array.to_device(queue, np.ones(10)))
    with pytest.raises(pyclray.RequestError, match="tmin: expected a number or a numpy array"):
        tracer.count_hits(cl_array.to_device(queue, origins), directions, tmin=cl_array.to_device(queue, np.ones(10)))


def test_kept_buffers_of_a_device_without_shared_memory(monkeypatch):
    """The kept buffers as on a GPU (copies enqueued in and out, every cast through them), on this
    device: a fresh handle whose buffers are told not to be host memory gives the same bits."""
    from pyclray.engine.opencl import buffers

    scene = mixed_scene()
    origins, directions = rays(5000, 14)
    with pyclray.prepare(scene) as handle:
        expected = handle.cast(origins, directions, aovs=CAST_AOVS)
        occluded = handle.occluded(origins, directions)
    monkeypatch.setattr(buffers, "shares_host_memory", lambda ctx: False)
    monkeypatch.setattr(cast_module, "shares_host_memory", lambda ctx: False)
    with pyclray.prepare(scene) as handle:
        for count in (5000, 3, 700):
            frame = handle.cast(origins[:count], directions[:count], aovs=CAST_AOVS)
            for name in CAST_AOVS:
                same(frame[name], expected[name][:count])
            same(handle.occluded(origins[:count], directions[:count]), occluded[:count])
        assert all(host is None for _, host in handle.ray_buffers.buffers.values())


def test_distances_stay_host_values(tracer):
    origins, directions = rays(4, 15)
    queue = tracer.ctx.queue
    with pytest.raises(pyclray.RequestError, match="tmax: expected a number or a numpy array"):
        tracer.cast(origins, cl_array.to_device(queue, directions), tmax=cl_array.to_device(queue, np.ones(4)))


def test_kernel_arguments_set_once_per_kept_buffers(monkeypatch):
    """A small cast's kernel keeps its arguments from call to call (engine/opencl/device.py:
    launch_kept): two handles of one variant's kernel (the same shape types, other shapes), casts of
    other counts and distances in turn, each gives the bits of the same cast through new buffers
    (every argument set); a repeated call sets none (the bare enqueue)."""
    from pyclray.engine.opencl import device

    scene = mixed_scene()
    moved = pyclray.Scene(scene.camera, scene.image,
                          tuple(replace(s, translate=(0.3, 0.1, 0.0)) if isinstance(s, pyclray.Mesh) else s
                                for s in scene.shapes))
    calls = [(0, 300, {}), (1, 300, {}), (0, 300, {"tmax": 2.0}), (1, 40, {"tmin": 0.5}), (0, 300, {}), (0, 300, {})]
    with pyclray.prepare(scene) as first, pyclray.prepare(moved) as second:
        handles = (first, second)
        bare = []
        enqueue = cl.enqueue_nd_range_kernel
        monkeypatch.setattr(device.cl, "enqueue_nd_range_kernel", lambda *a, **k: bare.append(1) or enqueue(*a, **k))
        got = [(handles[h].cast(*rays(n, n), aovs=CAST_AOVS, **kw), handles[h].occluded(*rays(n, n), **kw))
               for h, n, kw in calls]
        assert len(bare) >= 2  # the last call's cast and occluded: nothing changed since the one before
        monkeypatch.setattr(cast_module, "KEPT_BELOW", 0)
        for (h, n, kw), (frame, occluded) in zip(calls, got):
            expected = handles[h].cast(*rays(n, n), aovs=CAST_AOVS, **kw)
            for name in CAST_AOVS:
                same(frame[name], expected[name])
            same(occluded, handles[h].occluded(*rays(n, n), **kw))
        assert not np.array_equal(got[0][0]["depth"], got[1][0]["depth"])  # the handles' shapes differ


def test_a_large_cast_between_small_ones_leaves_them_right(monkeypatch):
    """A large cast (new buffers, every argument set by launch) between two equal small ones (kept
    buffers, launch_kept): the second small one sets its arguments again, and gives the first's bits."""
    monkeypatch.setattr(cast_module, "KEPT_BELOW", 512)  # a large cast of few rays
    small, large = rays(100, 17), rays(600, 18)
    with pyclray.prepare(mixed_scene()) as handle:
        first = handle.cast(*small, aovs=CAST_AOVS)
        big = handle.cast(*large, aovs=CAST_AOVS)
        again = handle.cast(*small, aovs=CAST_AOVS)
        for name in CAST_AOVS:
            same(again[name], first[name])
        assert not np.array_equal(big["depth"][:100], first["depth"])
