"""The benchmark matrix: pyclray (warm and cold), Mitsuba 3 (llvm_ad_rgb, scalar_rgb), the float64
oracle and the floor (a trivial kernel that only writes the three images), on the same scenes.

Errors against the oracle are computed at 512x512 and stored in ``extra_info`` for bench.report.
Slow cases get few rounds (``rounds_for``, at least 3; the oracle 1); scalar_rgb runs at 512x512
on tp02 and grid64 only, 3 rounds (grid64 takes ~15 s a render, grid1024 ~3 min, 2048x2048 16
times as long).
"""
from __future__ import annotations

import dataclasses
import os
import shutil
import tempfile
import time

import numpy as np
import pyopencl as cl
import pytest

import pyclray
from pyclray.engine import api
from pyclray.engine.bvh import tiles as culling
from pyclray.engine.opencl import device
from pyclray.engine.launch import programs
from pyclray.engine.queries import render
from pyclray.engine.launch import signatures
from pyclray.model.aovs import TABLE
from pyclray.reference import error_model, mitsuba, oracle

from . import blocks
from .metrics import compare

SCENE_NAMES = ("tp02", "grid64", "grid1024", "shapes")  # shapes: every shape type (scenes/shapes.toml)
SIZES = (512, 2048)
AOV_SETS = {"all": ("depth", "normal", "id"), "depth": ("depth",)}
PRECISIONS = ("fp32", "fp64")
ERROR_SIZE = 512
# seconds of timed rounds per case, roughly: the quick run (bench/conftest.py) spends less per case
BUDGET = 0.5 if os.environ.get("PYCLRAY_BENCH_MODE") == "quick" else 2.0
_references: dict = {}


def load(scenes_dir, name: str, size: int):
    return pyclray.load_scene(scenes_dir / f"{name}.toml").with_size(size, size)


def rounds_for(seconds: float, budget: float | None = None, most: int = 100, least: int = 3) -> int:
    budget = BUDGET if budget is None else budget
    return int(max(least, min(most, budget / max(seconds, 1e-6))))


def timed(fn):
    start = time.perf_counter()
    result = fn()
    return result, time.perf_counter() - start


def reference(scenes_dir, name: str) -> dict:
    """The oracle's images of a scene at ERROR_SIZE (computed once, by test_oracle if it ran)."""
    if name not in _references:
        _references[name] = error_model.reference(load(scenes_dir, name, ERROR_SIZE))
    return _references[name]


SETTLE = 0.3  # seconds of quiet before each timing: other threads (BLAS, Dr.Jit) go idle


def info(benchmark, kind: str, name: str, size: int, aovs: str = "all", precision: str = "fp64", **more):
    """Record what a case is, then let the machine settle before its timing starts."""
    time.sleep(SETTLE)
    benchmark.extra_info.update(
        {"kind": kind, "scene": name, "size": size, "aovs": aovs, "precision": precision, "rays": size * size, **more}
    )


# -- the float64 numpy oracle (also the reference of every error) -------------------------------
@pytest.mark.parametrize("name", SCENE_NAMES)
def test_oracle(benchmark, scenes_dir, name):
    scene = load(scenes_dir, name, ERROR_SIZE)
    info(benchmark, "oracle", name, ERROR_SIZE)
    benchmark.pedantic(oracle.render, args=(scene,), rounds=1, iterations=1)


# -- the floor: a kernel that only writes the three images ----------------------------------------
@pytest.mark.parametrize("mode", ["kernel", "copies", "in-place"])
@pytest.mark.parametrize("size", SIZES)
def test_floor(benchmark, size, mode):
    """kernel: enqueue and wait; copies: plus enqueue_copy into new numpy arrays; in-place: the
    kernel writes into new numpy arrays (USE_HOST_PTR buffers, then map), as pyclray does on a CPU."""
    ctx = device.context_for(None)
    kernel = cl.Program(ctx.context, blocks.FLOOR_SOURCE).build().floor_kernel
    count = size * size
    buffers = [cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY, count * n) for n in (4, 12, 4)]
    kernel.set_args(*buffers, np.int32(size), np.int32(size))

    def new_arrays():
        return [np.empty(count, np.float32), np.empty((count, 3), np.float32), np.empty(count, np.int32)]

    in_place = blocks.floor_in_place(ctx, size)

    def run():
        if mode == "in-place":
            in_place()
            return
        cl.enqueue_nd_range_kernel(ctx.queue, kernel, (size, size), None)
        if mode == "copies":
            for array, buffer in zip(new_arrays(), buffers):
                cl.enqueue_copy(ctx.queue, array, buffer, is_blocking=False)
        ctx.queue.finish()

    _, seconds = timed(run)
    info(benchmark, {"kernel": "floor", "copies": "floor+copies", "in-place": "floor-in-place"}[mode], "floor", size, precision="fp32")
    benchmark.pedantic(run, rounds=rounds_for(seconds, most=200), iterations=1, warmup_rounds=3)


# -- pyclray -----------------------------------------------------------------------------------
@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("aovs", list(AOV_SETS))
@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("name", SCENE_NAMES)
def test_pyclray_warm(benchmark, scenes_dir, name, size, aovs, precision):
    scene = load(scenes_dir, name, size)
    images, seconds = timed(lambda: pyclray.render(scene, AOV_SETS[aovs], precision))  # builds
    images, seconds = timed(lambda: pyclray.render(scene, AOV_SETS[aovs], precision))
    info(benchmark, "pyclray", name, size, aovs, precision)
    benchmark.pedantic(pyclray.render, args=(scene, AOV_SETS[aovs], precision), rounds=rounds_for(seconds), iterations=1, warmup_rounds=1)
    # errors after the timing: numpy's BLAS threads keep spinning for a while after use
    if size == ERROR_SIZE:
        benchmark.extra_info.update(compare(scene, images, reference(scenes_dir, name), engine=precision))


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("name", SCENE_NAMES)
def test_pyclray_new_scene(benchmark, scenes_dir, name, size):
    """Warm program, but a new (equal) Scene object every call, as a moved camera would be: the
    inputs, tile lists and rays that renders of one Scene object share are rebuilt each time."""
    scene = load(scenes_dir, name, size)
    fresh = lambda: pyclray.render(dataclasses.replace(scene))  # noqa: E731
    _, seconds = timed(fresh)
    _, seconds = timed(fresh)
    info(benchmark, "pyclray-new-scene", name, size, "all", "fp32")
    benchmark.pedantic(fresh, rounds=rounds_for(seconds), iterations=1, warmup_rounds=1)


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("aovs", list(AOV_SETS))
@pytest.mark.parametrize("name", SCENE_NAMES)
def test_pyclray_cold(benchmark, scenes_dir, name, aovs, precision):
    """First render in a process: in-memory programs cleared, an empty disk cache, PoCL's cache off."""
    scene = load(scenes_dir, name, ERROR_SIZE)
    folders = []

    def setup():
        programs.clear()
        folders.append(tempfile.mkdtemp(prefix="pyclray-cold-"))
        os.environ["PYCLRAY_CACHE_DIR"] = folders[-1]

    previous = os.environ["PYCLRAY_CACHE_DIR"]
    info(benchmark, "pyclray-cold", name, ERROR_SIZE, aovs, precision)
    try:
        benchmark.pedantic(
            lambda: pyclray.render(scene, AOV_SETS[aovs], precision),
            setup=setup, rounds=3, iterations=1, warmup_rounds=0,
        )
    finally:
        os.environ["PYCLRAY_CACHE_DIR"] = previous
        for folder in folders:
            shutil.rmtree(folder, ignore_errors=True)


# -- Mitsuba 3 ---------------------------------------------------------------------------------
def mitsuba_images(scene, image, ids) -> dict:
    """Mitsuba's aov image in pyclray's conventions (as pyclray.reference.mitsuba.render converts it)."""
    image = np.asarray(image, dtype=np.float64)
    near, _ = mitsuba.clip_range(scene)
    index = np.rint(image[..., 7]).astype(np.int64)
    hit = index > 0
    lookup = np.vectorize(lambda k: ids.get(int(k), -1), otypes=[np.int32])
    return {
        "depth": np.where(hit, image[..., 0] + near / mitsuba.axis_cosines(scene), np.inf),
        "normal": np.where(hit[..., None], image[..., 1:4], 0.0),
        "id": np.where(hit, lookup(np.where(hit, index, 0)) if hit.any() else -1, -1).astype(np.int32),
    }


def _mitsuba(benchmark, scenes_dir, name, size, variant, kind, most_rounds=100, least_rounds=3):
    scene = load(scenes_dir, name, size)
    mi = mitsuba.import_mitsuba(variant)
    mi_scene, ids = mitsuba.load(scene, variant)
    sensor = mi_scene.sensors()[0]
    integrator = mi_scene.integrator()

    def run():
        # np.array forces the evaluation of the JIT variants' lazy result, as pyclray reads back its images
        return np.array(integrator.render(mi_scene, sensor))

    image, seconds = timed(run)  # warm: JIT kernels compiled, scene loaded
    info(benchmark, kind, name, size, "all", "fp32")
    benchmark.pedantic(run, rounds=rounds_for(seconds, most=most_rounds, least=least_rounds), iterations=1)
    if size == ERROR_SIZE:  # after the timing, as for pyclray
        origins, directions = oracle.camera_rays(scene)
        mask = mitsuba.beyond_counterparts(scene, origins, directions)
        # on the pixels pyclray fp32 is judged on: the same pixels for every engine
        errors = compare(scene, mitsuba_images(scene, image, ids), reference(scenes_dir, name), exclude=mask,
                         engine="fp32")
        benchmark.extra_info.update(errors)
    del mi


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("name", SCENE_NAMES)
def test_mitsuba_llvm(benchmark, scenes_dir, name, size):
    _mitsuba(benchmark, scenes_dir, name, size, "llvm_ad_rgb", "mitsuba-llvm")


@pytest.mark.parametrize("name", ["tp02", "grid64", "shapes"])
def test_mitsuba_scalar(benchmark, scenes_dir, name):
    """512x512 only, and not grid1024 (~3 min a render): see the module's docstring."""
    _mitsuba(benchmark, scenes_dir, name, ERROR_SIZE, "scalar_rgb", "mitsuba-scalar", most_rounds=3)


# -- where the time of a tp02 render goes ------------------------------------------------------
BREAKDOWN = {
    "render, all AOVs": "the whole warm render (as test_pyclray_warm)",
    "kernel only, all AOVs": "the render kernel alone: enqueue and wait, inputs and (device) outputs in place",
    "kernel only, depth": "the depth-only render kernel alone",
    "kernel only, all AOVs, plane only": "the kernel on tp02 without its spheres (the ground plane alone)",
    "render 16x16, all AOVs": "a 16x16 render: Python, argument checks and one kernel launch",
}


@pytest.mark.parametrize("part", list(BREAKDOWN))
def test_breakdown(benchmark, scenes_dir, part):
    scene = load(scenes_dir, "tp02", ERROR_SIZE)
    if part == "kernel only, all AOVs, plane only":
        scene = dataclasses.replace(scene, shapes=scene.shapes[:1])
    aovs = AOV_SETS["depth"] if part.endswith("depth") else AOV_SETS["all"]
    ctx = device.context_for(None)
    width = height = ERROR_SIZE
    pyclray.render(scene, aovs)  # builds, and prepares the scene's inputs
    tracer = api.tracer_for(scene, ctx, "fp32")
    prepared = tracer.prepared
    inputs = tracer.view_state(scene).inputs_for(ctx, scene, prepared, "tiles")
    with prepared.lock:  # the view buffers in this view's frame (the render above left them so)
        prepared.rebase(inputs.eye, inputs.rows)
    lanes = programs.lanes_for(ctx.device, "fp32")
    variant = programs.Variant("render", scene.shape_types(), aovs, "fp32", lanes)
    kernel = programs.kernel_for(ctx, variant)
    buffers = [cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY, width * height * TABLE[aov].itemsize("fp32")) for aov in aovs]
    tile = culling.TILE
    args = signatures.arguments(variant, {
        "camera": inputs.camera, "col0": np.int32(0), "row0": np.int32(0), "cols": np.int32(width),
        "rows": np.int32(height), "tile_shift": np.int32(tile.bit_length() - 1), "tiles_x": np.int32(width // tile),
        **inputs.shape_args(prepared, "tiles"), **{signatures.image_parameter(a): b for a, b in zip(aovs, buffers)}})
    global_size, local_size = render.launch_size(lanes, 0, 0, width, height, ctx.device.max_work_group_size)

    def kernel_only():
        kernel(ctx.queue, global_size, local_size, *args)
        ctx.queue.finish()

    small = scene.with_size(16, 16)
    run = {
        "render, all AOVs": lambda: pyclray.render(scene, aovs),
        "render 16x16, all AOVs": lambda: pyclray.render(small, aovs),
    }.get(part, kernel_only)
    _, seconds = timed(run)
    info(benchmark, "breakdown", "tp02", ERROR_SIZE, "depth" if part.endswith("depth") else "all", "fp32", part=part)
    benchmark.pedantic(run, rounds=rounds_for(seconds, most=200), iterations=1, warmup_rounds=3)


# -- the speed targets, measured in blocks (bench/blocks.py) --------------------------------------
@pytest.mark.parametrize("group", list(blocks.GROUPS))
def test_targets_blocks(benchmark, group):
    """The cases of the speed targets, each timed in blocks of calls with a pause at each switch
    (bench/blocks.py); per-case statistics go to extra_info["cases"]."""
    name, size, _ = blocks.GROUPS[group]
    info(benchmark, "targets-blocks", name, size, "all", "fp32", group=group)
    result = {}
    benchmark.pedantic(lambda: result.update(blocks.measure((group,))), rounds=1, iterations=1)
    benchmark.extra_info["cases"] = result
