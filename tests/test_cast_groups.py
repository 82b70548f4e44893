"""cast and occluded trace CAST_GROUP (8) rays per work-item, their directions set up four at once in
vector registers, in work-groups of CAST_WORK_GROUP work-items (kernels/cast.cl, engine/queries/cast.py).
Each ray's computations are its own, so these hold the results to bits: of directions at the ends
of float64's range (the power of two that scales a direction before its length is taken is clamped
there), and of every place of a group and a work-group, batches ending anywhere."""
import numpy as np
import pytest

import pyclray
from pyclray.engine.queries import cast as cast_module

from test_cast import random_scene


def assert_same_bits(one, other):
    for name in pyclray.AOVS:
        np.testing.assert_array_equal(one[name], other[name])


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_directions_at_the_ends_of_the_range_give_the_same_bits(precision):
    """A direction whose largest component lies in [2^1023, max] (its 2^-e would be subnormal: the
    kernel scales by 2^-1022 instead; unclamped, the scale's bits are 0 and every ray a NaN), and
    subnormal directions (integers times 2^-1074: exact, the scale 2^1023), give the bits of the
    same directions of ordinary size: scaling by a power of two is exact."""
    scene, origins, directions = random_scene(3)
    ordinary = directions / np.abs(directions).max(axis=-1, keepdims=True) * 1.5  # largest 1.5
    huge = ordinary * 2.0**1023  # largest 1.5 * 2^1023: the top binade
    assert np.isfinite(huge).all() and (np.abs(huge).max(axis=-1) >= 2.0**1023).all()
    assert_same_bits(pyclray.cast(scene, origins, ordinary, precision=precision),
                     pyclray.cast(scene, origins, huge, precision=precision))
    whole = np.round(directions * 1000.0)  # integers up to a few thousand: exact as subnormals
    whole[~whole.any(axis=-1)] = (0.0, 0.0, 1.0)
    tiny = whole * 2.0**-1074
    assert (np.abs(tiny).max(axis=-1) < 2.0**-1022).all()
    assert_same_bits(pyclray.cast(scene, origins, whole, precision=precision),
                     pyclray.cast(scene, origins, tiny, precision=precision))
    np.testing.assert_array_equal(pyclray.occluded(scene, origins, whole, precision=precision),
                                  pyclray.occluded(scene, origins, tiny, precision=precision))


@pytest.fixture(params=["ordered", "caller's order"])
def order_rule(request, monkeypatch):
    """Large batches cast in the coherent order (as on a scene too large for the cache), or in the
    caller's order (as on this small scene: cast_module._orders)."""
    monkeypatch.setattr(cast_module, "ORDER_CACHE_SHARE", 0.0 if request.param == "ordered" else float("inf"))
    return request.param


def test_batches_ending_anywhere_in_a_group_give_the_same_bits(order_rule):
    """The rays of a batch of any length, unordered and in the coherent order (from COHERENT_FROM rays
    on, where the scene is ordered), are those of a longer batch, bit for bit: the places past a batch's
    end in its last group and work-group (set up as copies of its last ray) write nothing and change nothing."""
    scene, origins, directions = random_scene(4)
    rng = np.random.default_rng(4)
    count = cast_module.COHERENT_FROM + 300
    origins = origins[rng.integers(0, len(origins), count)] + rng.normal(size=(count, 3))
    directions = rng.normal(size=(count, 3))
    full = pyclray.cast(scene, origins, directions)
    blocked = pyclray.occluded(scene, origins, directions)
    group, work_group = cast_module.CAST_GROUP, cast_module.CAST_GROUP * cast_module.CAST_WORK_GROUP
    coherent = cast_module.COHERENT_FROM
    for size in (1, group - 1, group + 1, work_group - 1, work_group + 3, coherent - 1, coherent + group + 5):
        part = pyclray.cast(scene, origins[:size], directions[:size])
        assert_same_bits(part, {name: full[name][:size] for name in pyclray.AOVS})
        np.testing.assert_array_equal(pyclray.occluded(scene, origins[:size], directions[:size]), blocked[:size])


@pytest.mark.parametrize("shared_origin", [False, True])
def test_an_ordered_batch_gives_the_bits_of_small_batches(shared_origin, order_rule):
    """A batch of COHERENT_FROM rays or more is cast in a coherent order (engine/queries/cast.py: _orders;
    forced here, the scene being small), each ray read and written at its own place through the
    order: every ray's results, with a tmax per ray and with one shared origin, are those of the
    same rays cast in batches too small to be ordered, bit for bit (a ray written at another's
    place, or a limit read from another's, fails); and so in the caller's order."""
    scene, origins, directions = random_scene(5)
    rng = np.random.default_rng(5)
    count = 2 * cast_module.COHERENT_FROM + 777  # several small batches' worth
    origins = origins[0] if shared_origin else origins[rng.integers(0, len(origins), count)] + rng.normal(size=(count, 3))
    directions = rng.normal(size=(count, 3))
    tmax = rng.uniform(0.5, 20.0, count)
    whole = pyclray.cast(scene, origins, directions, tmax=tmax)
    blocked = pyclray.occluded(scene, origins, directions, tmax=tmax)
    small = cast_module.COHERENT_FROM - 1
    for start in range(0, count, small):
        part = slice(start, start + small)
        some = origins if shared_origin else origins[part]
        assert_same_bits(pyclray.cast(scene, some, directions[part], tmax=tmax[part]),
                         {name: whole[name][part] for name in pyclray.AOVS})
        np.testing.assert_array_equal(pyclray.occluded(scene, some, directions[part], tmax=tmax[part]), blocked[part])
    assert 0 < blocked.sum() < count  # both answers among the rays


def test_large_batches_are_ordered_where_the_scene_outgrows_the_cache_share(monkeypatch):
    """On a CPU device a large batch is cast in the coherent order only where the scene's cast data
    (cast_inputs' bytes: its tree, anchors and entries) exceed ORDER_CACHE_SHARE of the device's
    last-level cache (engine/queries/cast.py: _orders; a GPU on the CPU's host path orders every large
    batch, a device of the GPU class none: engine/queries/cast_device.py); small batches never are. The
    same rays give the same bits either way (the tests above)."""
    from pyclray.engine.queries import ray_order as cast_order
    from pyclray.engine.opencl.device import context_for, gpu_class
    from pyclray.engine.api import tracer_for

    calls = []
    real_order = cast_order.coherent_order
    monkeypatch.setattr(cast_order, "coherent_order", lambda *a, **k: calls.append(1) or real_order(*a, **k))
    scene, origins, directions = random_scene(6)
    rng = np.random.default_rng(6)
    count = cast_module.COHERENT_FROM + 100
    origins, directions = rng.uniform(-6, 6, (count, 3)), rng.normal(size=(count, 3))
    ctx = context_for(None)
    held = tracer_for(scene, ctx, "fp32").cast_inputs()[3]
    assert held > 0
    cache = ctx.device.global_mem_cache_size
    cpu = bool(ctx.device.type & cast_module.cl.device_type.CPU)
    gpu = gpu_class(ctx.device)
    results = {}
    for share, ordered in ((1.01 * held / cache, not cpu and not gpu), (0.99 * held / cache, not gpu)):
        monkeypatch.setattr(cast_module, "ORDER_CACHE_SHARE", share)
        calls.clear()
        results[ordered] = pyclray.cast(scene, origins, directions)
        assert len(calls) == (1 if ordered else 0)
        pyclray.cast(scene, origins[:100], directions[:100])  # a small batch: never ordered
        assert len(calls) == (1 if ordered else 0)
    if len(results) == 2:
        assert_same_bits(results[True], results[False])
