"""The float64 oracle through the scene's BVH (pyclray.reference.oracle_bvh) against the plain one
(every shape against every ray): the same nearest and second-nearest hits, bit for bit, since each
shape's own test runs on the rays that cross its box and a ray's result does not depend on the
others. A box test that dropped a shape the ray hits would show here as a different hit."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import pyclray
from pyclray.model.shapes import REGISTRY
from pyclray.reference import oracle

from conftest import SCENES

AOVS = ("depth", "normal", "id", "second")


def same_traces(scene, origins, directions):
    fast = oracle.trace(scene, origins, directions, aovs=AOVS)
    plain = oracle.trace_every_shape(scene, origins, directions, aovs=AOVS)
    for key in plain:
        assert np.array_equal(fast[key], plain[key]), key


@pytest.mark.parametrize("path", sorted(SCENES.glob("*.toml")), ids=lambda p: p.name)
def test_camera_rays_of_every_scene(path):
    scene = pyclray.load_scene(path)
    scene = scene.with_size(48, 36) if scene.camera.K is None else scene
    same_traces(scene, *oracle.camera_rays(scene))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_rays_through_random_scenes_of_every_shape(seed):
    """Rays from anywhere (inside shapes, on their surfaces as shadow rays leave them, along the
    axes with zero direction components), through scenes of every type, a large shape among them."""
    rng = np.random.default_rng(seed)
    shapes = [cls.random(rng, shift=rng.uniform(-2, 2, 3)) for cls in REGISTRY.values() for _ in range(4)]
    shapes.append(pyclray.Sphere((0.0, -1000.0, 0.0), 1000.0))  # larger than the rest together
    scene = pyclray.Scene(pyclray.Camera((0, 2, 12), (0, 0, 0)), pyclray.Image(8, 8), tuple(shapes))
    origins = rng.uniform(-5, 5, (3000, 3))
    directions = rng.normal(size=(3000, 3))
    directions[np.arange(600), rng.integers(0, 3, 600)] = 0.0  # a zero component: parallel to a slab
    directions[600:700] = [[0.0, 0.0, -1.0]]
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    first = oracle.trace_every_shape(scene, origins, directions, aovs=("depth",))["depth"]
    hit = np.isfinite(first)
    origins[:1000][hit[:1000]] += first[:1000][hit[:1000], None] * directions[:1000][hit[:1000]]  # on surfaces
    same_traces(scene, origins, directions)


def test_ctrl_c_during_a_check_is_quiet():
    """Ctrl-C while Mitsuba and the oracle work (a 1024-sphere grid at 1024x1024, a minute's work):
    status 130, nothing on stdout or stderr (no traceback, no Mitsuba warning)."""
    process = subprocess.Popen([sys.executable, "-m", "pyclray", "check", str(SCENES / "grid1024.toml"), "--size",
                                "1024x1024"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=dict(os.environ))
    time.sleep(4.0)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert out == "" and err == ""


def plain_visibility(scene, points, normals, directions, ids, skip, blur, lifts):
    """reference_visibility's definition, the plain way: every moved point's ray traced through
    every shape (trace_every_shape)."""
    from pyclray.model.lights import effective_lights
    from pyclray.reference.shading import facing_normals, light_terms

    size = max(1.0, float(np.abs(points[ids >= 0]).max(initial=1.0)))
    n_s = facing_normals(normals, directions)
    out, unsure = [], []
    for light in effective_lights(scene):
        def visible(origins):
            L, _, distance = light_terms(light, origins)
            t = oracle.trace_every_shape(scene, origins + skip * size * L, L, aovs=("depth",))["depth"]
            return ~(t < distance - skip * size)

        base = visible(points)
        mixed = np.zeros_like(base)
        for axis in range(3):
            for sign in (-1.0, 1.0):
                step = np.zeros(3)
                step[axis] = sign
                moved = step - np.einsum("...k,k->...", n_s, step)[..., None] * n_s + 0.5 * n_s
                mixed |= visible(points + blur[..., None] * moved) != base
        for lift in lifts:
            mixed |= visible(points + lift[..., None] * n_s) != base
        lit = (np.einsum("...k,...k", n_s, light_terms(light, points)[0]) > 0) & (ids >= 0)
        out.append((base & lit).astype(np.float64))
        unsure.append(mixed & lit)
    return out, unsure


@pytest.mark.parametrize("name", ["shapes-lit.toml", "rtiow.toml", "tp02-lit.toml"])
def test_shadow_visibility_tests_only_the_shapes_near_each_ray(name):
    """reference_visibility traces each light's shadow rays (and those of the moved points that find
    shadow edges) against the shapes near p's own ray only: the same V and the same edges as every
    moved ray traced through every shape."""
    from pyclray.reference.shading import reference_visibility

    scene = pyclray.load_scene(SCENES / name).with_size(40, 30)
    origins, directions = oracle.camera_rays(scene)
    truth = oracle.trace(scene, origins, directions, aovs=("depth", "normal", "id"))
    points = origins + np.where(np.isfinite(truth["depth"]), truth["depth"], 0)[..., None] * directions
    blur = 1e-3 * (1 + np.abs(points).max(axis=-1))
    lifts = (1e-4 * np.linalg.norm(points, axis=-1), 2e-3 * np.ones(truth["id"].shape))
    args = (scene, points, truth["normal"], directions, truth["id"])
    fast_v, fast_edges = reference_visibility(*args, skip=1e-9, blur=blur, lifts=lifts)
    plain_v, plain_edges = plain_visibility(*args, 1e-9, blur, lifts)
    for a, b in zip(fast_v + fast_edges, plain_v + plain_edges):
        assert np.array_equal(a, b)
    assert sum(e.sum() for e in fast_edges) > 0 and sum((v == 0).sum() for v in fast_v) > 0
