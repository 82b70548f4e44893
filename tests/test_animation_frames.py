"""An animation's frame on a prepared scene (pyclray.engine.scene.refit): only the shapes that moved are
rewritten, the BVH refitted above them, and render_animation's frames never walk the N shapes.
Every image is compared bit for bit with the frame's scene prepared from nothing (test_views.fresh),
which the rest of the suite holds to the float64 oracle; the tree is compared exactly with a refit
of the whole tree from its entries."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import pyclray
from pyclray.engine import api
from pyclray.engine.scene import refit
from pyclray.engine.bvh.tree import sah_cost
from pyclray.model import animation
from pyclray.model.animation import Animation, FrameShapes
from pyclray.model.frames import FrameWork

from test_views import ALL, fresh, need, same

FPS = 6.0


def far_field(offset: float, count: int = 2000, moving: int = 5, orbit: bool = False, mesh: bool = False) -> pyclray.Scene:
    """A ground plane and `count` named spheres (and with mesh, a flat grid mesh over them), all
    `offset` away from the origin along (1, 0.5, -1), camera with them; `moving` spheres keyed to
    cross the field and grow (the mesh to move), the camera keyed around the field with orbit."""
    shift = offset * np.array([1.0, 0.5, -1.0])
    rng = np.random.default_rng(count + moving)
    centres = rng.uniform((-8, 0, -8), (8, 3, 8), (count, 3)) + shift
    shapes = [pyclray.Plane((0.0, 1.0, 0.0), -float(shift[1]))]
    shapes += [pyclray.Sphere(tuple(c), 0.3, name=f"s{i}") for i, c in enumerate(centres.tolist())]
    keys = []
    for i in np.linspace(0, count - 1, moving).astype(int):
        start = centres[i]
        end = 2 * shift - start + [0.0, 1.0, 0.0]  # across the field's centre
        keys += [{"target": f"s{i}", "time": 0.0, "center": start.tolist(), "radius": 0.3},
                 {"target": f"s{i}", "time": 1.0, "center": end.tolist(), "radius": 0.6}]
    if mesh:  # a 12 x 12 grid of 242 triangles: its entries' leaf order is not their primitive order
        xs, zs = np.meshgrid(np.linspace(-3, 3, 12), np.linspace(-3, 3, 12))
        vertices = np.stack([xs.ravel(), 1.0 + 0.3 * np.sin(2 * xs.ravel()), zs.ravel()], 1) + shift
        corner = (np.arange(11)[:, None] * 12 + np.arange(11)[None]).ravel()
        faces = np.concatenate([np.stack([corner, corner + 1, corner + 12], 1), np.stack([corner + 1, corner + 13, corner + 12], 1)])
        shapes.append(pyclray.Mesh(vertices, faces, name="grid"))
        keys += [{"target": "grid", "time": 0.0, "translate": [0.0, 0.0, 0.0]},
                 {"target": "grid", "time": 1.0, "translate": [2.0, 1.0, -1.5]}]
    eye, target = shift + [0.0, 9.0, 20.0], shift + [0.0, 1.0, 0.0]
    if orbit:
        keys += [{"target": "camera", "time": 0.0, "eye": eye.tolist()},
                 {"target": "camera", "time": 1.0, "eye": (shift + [20.0, 6.0, 0.0]).tolist()}]
    return pyclray.Scene(pyclray.Camera(tuple(eye), tuple(target), fov=50.0), pyclray.Image(40, 32), tuple(shapes),
                         animation=Animation.from_table({"fps": FPS, "duration": 1.0, "keys": keys}))


def frames_equal_fresh(scene, precision="fp32", aovs=ALL):
    pyclray.clear_cache()
    frames = [frame for _, frame in pyclray.render_animation(scene, aovs=aovs, precision=precision)]
    kept = [t.prepared for t in api._tracers.values() if t.prepared.base is scene.shapes]
    assert len(kept) == 1 and kept[0]._refit is not None  # one prepared scene, refitted frame after frame
    for k, frame in enumerate(frames):
        at = scene.at(scene.animation.frame_time(k))
        same(frame, fresh(pyclray.Scene(at.camera, scene.image, at.shapes), aovs=aovs, precision=precision))
    return kept[0]


@pytest.mark.parametrize("orbit", [False, True])  # the changed entries brought to the same view; whole passes
@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_frames_a_million_units_off_are_the_fresh_frames_bit_for_bit(precision, orbit):
    """Five of 2,000 spheres 1e6 from the origin cross the field and double in size: each frame's
    images are those of its scene prepared from nothing, whether the camera stays (the changed
    entries rebased in place on the host, which must give the device pass's bits) or moves."""
    need(precision)
    scene = far_field(1e6, orbit=orbit)
    kept = frames_equal_fresh(scene, precision)
    assert kept.on_device and not kept.from_world  # the per-view pass on the device, a view buffer: what this covers


def test_frames_written_through_scatter_launches_are_the_fresh_frames(monkeypatch):
    """A device whose buffers are not the host's arrays (a GPU) gets a frame's rows through the
    scatter kernel and the world entries before the next whole pass; here the CPU device is told so."""
    monkeypatch.setattr(refit, "shares_host_memory", lambda ctx: False)
    frames_equal_fresh(far_field(1e6, orbit=True))
    frames_equal_fresh(far_field(1e6))


def test_a_moved_mesh_keeps_each_triangle_in_its_place():
    """A flat mesh's triangles sit in the BVH's leaf order, not in their primitive order: a moved
    mesh's new rows must land on their own triangles (its primitive image is the fresh one's)."""
    frames_equal_fresh(far_field(0.0, mesh=True), aovs=("depth", "normal", "id", "primitive"))


def test_the_refit_tree_is_the_whole_trees_refit_and_writes_only_changed_nodes(monkeypatch):
    """After every frame, each box is exactly the union of its entries' widened boxes (a leaf) or of
    its children's (every node recomputed from scratch here), the kernel's node rows are that tree's
    packed around the anchor (the wide tree's render reads, and the binary tree's where shadows made
    it), and a frame rewrote at most the changed leaves' paths to the root."""
    scene = far_field(1e3, count=3000, moving=4)
    written = []
    state_refit = refit.RefitState.refit
    monkeypatch.setattr(refit.RefitState, "refit", lambda self, *a: written.append(state_refit(self, *a)) or written[-1])
    pyclray.clear_cache()
    for k, _ in pyclray.render_animation(scene, aovs=("depth",)):
        ready = next(t.prepared for t in api._tracers.values() if t.prepared.base is scene.shapes)
        tree, state = ready.bvh.tree, ready._refit
        if state is None:  # the first frame: prepared from nothing
            continue
        lo, hi = np.empty_like(tree.lo), np.empty_like(tree.hi)
        for node in np.argsort(-state.depth, kind="stable"):  # deepest first
            first, count = tree.first[node], tree.count[node]
            boxes = state.widened[first:first + count] if count else np.stack([[lo[first], hi[first]], [lo[first + 1], hi[first + 1]]])
            lo[node], hi[node] = boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)
        assert np.array_equal(lo, tree.lo) and np.array_equal(hi, tree.hi)
        assert np.array_equal(ready._wide_host, ready.bvh.nodes(ready.anchor))
        if ready._nodes_host is not None:  # made by shadow rays only
            assert np.array_equal(ready._nodes_host, ready.bvh.binary_nodes(ready.anchor))
        assert np.isclose(state.cost(), sah_cost(tree), rtol=1e-9)
    depth = int(state.depth.max())
    assert len(written) == scene.animation.frame_count() - 1 and all(nodes is not None and len(nodes) <= 4 * (depth + 1) for nodes in written)  # 4 leaves' paths


def test_render_animation_walks_no_shapes_after_its_first_frame(monkeypatch):
    """A frame of render_animation holds its shapes as the animated scene's tuple and the K changed
    ones (FrameShapes): after the first frame (which prepares the scene), nothing iterates them or
    makes a tuple of all N, so a frame costs O(K) host work plus the refit."""
    scene = far_field(0.0)
    pyclray.clear_cache()
    sequence = pyclray.render_animation(scene, aovs=("depth", "id"))
    next(sequence)

    def walked(*args):
        raise AssertionError("a frame walked the N shapes")

    monkeypatch.setattr(FrameShapes, "__iter__", walked)
    monkeypatch.setattr(FrameWork, "frame_tuple", walked)
    assert len(list(sequence)) == scene.animation.frame_count() - 1


def test_frame_shapes_are_the_frames_tuple_as_a_sequence():
    """FrameShapes reads as the tuple scene.at(t) makes: length, items (negative indices too),
    slices, iteration, equality; out-of-range indices raise IndexError as a tuple's do."""
    scene = far_field(0.0, count=40, moving=3)
    t = 0.5
    lazy = animation.scene_at(scene, t, lazy=True)
    eager = scene.at(t)
    assert isinstance(lazy.shapes, FrameShapes) and isinstance(eager.shapes, tuple)
    assert len(lazy.shapes) == len(eager.shapes) and tuple(lazy.shapes) == eager.shapes and lazy.shapes == eager.shapes
    assert all(lazy.shapes[i] == eager.shapes[i] for i in range(-len(eager.shapes), len(eager.shapes)))
    assert lazy.shapes[3:17:2] == eager.shapes[3:17:2]
    assert lazy == dataclasses.replace(eager)  # the scenes are equal too
    with pytest.raises(IndexError):
        lazy.shapes[len(eager.shapes)]
    # a tuple made after a lazy frame, and a lazy frame after a tuple, are each their own time's
    assert scene.at(0.25).shapes == tuple(animation.scene_at(scene, 0.25, lazy=True).shapes)
    assert scene.at(t).shapes == eager.shapes



@pytest.mark.parametrize("orbit", [False, True])
def test_frames_seen_by_a_still_camera_reuse_the_views_inputs(monkeypatch, orbit):
    """A frame whose camera, image, lights and shading are the animated scene's objects reuses the
    last frame's view inputs through the BVH (its camera struct and lights are made from those
    alone; its images are the fresh frame's: the tests above); a moving camera makes its own."""
    from pyclray.engine.scene import views

    made, original = [], views.ViewInputs
    monkeypatch.setattr(views, "ViewInputs", lambda *args: made.append(args[-1]) or original(*args))
    scene = far_field(0.0, orbit=orbit)
    pyclray.clear_cache()
    for _ in pyclray.render_animation(scene, aovs=("depth",)):
        pass
    assert made == ["bvh"] * (scene.animation.frame_count() if orbit else 1)
