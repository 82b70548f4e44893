"""cast's blocks (engine/queries/cast_blocks.py, kernels/mesh.cl): a leaf's triangles of one mesh tested at
once give the bits of the triangles tested one by one (the ENTRY mode every other type uses), in
scenes where leaves mix meshes, other bounded types and exact ties; and the blocks hold what the
leaves held."""
import numpy as np
import pytest

import pyclray
from pyclray.engine.launch import programs
from pyclray.engine.queries.cast_blocks import regroup
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.engine.api import tracer_for
from pyclray.model.shapes.mesh import Mesh
from pyclray.model.shapes.mesh_shapes import perturbed_sphere, torus


def mixed_scene():
    """Two meshes whose triangles interleave (their leaves mix the two ids), a third holding copies
    of some of the first's triangles and of one of its own (exact ties: the lowest id, then the
    leaf's order), a zero-area triangle, a batch of spheres among them and a plane."""
    rng = np.random.default_rng(3)
    v1, f1 = perturbed_sphere(12, 24, 1.0, 0.2, rng)
    v2, f2 = torus(24, 12, 1.0, 0.35)
    copies = f1[::7]
    v3 = np.concatenate([v1, [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]]])
    n1 = len(v1)
    f3 = np.concatenate([copies, copies[:1], [[n1, n1 + 1, n1 + 2]]])  # a duplicate and a zero-area triangle
    shapes = (
        pyclray.Mesh(v1, f1, translate=(0.1, 0.0, 0.0), name="a"),
        pyclray.Mesh(v2, f2, translate=(0.1, 0.05, 0.0), name="b"),
        pyclray.Mesh(v3, f3, translate=(0.1, 0.0, 0.0), name="c"),
        pyclray.Spheres(rng.uniform(-1.5, 1.5, (60, 3)), np.full(60, 0.08), name="dots"),
        pyclray.Plane((0.0, 1.0, 0.0), -1.6),
    )
    return pyclray.Scene(pyclray.Camera((0, 0, 6), (0, 0, 0)), pyclray.Image(8, 8), shapes)


def rays(count, seed):
    rng = np.random.default_rng(seed)
    origins = rng.uniform(-2, 2, (count, 3))
    targets = rng.uniform(-1.2, 1.2, (count, 3))  # most rays meet the meshes, some from inside them
    return origins, targets - origins


def run_both(scene, origins, directions, precision):
    """cast's and occluded's results with the blocks, then with Mesh.cast_blocks off (every
    triangle its own entry: the kernel's ENTRY mode, programs built anew)."""
    out = []
    for _ in range(2):
        pyclray.clear_cache()
        frame = pyclray.cast(scene, origins, directions, precision=precision)
        out.append({**{k: frame[k] for k in ("depth", "normal", "id")},
                    "occluded": pyclray.occluded(scene, origins, directions, precision=precision)})
        Mesh.cast_blocks = False
        programs._programs.clear()
    return out


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_blocks_give_the_bits_of_one_triangle_at_a_time(precision, monkeypatch):
    """The block test is the triangle test in lanes (the same operations in the same order): every
    ray's depth, normal, id and occlusion are the same bits either way; a lost or misplaced triangle,
    a wrong lane, id or anchor, or a changed tie rule would change some of 6,000 rays."""
    if precision == "fp64" and not has_fp64(context_for().device):
        pytest.skip("device lacks cl_khr_fp64")
    monkeypatch.setattr(Mesh, "cast_blocks", True)
    monkeypatch.setattr(programs, "_programs", {})
    origins, directions = rays(6000, 1)
    blocks, entries = run_both(mixed_scene(), origins, directions, precision)
    pyclray.clear_cache()
    assert np.isfinite(blocks["depth"]).mean() > 0.5  # the rays do meet the shapes
    assert set(np.unique(blocks["id"])) >= {0, 1, 2, 3, 4}  # every shape wins somewhere (the copies: the ties)
    for name in entries:
        assert np.array_equal(blocks[name], entries[name], equal_nan=True), name


def test_the_blocks_hold_the_leaves_triangles():
    """Each leaf's refs, read back through the wide tree's renumbered codes: the blocks of a leaf
    hold its triangles of each mesh (their corners, through the block's vertices, each stored
    once), in the leaf's order, less the zero-area ones, with their mesh's id; the other types'
    entries keep their refs."""
    scene = mixed_scene()
    ctx = context_for()
    prepared = tracer_for(scene, ctx, "fp32").prepared
    tree, types = prepared.bvh, prepared.types
    worlds = {name: prepared.kinds[name].world for name in types}
    old_nodes = tree.nodes(np.zeros(3))
    nodes = old_nodes.copy()
    refs, anchors, per_type = regroup(tree, types, prepared.kinds, worlds, nodes)
    old_refs = tree.refs(types)
    kind_mesh = 1 + types.index("mesh")
    data = per_type["mesh"][0]
    words = data.view(np.int32)
    world, ids = worlds["mesh"], np.asarray(prepared.kinds["mesh"].ids)
    for old_code, code in zip(old_nodes["child"][old_nodes["child"] < 0], nodes["child"][nodes["child"] < 0]):
        first, count = (~old_code) >> 3, (~old_code) & 7
        new_first, new_count = (~code) >> 3, (~code) & 7
        leaf, got = old_refs[first:first + count], refs[new_first:new_first + new_count]
        assert sorted(r for r in leaf if r & 15 != kind_mesh) == sorted(r for r in got if r & 15 != kind_mesh)
        expected = {}
        for r in leaf[(leaf & 15) == kind_mesh] >> 4:
            if world["a"][r, 3] or world["b"][r, 3] or world["c"][r, 3]:
                expected.setdefault(int(ids[r]), []).append(r)
        found = {}
        for place in got[(got & 15) == kind_mesh] >> 4:
            head, mesh_id = words[16 * place], words[16 * place + 1]
            n, unique = head & 255, head >> 8
            vertices = data[8 * place + 1: 8 * place + 1 + 3 * unique].reshape(3, unique).T
            corners = data.view(np.uint8)[8 * (8 * place + 1 + 3 * unique):][: 3 * n].reshape(3, n).T
            assert len(np.unique(vertices, axis=0)) == unique  # each vertex once
            found[int(mesh_id)] = vertices[corners].reshape(n, 9).T
        assert set(found) >= set(expected)
        for mesh_id, entries in expected.items():
            corners = np.stack([world[v][entries, :3] for v in "abc"], 1).reshape(len(entries), 9)
            assert np.array_equal(found[mesh_id].T, corners)


def test_the_plain_built_ins_give_the_same_bits(monkeypatch):
    """Devices other than PoCL's CPU compile the blocks with OpenCL's own built-ins (the lowest set
    bit from clz, the library's square root: Variant.source's inline_builtins off): the same
    results, and the program builds."""
    origins, directions = rays(2000, 2)
    scene = mixed_scene()
    pyclray.clear_cache()
    fast = pyclray.cast(scene, origins, directions)
    monkeypatch.setattr(programs, "is_pocl_cpu", lambda _device: False)
    monkeypatch.setattr(programs, "_programs", {})
    pyclray.clear_cache()
    plain = pyclray.cast(scene, origins, directions)
    pyclray.clear_cache()
    for name in ("depth", "normal", "id"):
        assert np.array_equal(fast[name], plain[name], equal_nan=True), name


def test_interleaved_rays_give_the_bits_of_a_ray_alone():
    """Where leaves are blocks, a work-item's rays traverse interleaved, a step of each in turn
    (kernels/cast.cl's cast_group): a ray cast alone (its group of one, nothing to interleave)
    gives the bits it gives among a batch's others, so no step reads or writes another ray's
    state (a stack, a limit, a best hit or a moved origin shared or swapped would change some of
    these 120 rays, many of which meet the ties and the mixed leaves of mixed_scene)."""
    origins, directions = rays(120, 3)
    scene = mixed_scene()
    together = pyclray.cast(scene, origins, directions)
    assert np.isfinite(together["depth"]).mean() > 0.5
    for i in range(len(origins)):
        alone = pyclray.cast(scene, origins[i:i + 1], directions[i:i + 1])
        for name in ("depth", "normal", "id"):
            assert np.array_equal(alone[name][0], together[name][i], equal_nan=True), (name, i)
