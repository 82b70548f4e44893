"""The scene handle (pyclray.prepare, engine/tracer.py): its queries are the module-level functions'
bit for bit, an update is a handle prepared anew for the moved scene bit for bit, a closed handle
refuses every query, and the engine keeps no other state between calls than the one cache of
handles (engine/api.py)."""
from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest

import pyclray
from pyclray.engine import api
from pyclray.model.aovs import RENDER_AOVS

from test_views import every_shape, same

ENGINE = Path(pyclray.__file__).parent / "engine"


def rays(count=200, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-3.0, 3.0, (count, 3)) + [0.0, 1.0, 4.0], rng.normal(size=(count, 3))


def test_a_handles_queries_are_the_functions_bit_for_bit():
    scene = every_shape()
    origins, directions = rays()
    other = pyclray.Camera((3.0, 4.0, 9.0), (0.0, 0.5, 0.0), fov=40.0)
    with pyclray.prepare(scene) as tracer:
        assert isinstance(tracer, pyclray.Tracer) and tracer.scene is scene
        same(tracer.render(aovs=RENDER_AOVS), pyclray.render(scene, RENDER_AOVS))
        same(tracer.render(other, aovs=("depth", "id")), pyclray.render(scene, ("depth", "id"), camera=other))
        same(tracer.render(aovs=("depth",), window=(3, 5, 20, 11), acceleration="bvh"),
             pyclray.render(scene, ("depth",), window=(3, 5, 20, 11), acceleration="bvh"))
        for mine, theirs in zip(tracer.render_views([other, scene.camera], aovs=("depth", "normal")),
                                pyclray.render_views(scene, [other, scene.camera], aovs=("depth", "normal"))):
            same(mine, theirs)
        same(tracer.cast(origins, directions, aovs=("depth", "normal", "id"), tmax=5.0),
             pyclray.cast(scene, origins, directions, aovs=("depth", "normal", "id"), tmax=5.0))
        assert np.array_equal(tracer.occluded(origins, directions), pyclray.occluded(scene, origins, directions))


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_an_update_is_a_fresh_handle_of_the_moved_scene(precision):
    """An animation's frame (scene.at: only the moved shapes rewritten, the BVH refitted), shapes
    replaced in a tuple of as many (no animation: the differences found by identity), and another
    count of shapes (prepared anew): each gives what a handle prepared for that scene gives."""
    from test_animation_frames import far_field

    animated = far_field(0.0, orbit=True)
    origins, directions = rays(300, 1)
    frames = [animated.at(t) for t in (0.25, 0.5, 0.0)]
    first = frames[0]
    moved = tuple(dataclasses.replace(s, center=tuple(np.add(s.center, 0.1))) if i % 7 == 0 and hasattr(s, "center") else s
                  for i, s in enumerate(first.shapes))
    scenes = frames + [dataclasses.replace(first, shapes=moved), dataclasses.replace(first, shapes=first.shapes[:-3])]
    with pyclray.prepare(animated, precision=precision) as tracer:
        tracer.cast(origins, directions)  # cast's inputs made: an update must drop them
        for scene in scenes:
            tracer.update(scene)
            with pyclray.prepare(scene, precision=precision) as fresh:
                same(tracer.render(aovs=("depth", "normal", "id", "shaded")), fresh.render(aovs=("depth", "normal", "id", "shaded")))
                same(tracer.cast(origins, directions), fresh.cast(origins, directions))
                assert np.array_equal(tracer.occluded(origins, directions), fresh.occluded(origins, directions))


def test_an_update_moving_a_mesh_and_a_sphere_far_casts_as_a_fresh_handle():
    """Beside a mesh (cast tests a leaf's triangles at once: its refs and anchors regrouped), a sphere
    moved from 100 to 50 along +x is cast from its new box (its anchor and radius: a ray from the
    origin that started at the old anchor's reach would pass it) and a moved mesh from its new
    vertices, as a handle prepared for the moved scene casts them, bit for bit."""
    import trimesh

    ico = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    mesh = pyclray.Mesh(ico.vertices, ico.faces, translate=(0.0, 10.0, 0.0))
    before = pyclray.Scene(pyclray.Camera((0.0, 0.0, -5.0), (0.0, 0.0, 0.0)), pyclray.Image(8, 8),
                           (mesh, pyclray.Sphere((100.0, 0.0, 0.0), 1.0)))
    after = dataclasses.replace(before, shapes=(dataclasses.replace(mesh, translate=(0.0, -10.0, 0.0)),
                                                pyclray.Sphere((50.0, 0.0, 0.0), 1.0)))
    rng = np.random.default_rng(3)
    origins = np.zeros((400, 3))
    directions = np.concatenate([[[1.0, 0.0, 0.0], [0.011, -1.0, 0.013]], rng.normal(size=(398, 3))])  # (off the vertices)
    with pyclray.prepare(before) as tracer:
        tracer.cast(origins, directions)  # cast's inputs made for the shapes before
        tracer.update(after)
        moved = tracer.cast(origins, directions)
        assert moved["id"][:2].tolist() == [1, 0] and moved["depth"][0] == pytest.approx(49.0)
        with pyclray.prepare(after) as fresh:
            same(moved, fresh.cast(origins, directions))
    # an animation's frames (scene.at): the mesh's triangles where the frame has them
    animated = dataclasses.replace(before, animation=pyclray.Animation(10.0, 1.0, (
        {"target": "mesh", "time": 0.0, "translate": [0.0, 10.0, 0.0]},
        {"target": "mesh", "time": 0.1, "translate": [10.0, 0.0, 0.0]})))
    with pyclray.prepare(animated.at(0.0)) as tracer:
        tracer.cast(origins, directions)
        for t in (0.05, 0.1):
            tracer.update(animated.at(t))
            with pyclray.prepare(animated.at(t)) as fresh:
                same(tracer.cast(origins, directions), fresh.cast(origins, directions))


def test_a_closed_handle_refuses_every_query():
    scene = pyclray.load_scene("scenes/tp02.toml").with_size(16, 16)
    origins, directions = rays(10)
    with pyclray.prepare(scene) as tracer:
        tracer.render()
        tracer.cast(origins, directions)
        held = tracer.nbytes
        assert held > 0
    assert tracer.closed and tracer.nbytes == 0
    for query in (tracer.render, lambda: tracer.cast(origins, directions), lambda: tracer.occluded(origins, directions),
                  lambda: list(tracer.render_views([scene.camera])), lambda: tracer.update(scene)):
        with pytest.raises(pyclray.RequestError, match="closed"):
            query()
    tracer.close()  # closing again does nothing


def test_nbytes_counts_what_a_cast_adds():
    scene = every_shape()
    with pyclray.prepare(scene) as tracer:
        tracer.render(aovs=("depth",))
        rendered = tracer.nbytes
        tracer.cast(*rays(10))
        assert tracer.nbytes > rendered >= tracer.prepared.nbytes()


def test_bad_arguments_are_clear_errors():
    with pytest.raises(pyclray.RequestError, match="precision"):
        pyclray.prepare(pyclray.load_scene("scenes/tp02.toml"), precision="fp16")
    with pytest.raises(pyclray.RequestError, match="scene"):
        pyclray.prepare(42)
    with pyclray.prepare("scenes/tp02.toml") as tracer:
        with pytest.raises(pyclray.RequestError, match="camera"):
            tracer.render(camera="front")
        with pytest.raises(pyclray.RequestError, match="aovs"):
            tracer.render(aovs=("colour",))


def test_the_functions_share_one_cached_handle_per_shapes_tuple():
    scene = pyclray.load_scene("scenes/tp02.toml").with_size(16, 16)
    pyclray.clear_cache()
    pyclray.render(scene)
    pyclray.render(dataclasses.replace(scene, camera=pyclray.Camera((0.0, 3.0, 7.0), (0.0, 0.0, 0.0))))
    pyclray.cast(scene, *rays(10))
    assert len(api._tracers) == 1
    pyclray.clear_cache()
    assert not api._tracers


# The engine's state that outlives a call, each with why it is module-level: the cache of handles
# behind the module-level functions; the device contexts and the built programs (per device, shared
# by every handle on it); the build counters; the CPU names given to PoCL's devices.
MODULE_STATE = {("api.py", "_tracers"), ("opencl/device.py", "_contexts"), ("launch/programs.py", "_programs"),
                ("launch/programs.py", "stats"), ("opencl/pocl_cpu.py", "_patched")}


def test_the_engine_keeps_no_other_module_level_state():
    """No module of the engine holds a mutable container at module level (a cache, a registry of
    caches) but those of MODULE_STATE (names in capitals are constant tables): a scene's state is
    its handle's."""
    found = set()
    for path in ENGINE.rglob("*.py"):
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
            value = getattr(node, "value", None)
            mutable = isinstance(value, (ast.Dict, ast.List, ast.Set)) or (
                isinstance(value, ast.Call) and getattr(value.func, "id", getattr(value.func, "attr", None))
                in ("dict", "list", "set", "OrderedDict", "defaultdict"))
            for target in targets:
                if mutable and isinstance(target, ast.Name) and not target.id.lstrip("_").isupper():  # (constants)
                    found.add((str(path.relative_to(ENGINE)), target.id))
    assert found == MODULE_STATE
