"""The render path's speed-ups change no bit of the results: on PoCL, the compiler's own square root,
reductions and vector stores, the functions always inlined and the packet's function kept out of the
kernel (pyclray.engine.launch.programs.Variant.source, kernels/lanes.h), and the cached inputs give the same images as the
plain path."""
from __future__ import annotations

import dataclasses
import importlib

import numpy as np
import pytest

import pyclray
from pyclray.engine import api
from pyclray.engine.opencl import device
from pyclray.engine.launch import programs
from pyclray.engine.launch import run as request
from pyclray.model import aovs

from pyclray import Camera, Image, Plane, Scene, Sphere


def random_scene(seed: int, n_spheres: int = 12, size=(61, 47)) -> Scene:
    rng = np.random.default_rng(seed)
    eye = rng.normal(0, 3, 3)
    target = eye + rng.normal(0, 1, 3)
    fov = float(rng.choice([0.05, 20.0, 60.0, 120.0]))
    shapes = [Plane(tuple(rng.normal(0, 1, 3)), float(rng.normal(0, 2)))]
    forward = (target - eye) / np.linalg.norm(target - eye)
    spread = np.tan(np.radians(fov) / 2)
    for _ in range(n_spheres):  # mostly in view, some behind the eye or straddling it
        distance = rng.uniform(-2, 12)
        centre = eye + distance * forward + rng.normal(0, 1, 3) * spread * abs(distance)
        shapes.append(Sphere(tuple(centre), float(rng.uniform(0.05, 1.5) * max(spread, 0.01) * max(abs(distance), 0.5))))
    if seed % 3 == 0:  # the camera inside a sphere
        shapes.append(Sphere(tuple(eye + rng.normal(0, 0.1, 3)), 0.5))
    shapes.append(Sphere(tuple(target + rng.normal(0, 0.01, 3)), 0.02))  # a tiny one near the eye
    return Scene(Camera(tuple(eye), tuple(target), (0.0, 1.0, 0.0), fov), Image(*size), tuple(shapes))


def same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        assert a[key].dtype == b[key].dtype and a[key].shape == b[key].shape, key
        np.testing.assert_array_equal(a[key].view(np.uint8), b[key].view(np.uint8), err_msg=key)


def with_plain_builtins(monkeypatch):
    monkeypatch.setattr(programs, "is_pocl_cpu", lambda _device: False)
    monkeypatch.setattr(programs, "_programs", {})


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("seed", range(6))
def test_inline_builtins_are_bit_identical(monkeypatch, seed, precision):
    if not device.is_pocl_cpu(device.context_for(None).device):
        pytest.skip("device lacks PoCL: the inline built-ins are used on PoCL's CPU device only")
    scene = random_scene(seed)
    rng = np.random.default_rng(100 + seed)
    origins, directions = rng.normal(0, 3, (500, 3)), rng.normal(0, 1, (500, 3))
    requests = (("depth", "normal", "id"), ("depth",), ("normal",), aovs.RENDER_AOVS)
    fast = [pyclray.render(scene, aovs, precision) for aovs in requests]
    fast.append(pyclray.cast(scene, origins, directions, precision=precision))
    with monkeypatch.context() as patch:
        with_plain_builtins(patch)
        plain = [pyclray.render(scene, aovs, precision) for aovs in requests]
        plain.append(pyclray.cast(scene, origins, directions, precision=precision))
    for a, b in zip(fast, plain):
        same(a, b)



@pytest.mark.parametrize("name", ["mesh", "instanced", "shapes-lit"])
@pytest.mark.parametrize("lanes", [8, 1])
def test_inline_builtins_are_bit_identical_through_the_bvh(monkeypatch, scenes_dir, name, lanes):
    """The same with every shape type's code through the BVH (packets over the wide tree, shadow
    rays over the binary one, a mesh's indexed triangles, instances; shaded with shadows), at the
    CPU's width and at a GPU's one lane: the plain built-ins' program, which every device but PoCL's
    CPU compiles, builds and gives PoCL's bits (an empty prefetch once left a loop without a body
    there: the BVH's programs failed to build on Intel's CPU runtime and would have on GPUs)."""
    if not device.is_pocl_cpu(device.context_for(None).device):
        pytest.skip("device lacks PoCL: the inline built-ins are used on PoCL's CPU device only")
    monkeypatch.setenv("PYCLRAY_LANES", str(lanes))
    from pyclray.model.loader import load_scene

    scene = load_scene(scenes_dir / f"{name}.toml")
    scene = dataclasses.replace(scene, image=Image(53, 37))
    asked = tuple(a for a in aovs.RENDER_AOVS if a != "label")
    fast = pyclray.render(scene, asked, acceleration="bvh")
    with monkeypatch.context() as patch:
        with_plain_builtins(patch)
        plain = pyclray.render(scene, asked, acceleration="bvh")
    same(fast, plain)

def without_culling(monkeypatch):
    from pyclray.engine.bvh import tiles as culling

    monkeypatch.setattr(culling, "ENABLED", False)
    monkeypatch.setattr(api, "_tracers", api.OrderedDict())


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("seed", range(10))
def test_culling_is_bit_identical(monkeypatch, seed, precision):
    """Visiting only the shapes whose screen bounds meet a tile changes nothing, for spheres in
    view, behind the eye, around it, straddling its plane, tiny and far, and narrow or wide fields."""
    scene = random_scene(seed, n_spheres=40, size=(203, 157))
    culled = [pyclray.render(scene, aovs, precision) for aovs in (("depth", "normal", "id"), ("depth",))]
    with monkeypatch.context() as patch:
        without_culling(patch)
        every = [pyclray.render(scene, aovs, precision) for aovs in (("depth", "normal", "id"), ("depth",))]
    for a, b in zip(culled, every):
        same(a, b)


def test_a_moved_camera_is_a_new_render():
    """The cached inputs of one scene are never used for another (here: the same shapes, another eye)."""
    import dataclasses

    first = random_scene(3)
    moved = dataclasses.replace(first, camera=dataclasses.replace(first.camera, eye=tuple(np.add(first.camera.eye, 0.5))))
    a = pyclray.render(first)
    b = pyclray.render(moved)
    api.clear()
    same(pyclray.render(moved), b)
    same(pyclray.render(first), a)
    assert not np.array_equal(a["depth"], b["depth"])


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_output_paths_agree(monkeypatch, precision):
    """Images written straight into the arrays (CPU devices) or copied from kept device buffers
    (other devices) are the same, for renders and casts."""
    scene = random_scene(7, size=(97, 41))
    rng = np.random.default_rng(7)
    origins, directions = rng.normal(0, 3, (300, 3)), rng.normal(0, 1, (300, 3))
    runs = {}
    for zero_copy in (True, False):
        with monkeypatch.context() as patch:
            patch.setattr(request, "_zero_copy", lambda _ctx, value=zero_copy: value)
            runs[zero_copy] = [
                pyclray.render(scene, ("depth", "normal", "id"), precision),
                pyclray.render(scene, ("normal",), precision),
                pyclray.cast(scene, origins, directions, precision=precision),
            ]
    for a, b in zip(runs[True], runs[False]):
        same(a, b)
