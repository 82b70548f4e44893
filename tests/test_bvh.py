"""The BVH (pyclray/engine/bvh/tree.py): its structure, and traversal against float64 brute force; in the
kernels, render through the BVH gives the tile-culled render's images bit for bit.

Exact where exactness is possible: a node's box holds its children's boxes exactly (min/max of
float64 numbers), and the float64 traversal must find every shape whose own box the ray meets
(brute force over all shapes, the same slab test): no tolerance in either."""
import numpy as np
import pytest

import pyclray
from pyclray.engine.bvh import tree as bvh
from pyclray.engine.bvh import wide as bvh_wide
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.model.shapes import REGISTRY

from bvh_reference import traverse_reference
from conftest import SCENES


def random_bounds(seed: int, n: int) -> np.ndarray:
    """Spheres' boxes: clustered centres (a few Gaussian blobs and a uniform part) and radii
    spanning three decades, so that leaves and subtrees of very different sizes occur."""
    rng = np.random.default_rng(seed)
    blobs = rng.uniform(-50, 50, (4, 3))
    centres = np.where(
        rng.uniform(size=(n, 1)) < 0.5, blobs[rng.integers(0, 4, n)] + rng.normal(size=(n, 3)), rng.uniform(-60, 60, (n, 3))
    )
    radii = 10 ** rng.uniform(-2, 1, n)
    return np.stack([centres - radii[:, None], centres + radii[:, None]], axis=1)


def check_structure(tree: bvh.BVH, bounds: np.ndarray):
    n = len(bounds)
    leaf = tree.count > 0
    assert np.all(tree.count <= bvh.LEAF_SIZE)
    # every shape in exactly one leaf, the leaves' ranges partitioning order
    held = np.concatenate([tree.order[f: f + c] for f, c in zip(tree.first[leaf], tree.count[leaf])])
    assert np.array_equal(np.sort(held), np.arange(n))
    # each internal node's children: two nodes after it, each reached once, boxes inside its box
    inner = np.flatnonzero(~leaf)
    children = np.concatenate([tree.first[inner], tree.first[inner] + 1])
    assert np.all(children > np.concatenate([inner, inner]))
    assert np.array_equal(np.sort(children), np.arange(1, tree.nodes))
    for c in (tree.first[inner], tree.first[inner] + 1):
        assert np.all(tree.lo[inner] <= tree.lo[c]) and np.all(tree.hi[c] <= tree.hi[inner])
    # each leaf's box is exactly the union of its shapes' boxes
    for k in np.flatnonzero(leaf):
        mine = bounds[tree.order[tree.first[k]: tree.first[k] + tree.count[k]]]
        assert np.array_equal(tree.lo[k], mine[:, 0].min(axis=0)) and np.array_equal(tree.hi[k], mine[:, 1].max(axis=0))


@pytest.mark.parametrize("method", ["lbvh", "sah"])
@pytest.mark.parametrize("n", [1, 2, bvh.LEAF_SIZE, bvh.LEAF_SIZE + 1, 37, 1000, 20000])
def test_structure(n, method):
    bounds = random_bounds(n, n)
    check_structure(bvh.build(bounds, method=method), bounds)


@pytest.fixture(params=["lbvh", "sah"])
def builder(request, monkeypatch):
    """The scene's BVH built by each method, whatever the scene's size (SAH_FROM moved to 2)."""
    monkeypatch.setattr(bvh, "SAH_FROM", 2 if request.param == "sah" else 10**12)
    return request.param


def test_large_scenes_get_the_sah_tree():
    """build's default: the LBVH below SAH_FROM shapes, the binned SAH from there on."""
    bounds = random_bounds(3, bvh.SAH_FROM)
    assert bvh.sah_cost(bvh.build(bounds)) == bvh.sah_cost(bvh.build(bounds, method="sah"))
    assert bvh.sah_cost(bvh.build(bounds[:-1])) == bvh.sah_cost(bvh.build(bounds[:-1], method="lbvh"))
    with pytest.raises(ValueError, match="method"):
        bvh.build(bounds, method="octree")


def reference_sah():
    """bench/bvh_build.py's full binned SAH build (the repository's root on the path, as
    `python -m pytest` has it)."""
    import sys

    from conftest import REPO

    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))
    from bench.bvh_build import reference

    return reference


def torus_bounds(triangles: int, offset=0.0) -> np.ndarray:
    """The boxes of a torus' triangles (thin boxes of every orientation), moved by offset."""
    nu, nv = triangles // 40, 20
    theta, phi = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False), np.linspace(0, 2 * np.pi, nv, endpoint=False), indexing="ij")
    vertices = np.stack([(1 + 0.3 * np.cos(phi)) * np.cos(theta), 0.3 * np.sin(phi), (1 + 0.3 * np.cos(phi)) * np.sin(theta)], -1)
    a, b = vertices, np.roll(vertices, -1, axis=0)
    c, d = np.roll(b, -1, axis=1), np.roll(a, -1, axis=1)
    corners = np.concatenate([np.stack([a, b, c], 2), np.stack([a, c, d], 2)]).reshape(-1, 3, 3) + offset
    return np.stack([corners.min(axis=1), corners.max(axis=1)], axis=1)


@pytest.mark.parametrize("make", [lambda: random_bounds(7, 20000), lambda: torus_bounds(20000)], ids=["clustered spheres", "torus"])
def test_the_sah_tree_is_within_ten_percent_of_a_full_binned_sah_build(make):
    """Issue 23's quality target: the SAH cost of the tree (its expected box and shape tests per
    random ray) at most 1.1 times that of a full binned SAH build (bench/bvh_build.py's reference:
    32 bins on every axis at every node); the LBVH does not meet it on either."""
    bounds = bvh.widened(make())
    reference = bvh.sah_cost(reference_sah()(bounds))
    assert bvh.sah_cost(bvh.build(bounds, method="sah")) <= 1.1 * reference
    assert bvh.sah_cost(bvh.build(bounds, method="lbvh")) > 1.1 * reference  # the bound tells them apart


@pytest.mark.parametrize("make", [lambda: random_bounds(7, 20000), lambda: torus_bounds(20000)], ids=["clustered spheres", "torus"])
def test_the_scene_tree_is_within_ten_percent_of_a_full_binned_sah_build_at_its_costs(make):
    """A scene's SAH tree is built for render's packets (bvh.SCENE_LEAF_SIZE, SCENE_TRAVERSAL: a
    node's visit costs about four shape tests there): weighed with those costs, it is within 1.1
    times a full binned SAH build made for the same costs (which the LBVH is not)."""
    from pyclray.engine.bvh.scene import primitives_bvh

    bounds = make()
    leaf, cost = bvh.SCENE_LEAF_SIZE, bvh.SCENE_TRAVERSAL
    tree = primitives_bvh({"sphere": bounds}).tree
    assert tree.count.max() <= leaf and tree.count.max() > bvh.LEAF_SIZE  # built with the scene's leaves
    reference = bvh.sah_cost(reference_sah()(bvh.widened(bounds), leaf, traversal=cost), traversal=cost)
    assert bvh.sah_cost(tree, traversal=cost) <= 1.1 * reference
    assert bvh.sah_cost(bvh.build(bvh.widened(bounds), leaf, method="lbvh"), traversal=cost) > 1.1 * reference


@pytest.mark.parametrize("n", [5, 3000, 20000])  # the LBVH and the SAH tree
def test_one_bounded_type_has_its_entries_at_their_leaf_positions(n):
    """The render kernel reads a leaf's entries without its refs where the program has one bounded
    type (kernels/nearest.h: PYCLRAY_ONE_BOUNDED), and asks for them from memory where the
    traversal first meets the leaf: that needs refs[q] to be entry q of the type's array, q * 16 +
    its kind; with two types it is not so."""
    from pyclray.engine.bvh.scene import primitives_bvh

    bounds = bvh.widened(random_bounds(3, n))
    refs = primitives_bvh({"sphere": bounds}).refs(("plane", "sphere"))
    assert np.array_equal(refs, np.arange(n) * 16 + 2)
    two = primitives_bvh({"sphere": bounds, "box": bounds}).refs(("box", "sphere"))
    assert not np.array_equal(two >> 4, np.arange(2 * n))
    from pyclray.engine.launch.programs import Variant

    def defines(types):
        return Variant("render", types, ("depth",), "fp32", 8, bvh=True).defines()

    assert "#define PYCLRAY_ONE_BOUNDED KIND_sphere" in defines(("plane", "sphere"))
    assert not any("PYCLRAY_ONE_BOUNDED" in line for line in defines(("box", "sphere")))


def test_the_reference_build_is_a_valid_tree():
    """The reference the ten percent are measured against is a valid tree over the shapes (every
    shape in one leaf, boxes the exact unions), its leaves no larger than the kernels take."""
    bounds = random_bounds(4, 3000)
    check_structure(reference_sah()(bounds), bounds)


def test_the_sah_tree_is_the_same_whatever_the_threads():
    """Node numbers follow from the splits alone (bvh_sah._grow), not from which thread built what:
    one, two or three threads build the same arrays, bit for bit, and a valid tree."""
    from pyclray.engine.bvh import sah as bvh_sah

    bounds = random_bounds(8, 30000)
    trees = [bvh_sah.build(bounds, bvh.LEAF_SIZE, bvh.MAX_SAH_DEPTH, threads=t) for t in (1, 2, 3)]
    check_structure(bvh.BVH(*trees[0]), bounds)
    for other in trees[1:]:
        assert all(np.array_equal(a, b) for a, b in zip(trees[0], other))


def test_extreme_bounds_still_give_a_valid_sah_tree():
    """Boxes of 1e300, of 1e-200 and at 1e250 among ordinary ones: the float32 rows the SAH bins
    are kept finite (bvh_sah._rows), so every split stays consistent and the tree valid, its boxes
    the exact float64 unions."""
    bounds = random_bounds(3, 30000)
    bounds[:5] = [[-1e300] * 3, [1e300] * 3]
    bounds[5:10] *= 1e-200
    bounds[10:15] += 1e250
    check_structure(bvh.build(bounds, method="sah"), bounds)


def test_far_away_scenes_get_as_good_a_tree():
    """The SAH's binning works relative to the scene's centre, scaled to its size: a torus moved to
    1e7 gets a tree of the same cost as at the origin (float32 at 1e7 alone would merge its
    triangles' centres into a few values)."""
    near, far = torus_bounds(20000), torus_bounds(20000, offset=1e7)
    cost_near, cost_far = bvh.sah_cost(bvh.build(near, method="sah")), bvh.sah_cost(bvh.build(far, method="sah"))
    assert abs(cost_far / cost_near - 1) < 0.02


@pytest.mark.parametrize("max_depth", [12, 14, 20])
def test_the_sah_tree_keeps_within_its_depth(max_depth):
    """The kernels' stacks bound the depth (bvh.MAX_SAH_DEPTH): where the SAH's splits would go
    deeper, object median splits keep every leaf within max_depth levels; the tree stays valid.
    Boxes of sizes over twelve decades along a line make the SAH peel a few off at each split."""
    from pyclray.engine.bvh import sah as bvh_sah

    rng = np.random.default_rng(max_depth)
    x = np.sort(10 ** rng.uniform(-6, 6, 1000))
    size = 10 ** rng.uniform(-6, 0, 1000) * x
    bounds = np.stack([np.stack([x, -size, -size], 1), np.stack([x + size, size, size], 1)], 1)
    tree = bvh.BVH(*bvh_sah.build(bounds, bvh.LEAF_SIZE, max_depth))
    check_structure(tree, bounds)
    assert tree.depth() <= max_depth
    assert bvh.BVH(*bvh_sah.build(bounds, bvh.LEAF_SIZE, 200)).depth() > 14  # the guard was needed


@pytest.mark.parametrize("max_depth", [16, 20])
def test_sampled_splits_keep_within_the_depth(max_depth):
    """Nodes of at least 2 bvh_sah.SAMPLE primitives choose their split from a sample of their rows:
    the depth bound is then checked on the real sides after the partition (the sample's counts
    only estimate them). The same peeling boxes, 20 times as many: sampled nodes at the top."""
    from pyclray.engine.bvh import sah as bvh_sah

    rng = np.random.default_rng(max_depth)
    n = 20_000
    assert n >= 4 * bvh_sah.SAMPLE  # the root and its children are sampled
    x = np.sort(10 ** rng.uniform(-6, 6, n))
    size = 10 ** rng.uniform(-6, 0, n) * x
    bounds = np.stack([np.stack([x, -size, -size], 1), np.stack([x + size, size, size], 1)], 1)
    tree = bvh.BVH(*bvh_sah.build(bounds, bvh.LEAF_SIZE, max_depth))
    check_structure(tree, bounds)
    assert tree.depth() <= max_depth
    assert bvh.BVH(*bvh_sah.build(bounds, bvh.LEAF_SIZE, 200)).depth() > max_depth  # the guard was needed


@pytest.mark.parametrize("method", ["lbvh", "sah"])
def test_equal_centres_give_a_balanced_tree(method):
    """Shapes with one centre share a Morton code; the keys' low bits (their rank) still split
    them in halves: depth log2(n / leaf size) + 1, not n. The SAH finds no split between bins
    and halves them too."""
    bounds = np.zeros((4096, 2, 3))
    bounds[:, 1] = 1.0
    tree = bvh.build(bounds, method=method)
    check_structure(tree, bounds)
    assert tree.depth() == 11


def test_no_shapes():
    tree = bvh.build(np.zeros((0, 2, 3)))
    assert tree.nodes == 1 and tree.count[0] == 0 and tree.order.size == 0


def slab_hits(lo, hi, origin, direction, t_max=np.inf):
    """Brute force: whether the ray meets each box (N, 3) with 0 <= t <= t_max (float64)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (lo - origin) / direction
        t1 = (hi - origin) / direction
    parallel = direction == 0
    inside = (origin >= lo) & (origin <= hi)
    near = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t0, t1))
    far = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t0, t1))
    return np.maximum(near.max(axis=1), 0.0) <= np.minimum(far.min(axis=1), t_max)


@pytest.mark.parametrize("method", ["lbvh", "sah"])
@pytest.mark.parametrize("seed", range(3))
def test_traversal_finds_every_box_the_ray_meets(seed, method):
    bounds = random_bounds(100 + seed, 3000)
    tree = bvh.build(bounds, method=method)
    rng = np.random.default_rng(seed)
    for _ in range(40):
        origin = rng.uniform(-80, 80, 3)
        direction = rng.normal(size=3)
        if rng.uniform() < 0.2:  # axis-parallel rays: the slab test's special case
            direction[rng.integers(0, 3)] = 0.0
        t_max = rng.choice([np.inf, rng.uniform(1, 100)])
        expected = np.flatnonzero(slab_hits(bounds[:, 0], bounds[:, 1], origin, direction, t_max))
        found = traverse_reference(tree, origin, direction, t_max)
        assert set(expected) <= set(found)
        # and the traversal is not a scan of everything: the leaves it visits are those it must
        assert len(found) <= len(expected) + 40 * bvh.LEAF_SIZE


def test_outward_rounding_holds_the_float64_box():
    rng = np.random.default_rng(5)
    lo = rng.normal(size=(1000, 3)) * 10.0 ** rng.integers(-30, 30, (1000, 3))
    hi = lo + np.abs(rng.normal(size=(1000, 3))) * 10.0 ** rng.integers(-30, 30, (1000, 3))
    lo32, hi32 = bvh.outward32(lo, hi)
    assert np.all(lo32.astype(np.float64) <= lo) and np.all(hi32.astype(np.float64) >= hi)
    assert np.all(np.isfinite(lo32)) and np.all(np.isfinite(hi32))
    huge_lo, huge_hi = bvh.outward32(np.array([[-1e300, 0, 0]]), np.array([[1e300, 0, 0]]))
    assert huge_lo[0, 0] == -np.finfo(np.float32).max and huge_hi[0, 0] == np.finfo(np.float32).max


def test_every_shape_type_declares_its_bounds():
    """world_bounds holds the shape: for a sphere, centre -+ radius widened by no more than a few
    float64 ulps of rounding; unbounded types (the plane) stay out of the BVH. (Every shape's bounds
    are checked against points of its surface in tests/test_shapes.py.)"""
    sphere = pyclray.Sphere((1.0, -2.0, 3.0), 0.5)
    lo, hi = REGISTRY["sphere"].world_bounds([sphere])[0]
    exact_lo, exact_hi = np.array([0.5, -2.5, 2.5]), np.array([1.5, -1.5, 3.5])
    assert np.all(lo <= exact_lo) and np.all(hi >= exact_hi)
    assert np.allclose(lo, exact_lo, rtol=0, atol=1e-11) and np.allclose(hi, exact_hi, rtol=0, atol=1e-11)
    assert REGISTRY["sphere"].bounded and not REGISTRY["plane"].bounded


def crowded_scene(seed: int, count: int = 300, size: int = 64) -> pyclray.Scene:
    """Many spheres of sizes over four decades, some overlapping, one huge sphere the eye is just
    outside of, a ground plane, and an eye among them: grazing and near-tie pixels abound, where a
    box test that drops a shape would change an image."""
    rng = np.random.default_rng(seed)
    shapes = [pyclray.Plane((0, 1, 0), 1.0)]
    for _ in range(count):
        shapes.append(pyclray.Sphere(tuple(rng.uniform(-10, 10, 3)), float(10 ** rng.uniform(-2.5, 0.5))))
    shapes.append(pyclray.Sphere((0.0, -1000.0, 0.0), 1000.0 - 1e-3))
    shapes.insert(int(rng.integers(0, len(shapes))), pyclray.Sphere(shapes[1].center, shapes[1].radius))  # a copy: exact ties
    camera = pyclray.Camera(tuple(rng.uniform(-3, 3, 3) + [0, 3, 0]), tuple(rng.uniform(-5, 5, 3)), fov=float(rng.uniform(20, 100)))
    return pyclray.Scene(camera, pyclray.Image(size, size - 8), tuple(shapes))


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("seed", range(3))
def test_render_through_the_bvh_equals_the_tiles_bit_for_bit(builder, seed, precision):
    """The BVH's box tests are conservative (kernels/bvh.h) and the lowest id wins exact ties
    whatever the order of visit: every image is the tile-culled render's, bit for bit."""
    if precision == "fp64" and not has_fp64(context_for().device):
        pytest.skip("device lacks cl_khr_fp64")
    scene = crowded_scene(seed)
    tiles = pyclray.render(scene, precision=precision, acceleration="tiles")
    through = pyclray.render(scene, precision=precision, acceleration="bvh")
    for name in tiles:
        assert np.array_equal(tiles[name], through[name], equal_nan=True), name
    assert (tiles["id"] > 0).sum() > scene.image.width * scene.image.height // 4
    depth_only = pyclray.render(scene, aovs=("depth",), precision=precision, acceleration="bvh")
    assert np.array_equal(depth_only["depth"], tiles["depth"])


@pytest.mark.parametrize("seed", range(2))
def test_every_shape_type_renders_the_same_through_the_bvh(builder, seed):
    """Shapes of every bounded type of the registry, crowded (each type's random shapes, several
    times over, shifted about), through the BVH and through tile lists: the same bits."""
    rng = np.random.default_rng([seed, 17])
    shapes = [pyclray.Plane((0, 1, 0), 3.0)]
    for _ in range(12):
        for kind, cls in REGISTRY.items():
            if cls.bounded:
                shapes.append(cls.random(rng, rng.uniform(-6, 6, 3)))
    camera = pyclray.Camera((0.5, 4.0, 16.0), (0.0, 0.0, 0.0), fov=70.0)
    scene = pyclray.Scene(camera, pyclray.Image(61, 47), tuple(shapes))
    tiles = pyclray.render(scene, acceleration="tiles")
    through = pyclray.render(scene, acceleration="bvh")
    for name in tiles:
        assert np.array_equal(tiles[name], through[name], equal_nan=True), name
    assert len(np.unique(tiles["id"])) > 20


def test_a_moved_camera_reuses_the_tree():
    """Only the boxes are re-expressed around the new eye: the tree is built once per shapes tuple."""
    from dataclasses import replace

    from pyclray.engine.api import tracer_for
    from pyclray.engine.opencl.device import context_for

    def scene_bvh(scene):
        return tracer_for(scene, context_for(None), "fp32").prepared.bvh

    scene = crowded_scene(7, size=16)
    first = scene_bvh(scene)
    moved = replace(scene, camera=pyclray.Camera((9.0, 4.0, 9.0), (0.0, 0.0, 0.0)))
    assert scene_bvh(moved) is first
    tiles = pyclray.render(moved, acceleration="tiles")
    through = pyclray.render(moved, acceleration="bvh")
    assert np.array_equal(tiles["id"], through["id"]) and np.array_equal(tiles["depth"], through["depth"])


def test_bad_acceleration_is_a_clear_error():
    scene = crowded_scene(0, count=3, size=12)
    with pytest.raises(pyclray.PyclrayError, match="acceleration"):
        pyclray.render(scene, acceleration="octree")


@pytest.mark.parametrize("lanes", [1, 2, 4, 8])
def test_packets_of_every_width_traverse_to_the_same_bits(builder, monkeypatch, lanes):
    """A packet visits a node when any lane's widened ray enters it before that lane's nearest
    hit; the shapes are tested against the whole packet, so every lane sees every shape its own
    ray could hit: the images equal the tiles' at every lane width, and windows of the image too."""
    scene = crowded_scene(11, count=200, size=45)
    monkeypatch.setenv("PYCLRAY_LANES", str(lanes))
    tiles = pyclray.render(scene, acceleration="tiles")
    through = pyclray.render(scene, acceleration="bvh")
    window = pyclray.render(scene, acceleration="bvh", window=(3, 5, 29, 17))
    for name in tiles:
        assert np.array_equal(tiles[name], through[name]), name
        assert np.array_equal(window[name], through[name][5:22, 3:32]), name


def test_auto_takes_tiles_for_short_lists_and_the_bvh_for_long_ones():
    """Tiles where a tile's list is short (views.TILE_LIST_MAX shapes on average), the BVH where
    it is long: tp02's three spheres, and 3,000 spheres filling a small image."""
    from pyclray.engine.api import tracer_for
    from pyclray.engine.opencl.device import context_for
    from pyclray.engine.scene.views import ViewState

    def acceleration_for(scene, acceleration="auto"):
        return ViewState().acceleration(scene, acceleration, tracer_for(scene, context_for(None), "fp32").prepared)

    tp02 = pyclray.load_scene(SCENES / "tp02.toml").with_size(64, 64)
    assert acceleration_for(tp02) == "tiles"
    assert acceleration_for(crowded_scene(3, count=3000, size=64)) == "bvh"
    assert acceleration_for(tp02, "bvh") == "bvh"


@pytest.mark.parametrize("struct", [bvh.NODE, bvh_wide.WIDE_NODE], ids=lambda s: s.name)
def test_node_layouts_are_the_devices(struct):
    from test_layout import measure_on_device

    from pyclray.model.layout import layout

    spec = layout(struct, "fp32")
    assert measure_on_device(struct, "fp32") == [spec.dtype.itemsize] + [spec.dtype.fields[name][1] for name, _ in struct.fields]


@pytest.mark.parametrize("case", __import__("pyclray.reference.stability", fromlist=["CASES"]).CASES, ids=lambda c: c.name)
def test_the_stiff_cases_render_the_same_through_the_bvh(builder, case):
    """pyclray stability's scenes (far, huge, tiny, grazing, coincident shapes...) give the very
    same bits through the BVH as through tile lists: the BVH changes no exactness result."""
    scene = case.make()
    tiles = pyclray.render(scene, acceleration="tiles")
    through = pyclray.render(scene, acceleration="bvh")
    for name in tiles:
        assert np.array_equal(tiles[name], through[name]), name


@pytest.mark.parametrize("refit_max", [1.5, 0.0])  # refit in place; every frame rebuilt
def test_animation_refits_the_sah_tree(monkeypatch, refit_max):
    """The refit of an animation's frame (pyclray.engine.scene.refit) reads only the layout both builds
    share (children first and first + 1, leaves' ranges): over the SAH tree too, every frame
    equals its scene prepared from nothing, bit for bit (tests/test_views.py's test, on this tree)."""
    from test_views import test_animation_frames_update_the_prepared_scene_and_equal_fresh_frames as frames_test

    monkeypatch.setattr(bvh, "SAH_FROM", 2)
    frames_test(monkeypatch, 3000, refit_max, False)
