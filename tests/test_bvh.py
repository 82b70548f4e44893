"""The BVH (pyclray/engine/bvh.py): its structure, and traversal against float64 brute force; in the
kernels, render through the BVH gives the tile-culled render's images bit for bit.

Exact where exactness is possible: a node's box holds its children's boxes exactly (min/max of
float64 numbers), and the float64 traversal must find every shape whose own box the ray meets
(brute force over all shapes, the same slab test): no tolerance in either."""
import numpy as np
import pytest

import pyclray
from pyclray.engine import bvh
from pyclray.engine import bvh_wide
from pyclray.engine.device import context_for, has_fp64
from pyclray.model.shapes import REGISTRY

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


@pytest.mark.parametrize("n", [1, 2, bvh.LEAF_SIZE, bvh.LEAF_SIZE + 1, 37, 1000])
def test_structure(n):
    bounds = random_bounds(n, n)
    check_structure(bvh.build(bounds), bounds)


def test_equal_centres_give_a_balanced_tree():
    """Shapes with one centre share a Morton code; the keys' low bits (their rank) still split
    them in halves: depth log2(n / leaf size) + 1, not n."""
    bounds = np.zeros((4096, 2, 3))
    bounds[:, 1] = 1.0
    tree = bvh.build(bounds)
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


@pytest.mark.parametrize("seed", range(3))
def test_traversal_finds_every_box_the_ray_meets(seed):
    bounds = random_bounds(100 + seed, 3000)
    tree = bvh.build(bounds)
    rng = np.random.default_rng(seed)
    for _ in range(40):
        origin = rng.uniform(-80, 80, 3)
        direction = rng.normal(size=3)
        if rng.uniform() < 0.2:  # axis-parallel rays: the slab test's special case
            direction[rng.integers(0, 3)] = 0.0
        t_max = rng.choice([np.inf, rng.uniform(1, 100)])
        expected = np.flatnonzero(slab_hits(bounds[:, 0], bounds[:, 1], origin, direction, t_max))
        found = bvh.traverse_reference(tree, origin, direction, t_max)
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
def test_render_through_the_bvh_equals_the_tiles_bit_for_bit(seed, precision):
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
def test_every_shape_type_renders_the_same_through_the_bvh(seed):
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
    import sys
    from dataclasses import replace

    render_module = sys.modules["pyclray.engine.views"]

    scene = crowded_scene(7, size=16)
    first = render_module.scene_bvh(scene)
    moved = replace(scene, camera=pyclray.Camera((9.0, 4.0, 9.0), (0.0, 0.0, 0.0)))
    assert render_module.scene_bvh(moved) is first
    tiles = pyclray.render(moved, acceleration="tiles")
    through = pyclray.render(moved, acceleration="bvh")
    assert np.array_equal(tiles["id"], through["id"]) and np.array_equal(tiles["depth"], through["depth"])


def test_bad_acceleration_is_a_clear_error():
    scene = crowded_scene(0, count=3, size=12)
    with pytest.raises(pyclray.PyclrayError, match="acceleration"):
        pyclray.render(scene, acceleration="octree")


@pytest.mark.parametrize("lanes", [1, 2, 4, 8])
def test_packets_of_every_width_traverse_to_the_same_bits(monkeypatch, lanes):
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
    import sys

    render_module = sys.modules["pyclray.engine.views"]
    tp02 = pyclray.load_scene(SCENES / "tp02.toml").with_size(64, 64)
    assert render_module.acceleration_for(tp02) == "tiles"
    assert render_module.acceleration_for(crowded_scene(3, count=3000, size=64)) == "bvh"
    assert render_module.acceleration_for(tp02, "bvh") == "bvh"


@pytest.mark.parametrize("struct", [bvh.NODE, bvh_wide.WIDE_NODE], ids=lambda s: s.name)
def test_node_layouts_are_the_devices(struct):
    from test_layout import measure_on_device

    from pyclray.model.layout import layout

    spec = layout(struct, "fp32")
    assert measure_on_device(struct, "fp32") == [spec.dtype.itemsize] + [spec.dtype.fields[name][1] for name, _ in struct.fields]


@pytest.mark.parametrize("case", __import__("pyclray.reference.stability", fromlist=["CASES"]).CASES, ids=lambda c: c.name)
def test_the_stiff_cases_render_the_same_through_the_bvh(case):
    """pyclray stability's scenes (far, huge, tiny, grazing, coincident shapes...) give the very
    same bits through the BVH as through tile lists: the BVH changes no exactness result."""
    scene = case.make()
    tiles = pyclray.render(scene, acceleration="tiles")
    through = pyclray.render(scene, acceleration="bvh")
    for name in tiles:
        assert np.array_equal(tiles[name], through[name]), name
