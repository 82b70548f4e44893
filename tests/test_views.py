"""Build once, render many (pyclray.engine.scene.prepared): the scene's shapes are prepared on the device
once per shapes tuple, and a view from another camera rebases them into its frame on the device.
What a view computes must not depend on the views before it: every test here compares bit for bit
with a render from a freshly prepared scene (the cache cleared), which is itself held to the float64
oracle by the rest of the suite (tests/test_render.py, test_shapes.py, the holdout-style cases)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import pyclray
from pyclray.engine import api
from pyclray.engine.scene import prepared
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.model.aovs import RENDER_AOVS
from pyclray.reference import oracle

from oracle_checks import assert_agrees_with_oracle

# every image but flow, which an animation's frame has to its next frame and a still scene has not
ALL = tuple(a for a in RENDER_AOVS if a != "flow")


def same(a, b):
    assert set(a) == set(b)
    for name in a:
        assert np.array_equal(a[name], b[name], equal_nan=True), name


def fresh(scene, **options):
    """The render of a scene prepared from nothing."""
    pyclray.clear_cache()
    return pyclray.render(scene, **options)


def need(precision):
    if precision == "fp64" and not has_fp64(context_for(None).device):
        pytest.skip("device lacks cl_khr_fp64")


def every_shape(offset=(0.0, 0.0, 0.0), size=(48, 40)) -> pyclray.Scene:
    """scenes/shapes.toml (every shape type, lit) moved by offset, camera and lights with it."""
    scene = pyclray.load_scene("scenes/shapes-lit.toml").with_size(*size)
    move = lambda p: tuple(np.add(p, offset))
    shapes = []
    for shape in scene.shapes:
        changes = {}
        for field in ("center", "p0", "p1"):
            if hasattr(shape, field):
                changes[field] = move(getattr(shape, field))
        if isinstance(shape, pyclray.Plane):
            n, h = shape.unit()
            shapes.append(dataclasses.replace(shape, normal=tuple(n), offset=float(h - n @ np.asarray(offset))))
        else:
            shapes.append(dataclasses.replace(shape, **changes))
    lights = tuple(dataclasses.replace(l, position=move(l.position)) if hasattr(l, "position") else l for l in scene.lights)
    camera = dataclasses.replace(scene.camera, eye=move(scene.camera.eye), target=move(scene.camera.target))
    return dataclasses.replace(scene, camera=camera, shapes=tuple(shapes), lights=lights)


@pytest.mark.parametrize("fp64", [True, False])  # the per-view pass on the device; on the host (devices without fp64)
@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("offset", [1e5, 1e6, 1e8])
def test_a_far_view_after_a_near_one_is_the_fresh_far_view_bit_for_bit(monkeypatch, precision, offset, fp64):
    """The same shapes seen from the usual camera and then from one 1e5..1e8 away along the view
    axis (the scene moved with it, so both see it): the far view equals a fresh scene's far view,
    with the per-view pass on the device and on the host (devices without fp64)."""
    need(precision)
    if not fp64:
        monkeypatch.setattr(prepared, "has_fp64", lambda device: False)
    near = every_shape()
    far_scene = every_shape((offset, 0.3 * offset, -offset))
    expected = fresh(far_scene, aovs=ALL, precision=precision)
    pyclray.clear_cache()
    pyclray.render(far_scene, aovs=ALL, precision=precision, camera=near.camera)  # a first view elsewhere
    pyclray.render(dataclasses.replace(far_scene, camera=near.camera), aovs=ALL, precision=precision)
    same(pyclray.render(far_scene, aovs=ALL, precision=precision), expected)


@pytest.mark.parametrize("acceleration", ["tiles", "bvh"])
def test_camera_argument_replace_and_render_views_agree(acceleration):
    scene = pyclray.load_scene("scenes/tp02-lit.toml").with_size(40, 30)
    cameras = [pyclray.Camera((4.0 * np.cos(a), 2.0, 4.0 * np.sin(a)), (0.0, 0.5, 0.0), fov=50.0) for a in np.linspace(0, 3, 5)]
    views = list(pyclray.render_views(scene, cameras, aovs=ALL, acceleration=acceleration))
    assert len(views) == len(cameras)
    for camera, view in zip(cameras, views):
        same(view, pyclray.render(scene, aovs=ALL, camera=camera, acceleration=acceleration))
        same(view, fresh(dataclasses.replace(scene, camera=camera), aovs=ALL, acceleration=acceleration))
    # the views came from one prepared scene: the shapes were packed and uploaded once
    pyclray.clear_cache()
    list(pyclray.render_views(scene, cameras, aovs=("depth",)))
    assert len(api._tracers) == 1


def test_render_views_takes_scenes_of_other_sizes_and_rejects_other_things():
    scene = pyclray.load_scene("scenes/tp02.toml").with_size(32, 24)
    other = scene.with_size(16, 8)
    (a, b) = pyclray.render_views(scene, [scene.camera, other])
    assert a["depth"].shape == (24, 32) and b["depth"].shape == (8, 16)
    with pytest.raises(pyclray.RequestError, match="camera: expected a pyclray.Camera"):
        pyclray.render(scene, camera="front")


def test_render_views_yields_the_frames_before_a_bad_view_then_raises_and_can_stop_early():
    """render_views enqueues the next view before it returns a frame (engine/queries/render.py): a bad view
    (here not a camera) must still come after the frames before it, as a loop of render() would
    give them, and an iterator left after its first frame (a view still in flight) must leave the
    scene in a state where the next render is the fresh one, bit for bit."""
    scene = pyclray.load_scene("scenes/tp02.toml").with_size(32, 24)
    cameras = [pyclray.Camera((3.0, 2.0, 4.0 + k), (0.0, 0.5, 0.0), fov=50.0) for k in range(3)]
    frames = pyclray.render_views(scene, [cameras[0], cameras[1], "front", cameras[2]], aovs=("depth", "id"))
    first, second = next(frames), next(frames)
    same(first, fresh(dataclasses.replace(scene, camera=cameras[0]), aovs=("depth", "id")))
    same(second, fresh(dataclasses.replace(scene, camera=cameras[1]), aovs=("depth", "id")))
    with pytest.raises(pyclray.RequestError, match="camera: expected a pyclray.Camera"):
        next(frames)
    left = pyclray.render_views(scene, cameras, aovs=("depth", "id"))
    same(next(left), pyclray.render(scene, aovs=("depth", "id"), camera=cameras[0]))
    left.close()  # the second view was in flight
    same(pyclray.render(scene, aovs=("depth", "id"), camera=cameras[2]),
         fresh(dataclasses.replace(scene, camera=cameras[2]), aovs=("depth", "id")))


def test_a_moved_camera_uploads_no_shapes(monkeypatch):
    """After the first view, other cameras neither pack nor upload the shapes: the prepared scene is
    the same object and no shape is packed on the host (Shape.pack_world is never called again)."""
    scene = pyclray.load_scene("scenes/grid64.toml").with_size(32, 32)
    pyclray.clear_cache()
    pyclray.render(scene)
    first = api.tracer_for(scene, context_for(None), "fp32").prepared
    calls = []
    for cls in pyclray.model.shapes.REGISTRY.values():
        monkeypatch.setattr(cls, "pack_world", classmethod(lambda c, shapes: calls.append(c) or None))
    for a in np.linspace(0.1, 1.0, 4):
        pyclray.render(scene, camera=dataclasses.replace(scene.camera, eye=tuple(np.add(scene.camera.eye, a))))
    assert not calls
    assert api.tracer_for(scene, context_for(None), "fp32").prepared is first


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_the_host_rebase_of_devices_without_fp64_gives_the_same_images(monkeypatch, precision):
    """A device without float64 rebases on the host (Shape.rebase, numpy float64) what others rebase
    on the device (kernels/rebase.cl): the same formulas in the same order (pyclray.model.shapes.device.in_space),
    so the same images to the last bit."""
    need(precision)
    scene = every_shape((1e4, 0.0, 0.0))
    expected = fresh(scene, aovs=ALL, precision=precision)
    monkeypatch.setattr(prepared, "has_fp64", lambda device: False)
    same(fresh(scene, aovs=ALL, precision=precision), expected)
    pyclray.clear_cache()


def moving_spheres(count: int, moving: int = 6, size=(64, 48), orbit: bool = False) -> pyclray.Scene:
    """A field of named spheres over a ground plane, `moving` of them keyed to travel across it (and
    with orbit, the camera keyed around it too)."""
    from pyclray.model.animation import Animation

    rng = np.random.default_rng(count)
    centres = rng.uniform((-8, 0, -8), (8, 3, 8), (count, 3))
    shapes = (pyclray.Plane((0, 1, 0), 0.0),) + tuple(
        pyclray.Sphere(tuple(c), 0.3, name=f"s{i}") for i, c in enumerate(centres.tolist()))
    keys = []
    for i in np.linspace(0, count - 1, moving).astype(int):
        start = centres[i].tolist()
        keys += [{"target": f"s{i}", "time": 0.0, "center": start},
                 {"target": f"s{i}", "time": 1.0, "center": [-start[0], start[1] + 1.0, -start[2]]},
                 {"target": f"s{i}", "time": 0.5, "radius": 0.6}, {"target": f"s{i}", "time": 0.0, "radius": 0.3}]
    if orbit:
        keys += [{"target": "camera", "time": 0.0, "eye": [0.0, 9.0, 20.0]}, {"target": "camera", "time": 1.0, "eye": [20.0, 6.0, 0.0]}]
    return pyclray.Scene(pyclray.Camera((0, 9, 20), (0, 1, 0), fov=55.0), pyclray.Image(*size), shapes,
                         animation=Animation.from_table({"fps": 8.0, "duration": 1.0, "keys": keys}))


@pytest.mark.parametrize("orbit", [False, True])  # frames brought to the same view in place; whole passes
@pytest.mark.parametrize("count", [300, 3000])
@pytest.mark.parametrize("refit_max", [1.5, 0.0])  # refit in place; every frame rebuilt
def test_animation_frames_update_the_prepared_scene_and_equal_fresh_frames(monkeypatch, count, refit_max, orbit):
    """Each frame of an animation that moves (and grows) a few of many spheres is the update of
    one prepared scene in place (their entries, a refit of the BVH above them, their changed
    materials' extents), or a rebuild where the refit would degrade the tree; either way the
    images equal those of the frame's scene prepared from nothing, bit for bit."""
    monkeypatch.setattr(prepared.PreparedScene, "REFIT_COST_MAX", refit_max)
    scene = moving_spheres(count, orbit=orbit)
    pyclray.clear_cache()
    frames = [frame for _, frame in pyclray.render_animation(scene, aovs=ALL)]
    kept = [t.prepared for t in api._tracers.values() if t.prepared.base is scene.shapes]
    assert len(kept) == 1  # one prepared scene, updated (or rebuilt) frame after frame
    if refit_max and count > 1000:  # the large field is refitted (the small one's few moves may degrade its tree)
        from pyclray.engine.bvh.tree import sah_cost

        state = kept[0]._refit
        assert np.isclose(state.cost(), sah_cost(kept[0].bvh.tree), rtol=1e-9)  # the kept cost is the tree's
    for k, frame in enumerate(frames):
        t = scene.animation.frame_time(k)
        at = scene.at(t)
        still = pyclray.Scene(at.camera, scene.image, at.shapes)  # no derivation: a new scene
        same(frame, fresh(still, aovs=ALL))


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("extent", [1e4, 1e6])
def test_boxes_around_the_anchor_drop_no_shape_seen_from_far_off_it(precision, extent):
    """The BVH's boxes stay around the scene's anchor (its root box's centre) and a view passes the
    eye relative to it, rounded to float with a margin (kernels/bvh.h: box_entries). Here the eye is
    `extent` away from the anchor, 0.05 from tiny spheres (r = 2e-3): at 1e6 the rounding of the eye
    (extent 2^-24, 0.06) is 30 times their size, so a margin that did not cover it would drop them. Held to the float64 oracle, pixel by pixel, within the error model."""
    need(precision)
    rng = np.random.default_rng(7)
    corner = np.array([extent, 0.5 * extent, -extent])
    tiny = corner + rng.uniform(-0.01, 0.01, (40, 3)) * [1, 1, 0.5] + np.array([0.0, 0.0, -0.05])
    far = rng.uniform(-extent, extent, (50, 3))  # the rest of the field: the anchor near the origin
    centres = np.concatenate([tiny, far, -corner[None]])
    radii = np.concatenate([np.full(40, 2e-3), np.full(50, 1.0), [1.0]])
    camera = pyclray.Camera(tuple(corner), tuple(corner + np.array([0.0, 0.0, -1.0])), fov=25.0)
    # Sphere objects, not a batch: the error model's frame is per shape (a batch's is its own centre)
    shapes = tuple(pyclray.Sphere(tuple(c), float(r)) for c, r in zip(centres, radii))
    scene = pyclray.Scene(camera, pyclray.Image(40, 32), shapes)
    pyclray.clear_cache()
    image = pyclray.render(scene, precision=precision, acceleration="bvh")
    anchor = api.tracer_for(scene, context_for(None), precision).prepared.anchor
    assert np.linalg.norm(anchor - corner) > 0.5 * extent  # the case this test is about
    origins, directions = oracle.camera_rays(scene)
    result = {name: image[name].reshape(-1, *image[name].shape[2:]) for name in ("depth", "normal", "id")}
    assert_agrees_with_oracle(scene, origins.reshape(-1, 3), directions.reshape(-1, 3), result, precision,
                              reference_point=corner)


def test_an_animation_frame_that_changes_no_shape_updates_nothing():
    """A frame whose keys move nothing (an animation holding still) is an update of no shape: no
    materials compared or written (pack_materials gives a row even for no shape), the images kept."""
    scene = pyclray.load_scene("scenes/tp02_orbit.toml").with_size(16, 12)
    before = fresh(scene)
    ready = api.tracer_for(scene, context_for(None), "fp32").prepared
    assert ready.update(scene.shapes, [])
    same(pyclray.render(scene), before)


def test_render_views_of_a_mesh_equal_fresh_renders():
    """render_views enqueues view i+1 (its per-view pass included) while view i's kernel may still
    run: a mesh's shared vertices must be from_world in the queue's order, not under the running kernel
    (each view equals a fresh render)."""
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 40, endpoint=False), np.linspace(0.2, np.pi - 0.2, 20))
    vertices = np.stack([np.sin(v) * np.cos(u), np.cos(v) + 1.0, np.sin(v) * np.sin(u)], -1).reshape(-1, 3)
    faces = [(r * 40 + c, r * 40 + (c + 1) % 40, (r + 1) * 40 + c) for r in range(19) for c in range(40)]
    mesh = pyclray.Mesh(vertices, np.array(faces))
    scene = pyclray.Scene(pyclray.Camera((0.0, 1.0, 4.0), (0.0, 1.0, 0.0), fov=40.0), pyclray.Image(160, 120),
                          (pyclray.Plane((0.0, 1.0, 0.0), 0.0), mesh))
    cameras = [pyclray.Camera((4.0 * np.sin(a), 1.5, 4.0 * np.cos(a)), (0.0, 1.0, 0.0), fov=40.0) for a in np.linspace(0, 5, 8)]
    pyclray.clear_cache()
    views = list(pyclray.render_views(scene, cameras, aovs=("depth", "normal", "id", "primitive")))
    for camera, view in zip(cameras, views):
        same(view, fresh(dataclasses.replace(scene, camera=camera), aovs=("depth", "normal", "id", "primitive")))
