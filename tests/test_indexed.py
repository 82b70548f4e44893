"""Meshes as shared vertices and faces (pyclray.engine.scene.indexed), the path of every device with float64,
and the compiled passes over a large scene's boxes (pyclray.engine.bvh.passes). What this holds: the
indexed path's bounds and node boxes are the bits of the numpy code they replace (so the tree and the
images do not depend on which ran), its host and device vertex passes agree bit for bit, its images
are the per-view copy's (tests/test_framed.py holds every image of every shape to that), and its
memory meets issue 23's 64 bytes a triangle."""
from __future__ import annotations

import numpy as np
import pytest

import pyclray
from pyclray.engine import api
from pyclray.engine.bvh import tree as bvh
from pyclray.engine.bvh import passes as bvh_fast
from pyclray.engine.scene import indexed
from pyclray.engine.scene import prepared
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.model.shapes.device import padded_bounds
from pyclray.model.shapes.mesh import Mesh
from pyclray.model.shapes.mesh_shapes import perturbed_sphere

from test_views import ALL, fresh, same


def need_fp64():
    if not has_fp64(context_for(None).device):
        pytest.skip("device lacks cl_khr_fp64: meshes keep the per-view copy there")


def sphere_mesh(rings=60, segments=120, offset=(0.0, 0.0, 0.0), seed=3) -> Mesh:
    vertices, faces = perturbed_sphere(rings, segments, 1.0, 0.05, np.random.default_rng(seed))
    return Mesh(vertices + np.asarray(offset), faces, name="ball")


def test_indexed_bounds_are_the_world_entries_bounds_bit_for_bit():
    """The bounds from vertices and faces (numpy below COMPILED_FROM, numba above) are
    Mesh.bounds_of of the 96-byte world entries, which the per-view copy's tree is built over:
    the same tree either way. A zero-area triangle and a far offset included."""
    mesh = sphere_mesh(offset=(3e7, -1e5, 2.5))
    vertices, faces = Mesh.pack_indexed([mesh])
    faces[5, 1] = faces[5, 0]  # a degenerate face: its bounds still its corners'
    expected = Mesh.bounds_of(Mesh.pack_world([Mesh(mesh.world_vertices(), faces[:, :3], name="ball")]))
    assert np.array_equal(indexed.indexed_bounds(vertices, faces[:100]), expected[:100])  # numpy
    out = np.empty_like(expected)
    bvh_fast.triangle_bounds(vertices, faces, out)
    assert len(faces) >= 1000 and np.array_equal(out, expected)


def test_the_compiled_widening_and_node_packing_keep_numpys_bits():
    """bvh.widened and bvh.pack_nodes above SAH_FROM (bvh_fast) against their numpy formulas, on
    boxes of every scale, beyond float32's range, infinite and NaN (where numpy's NaN wins, theirs
    does too)."""
    rng = np.random.default_rng(7)
    lo = rng.normal(size=(4000, 3)) * 10.0 ** rng.integers(-30, 45, (4000, 3))
    hi = lo + np.abs(rng.normal(size=(4000, 3))) * 10.0 ** rng.integers(-30, 45, (4000, 3))
    lo[:3], hi[:3] = [[np.inf] * 3, [-np.inf, 0, 0], [np.nan, 0, 0]], [[np.inf] * 3, [np.inf, 1, 1], [1, 1, 1]]
    bounds = np.stack([lo, hi], axis=1)
    with np.errstate(over="ignore", invalid="ignore"):
        extent = bounds[:, 1] - bounds[:, 0]
        size = extent.max(axis=1, initial=0.0)[:, None] * bvh.WIDEN
        expected = np.stack([bounds[:, 0] - size, bounds[:, 1] + size], axis=1)
        out = np.empty_like(bounds)
        bvh_fast.widen(bounds, bvh.WIDEN, out)
    assert np.array_equal(out, expected, equal_nan=True)
    tree = bvh.BVH(lo, hi, np.arange(4000, dtype=np.int32), np.ones(4000, np.int32), np.arange(4000))
    origin = np.array([1e5, -3.0, 0.25])
    packed = bvh.pack_nodes(tree, origin)  # 4000 nodes: compiled only from SAH_FROM on
    assert tree.nodes < bvh.SAH_FROM
    words = np.zeros((4000, 8), np.float32)
    with np.errstate(over="ignore", invalid="ignore"):
        bvh_fast.pack_binary(lo, hi, tree.first, tree.count, origin, words, words.view(np.int32))
    assert words.tobytes() == packed.tobytes()


def test_the_compiled_wide_node_packing_keeps_numpys_bits(monkeypatch):
    """bvh_wide.pack_wide from SAH_FROM nodes on (bvh_fast.pack_wide_boxes) against its numpy form,
    whole and by rows (an animation's refit), on a real tree's slots (empty ones included) given
    boxes of every scale, beyond float32's range and infinite: the kernels see the same bits."""
    from pyclray.engine.bvh import wide as bvh_wide

    rng = np.random.default_rng(11)
    centres = rng.uniform(-1, 1, (20_000, 3))
    tree = bvh.build(np.stack([centres - 0.01, centres + 0.01], axis=1))
    assert tree.nodes >= bvh.SAH_FROM  # what this compares: the compiled pass
    m = tree.nodes
    lo = rng.normal(size=(m, 3)) * 10.0 ** rng.integers(-30, 45, (m, 3))
    hi = lo + np.abs(rng.normal(size=(m, 3))) * 10.0 ** rng.integers(-30, 45, (m, 3))
    lo[:2], hi[:2] = [[-np.inf] * 3, [1e39, 0, 0]], [[np.inf] * 3, [1e40, 1, 1]]
    tree = bvh.BVH(lo, hi, tree.first, tree.count, tree.order)
    wide = bvh_wide.collapse(tree)
    assert (wide.binary < 0).any()  # empty slots are packed too
    rows = np.arange(0, len(wide.binary), 5)
    origin = np.array([1e5, -3.0, 0.25])
    with np.errstate(over="ignore", invalid="ignore"):
        compiled, by_rows = bvh_wide.pack_wide(tree, wide, origin), bvh_wide.pack_wide(tree, wide, origin, rows)
        monkeypatch.setattr(bvh_wide, "SAH_FROM", 1 << 62)  # the numpy form
        expected = bvh_wide.pack_wide(tree, wide, origin)
    assert compiled.tobytes() == expected.tobytes() and by_rows.tobytes() == expected[rows].tobytes()


def test_a_mesh_beside_a_few_shapes_holds_at_most_64_bytes_a_triangle():
    """Issue 23's memory target for every mesh, not only those of from_world scenes: a
    closed mesh of 57,120 triangles (half as many vertices, as a scan) on a ground plane, counted as
    PreparedScene.nbytes counts (vertices in the world and in the frame, faces, ids, BVH nodes,
    materials; no refs: the plane is unbounded, the mesh the one bounded type). python -m
    bench.meshes: the 80,000-triangle bunny 56.8 bytes a triangle."""
    need_fp64()
    mesh = sphere_mesh(rings=120, segments=240)
    scene = pyclray.Scene(pyclray.Camera((0.0, 1.0, 4.0), (0.0, 0.0, 0.0)), pyclray.Image(32, 32),
                          (pyclray.Plane((0.0, 1.0, 0.0), 1.5), mesh))
    pyclray.clear_cache()
    pyclray.render(scene, aovs=("depth",))
    held = api.tracer_for(scene, context_for(None), "fp32").prepared
    assert held.kinds["mesh"].indexed is not None and not held.from_world  # indexed without being from_world
    assert held.nbytes() / len(mesh.faces) <= 64


@pytest.mark.parametrize("shared", [True, False])
@pytest.mark.parametrize("count", [20, 2000])
def test_a_moved_indexed_mesh_is_refitted_in_place(monkeypatch, shared, count):
    """An animation that moves a mesh rewrites its shared vertices in place (the world's, and the
    held view's: the host's in_space, the device pass's bits) and refits the tree above its faces,
    on a device whose buffers are the host's arrays and (shared False) on one they are copied to:
    each frame is its scene prepared from nothing, bit for bit."""
    need_fp64()
    from pyclray.engine.scene import refit
    from pyclray.engine.opencl.buffers import shares_host_memory

    if shared and not shares_host_memory(context_for(None)):
        # only refit is told the buffers are the arrays: on a device whose buffers are copies (a GPU)
        # that is a device the code never meets, and rows written on the host never reach it
        pytest.skip("device lacks buffers in host memory (its buffers are copies): the shared case is a CPU device's")
    from test_animation_frames import far_field, frames_equal_fresh

    monkeypatch.setattr(refit, "shares_host_memory", lambda ctx: shared)
    kept = frames_equal_fresh(far_field(1e5, count=count, mesh=True), aovs=("depth", "normal", "id", "primitive"))
    assert kept.kinds["mesh"].indexed is not None and kept.on_device  # what this covers
