"""One ray per work-item through the pair nodes (engine/bvh/pairs.py, kernels/bvh_pairs.h): the
traversal a lane width of 1 (a GPU's) compiles in, for a render through the BVH, the ray queries
(cast, occluded, count_hits, all_hits) and the closest-point queries' search (a point per
work-item: closest_points, distance, signed_distance, occupancy). PoCL at PYCLRAY_LANES=1 builds the
same programs as a GPU.

Why every result is the same bits as the 8-lane path's (the wide tree's packets, the CPU's): the
pair nodes hold the binary tree's boxes rounded as the wide nodes hold them, tested by the same
operations, with the same leaves; every shape test is the same function, and every tie rule
(render's id and key, cast's id, the closest point's id and primitive) picks one winner whatever
order the leaves are visited in. So the tests compare bits (np.array_equal of the raw bytes), no
tolerance: a traversal that dropped a leaf a ray's hit lies in, or tested a box otherwise, would
show in some pixel or ray."""
from __future__ import annotations

import numpy as np
import pytest

import pyclray
from pyclray.engine.api import tracer_for
from pyclray.engine.bvh.pairs import PAIR_NODE, leaf_codes, pack_pairs
from pyclray.engine.bvh.tree import build
from pyclray.engine.launch import programs
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.model.layout import layout
from pyclray.model.lights import DirectionalLight, PointLight, Shading
from pyclray.model.shapes.mesh_shapes import grid, perturbed_sphere

EVERY = ("depth", "normal", "id", "primitive", "barycentric")


def need(precision):
    if precision == "fp64" and not has_fp64(context_for(None).device):
        pytest.skip("device lacks cl_khr_fp64")


def at_width(monkeypatch, lanes: int, fn):
    with monkeypatch.context() as patch:
        patch.setenv("PYCLRAY_LANES", str(lanes))
        return fn()


def same_bits(a, b, what=""):
    """Two results (a Frame or mapping of arrays, or an array) with the same bits."""
    if not isinstance(a, np.ndarray):
        assert set(a.keys()) == set(b.keys()), what
        for key in a.keys():
            same_bits(np.asarray(a[key]), np.asarray(b[key]), f"{what} {key}")
        return
    assert a.dtype == b.dtype and a.shape == b.shape, what
    assert np.array_equal(np.ascontiguousarray(a).view(np.uint8), np.ascontiguousarray(b).view(np.uint8)), what


def bunny(scenes_dir):
    base = pyclray.Mesh.load(scenes_dir / "meshes" / "bunny.ply")
    return pyclray.Mesh(base.vertices, base.faces, name="bunny")


def instances():
    """A perturbed sphere placed 9 times (rotated, scaled, mirrored: mesh instances) on a grid floor."""
    rng = np.random.default_rng(7)
    v, f = perturbed_sphere(10, 14, 0.8, 0.25, rng)
    base = pyclray.Mesh(v, f)
    shapes = [base.placed(scale=[(1.0, 1.0, 1.0), (1.3, 0.6, 0.9), (-1.0, 1.0, 1.0)][(i + j) % 3],
                          axis=tuple(rng.normal(size=3)), angle=float(rng.uniform(0, 360)),
                          translate=(2.2 * (i - 1), 0.8, 2.2 * (j - 1)))
              for i in range(3) for j in range(3)]
    v, f = grid(6, 6, 12.0)
    return shapes + [pyclray.Mesh(v, f)]


def mixed(scenes_dir):
    """Analytic shapes among meshes, a sphere batch and a plane (unbounded: outside the tree)."""
    mesh = bunny(scenes_dir)
    lo, hi = mesh.box()
    rng = np.random.default_rng(3)
    centres = rng.uniform(lo, hi, (200, 3))
    return [mesh, pyclray.Spheres(centres, np.full(200, 0.004)),
            pyclray.Sphere(tuple(0.5 * (lo + hi) + [0.1, 0, 0]), 0.03),
            pyclray.Box(tuple(0.5 * (lo + hi) - [0.08, 0, 0]), (0.03, 0.04, 0.05), axis=(1, 1, 0), angle=30.0),
            pyclray.Cylinder(tuple(lo), tuple(hi), 0.01),
            pyclray.Disk(tuple(0.5 * (lo + hi) + [0, 0.05, 0.05]), (0, 0, 1), 0.03),
            pyclray.Rectangle(tuple(0.5 * (lo + hi) + [0, -0.05, 0.05]), (0.03, 0, 0), (0, 0.02, 0.01)),
            pyclray.Plane((0, 1, 0), -float(lo[1]))]


def scene_of(shapes, size=(97, 61), **keys) -> pyclray.Scene:
    """A view of the shapes' box from a corner (the plane, unbounded, left out of the box)."""
    boxes = [s.box() for s in shapes if s.bounded]
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    centre, size_ = 0.5 * (lo + hi), float(np.linalg.norm(hi - lo))
    eye = centre + size_ * np.array([0.6, 0.5, 1.1])
    return pyclray.Scene(pyclray.Camera(tuple(eye), tuple(centre), (0, 1, 0), 40.0), pyclray.Image(*size), tuple(shapes),
                         **keys)


def rays_at(scene, count=2000, seed=0, far=None):
    """Rays from around the scene's box into it (and some away), or from `far` away toward it."""
    rng = np.random.default_rng(seed)
    boxes = [s.box() for s in scene.shapes if s.bounded]
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    targets = rng.uniform(lo, hi, (count, 3))
    if far is None:
        origins = rng.uniform(lo - (hi - lo), hi + (hi - lo), (count, 3))
    else:
        away = rng.normal(size=(count, 3))
        origins = 0.5 * (lo + hi) + far * away / np.linalg.norm(away, axis=1)[:, None]
    directions = targets - origins
    directions[::7] *= -1  # some leave the scene
    return origins, directions


def queries(scene, precision, origins, directions, hits=True):
    """Every query through the tree: the render through the BVH (every image), cast, occluded
    (within a limit), count_hits and all_hits."""
    out = {"render": pyclray.render(scene, EVERY, precision, acceleration="bvh"),
           "cast": pyclray.cast(scene, origins, directions, aovs=EVERY, precision=precision),
           "occluded": pyclray.occluded(scene, origins, directions, tmax=np.linalg.norm(directions, axis=1) * 0.5,
                                        precision=precision)}
    if hits:
        out["count_hits"] = pyclray.count_hits(scene, origins, directions, precision=precision)
        out["all_hits"] = pyclray.all_hits(scene, origins, directions, aovs=("depth", "id", "primitive"),
                                           precision=precision)
    return out


def widest(precision) -> int:
    """The CPU's lane width at this precision (8 floats, 4 doubles)."""
    return programs.MAX_LANE_BITS // (32 if precision == "fp32" else 64)


def assert_same_at_widths(monkeypatch, scene, precision, origins, directions, hits=True):
    one = at_width(monkeypatch, 1, lambda: queries(scene, precision, origins, directions, hits))
    eight = at_width(monkeypatch, widest(precision), lambda: queries(scene, precision, origins, directions, hits))
    for name in one:
        same_bits(one[name], eight[name], name)
    return one


def recorded_builds(monkeypatch) -> list:
    """The (variant, source) of each program built from now on in this test (programs._build
    recorded, then called as ever)."""
    built = []
    original = programs._build

    def recording(ctx, variant):
        built.append((variant, variant.source()))
        return original(ctx, variant)

    monkeypatch.setattr(programs, "_build", recording)
    return built


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_a_mesh_gives_the_same_bits(monkeypatch, scenes_dir, precision):
    """The bunny (its triangles cast in blocks): every image of a render, cast, occluded and the hit counts."""
    need(precision)
    scene = scene_of([bunny(scenes_dir)])
    origins, directions = rays_at(scene)
    one = assert_same_at_widths(monkeypatch, scene, precision, origins, directions)
    assert (one["render"]["id"] >= 0).mean() > 0.2 and np.isfinite(one["cast"]["depth"]).mean() > 0.3


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_mesh_instances_give_the_same_bits(monkeypatch, precision):
    """Mesh instances (Mesh.placed: the scene's tree over instances, each instance's own tree inside)."""
    need(precision)
    scene = scene_of(instances())
    assert "instance" in tracer_for(scene, context_for(), precision).prepared.types
    origins, directions = rays_at(scene, seed=1)
    one = assert_same_at_widths(monkeypatch, scene, precision, origins, directions)
    assert len(np.unique(one["render"]["id"])) > 8


def instances_of_meshes(scenes_dir, offset=(0.0, 0.0, 0.0)):
    """Three shared meshes, each placed several times (rotated, scaled, mirrored: a negative
    determinant), about offset: a perturbed sphere (168 triangles), the bunny (5,000 triangles: a tree
    15 levels deep) and a mesh of a single triangle (its tree a leaf); and a floor of its own (not an
    instance)."""
    rng = np.random.default_rng(21)
    v, f = perturbed_sphere(8, 12, 0.6, 0.2, rng)
    ball = pyclray.Mesh(v, f)
    rabbit = bunny(scenes_dir)
    lo, hi = rabbit.box()
    rabbit = pyclray.Mesh(1.2 / np.max(hi - lo) * (rabbit.vertices - 0.5 * (lo + hi)), rabbit.faces)  # 1.2 across
    triangle = pyclray.Mesh(np.array([[-0.5, -0.4, 0.0], [0.6, -0.3, 0.1], [0.0, 0.7, -0.2]]), np.array([[0, 1, 2]]))
    scales = [(1.0, 1.0, 1.0), (1.3, 0.6, 0.9), (-1.0, 1.0, 1.0), (0.8, -1.1, 1.2)]
    shapes = []
    for m, mesh in enumerate((ball, rabbit, triangle)):
        for i in range(4):
            shapes.append(mesh.placed(scale=scales[(i + m) % 4], axis=tuple(rng.normal(size=3)),
                                      angle=float(rng.uniform(0, 360)),
                                      translate=tuple(np.add(offset, (1.6 * (i - 1.5), 0.7 + 0.2 * m, 1.6 * (m - 1))))))
    v, f = grid(4, 4, 8.0)
    shapes.append(pyclray.Mesh(v + np.array(offset), f))
    return shapes


def grazing_rays(scene):
    """Rays along the world boxes' faces and edges of the instances (axis-parallel, and within a
    few float steps of it), and rays through their meshes' vertices: the box tests at their limits."""
    rng = np.random.default_rng(13)
    origins, directions = [], []
    for shape in scene.shapes[:-1]:
        lo, hi = shape.box()
        for axis in range(3):
            for side in (lo, hi):
                for other in range(3):
                    if other == axis:
                        continue
                    start = 0.5 * (lo + hi)
                    start[axis] = side[axis]  # on the face's plane
                    start[other] = lo[other] - 1.0  # before the box, running along `other`
                    d = np.zeros(3)
                    d[other] = 1.0
                    for tilt in (0.0, 1e-7, -1e-7):
                        direction = d.copy()
                        direction[axis] = tilt
                        origins.append(start)
                        directions.append(direction)
        corner = np.where(rng.uniform(size=3) < 0.5, lo, hi)  # along an edge of the box
        origins.append(corner - 2.0 * np.eye(3)[0])
        directions.append(np.eye(3)[0])
    for shape in scene.shapes[:-1]:  # through some of each placed mesh's vertices
        m = shape.transform()
        picked = shape.vertices[rng.choice(len(shape.vertices), 4)]
        through = picked @ m[:3, :3].T + m[:3, 3]
        start = through + rng.normal(size=(4, 3))
        origins += list(start)
        directions += list(through - start)
    return np.array(origins), np.array(directions)


def lit(shapes, **keys):
    """A scene of these shapes lit by a point light and a directional one, with shadows."""
    lights = (PointLight(position=(3.0, 4.0, 3.0), intensity=(20.0, 20.0, 20.0), name="point"),
              DirectionalLight(direction=(-0.3, -1.0, -0.5), irradiance=(0.8, 0.8, 0.8), name="sun"))
    return scene_of(shapes, lights=lights, shading=Shading(shadows=True), **keys)


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_instances_of_several_meshes_give_the_same_bits(monkeypatch, scenes_dir, precision):
    """Instances of three meshes (a deep tree, a tree of one leaf; rotated, scaled and mirrored
    placements) through their pair nodes at one lane: every query, the shaded image with shadows
    onto and among them, rays grazing their boxes and through their vertices, and occupancy."""
    need(precision)
    scene = lit(instances_of_meshes(scenes_dir))
    prepared = tracer_for(scene, context_for(), precision).prepared
    assert "instance" in prepared.types and prepared.kinds["instance"].count == 12
    random_rays = rays_at(scene, 1500, seed=10)
    grazing = grazing_rays(scene)
    origins, directions = (np.concatenate([a, b]) for a, b in zip(random_rays, grazing))
    one = assert_same_at_widths(monkeypatch, scene, precision, origins, directions)
    assert len(np.unique(one["render"]["id"])) >= 12 and len(np.unique(one["cast"]["id"])) >= 12
    assert np.isfinite(one["cast"]["depth"][-len(grazing[0]):]).mean() > 0.3  # the grazing rays hit
    run = lambda: pyclray.render(scene, ("shaded", "depth", "id"), precision, acceleration="bvh")  # noqa: E731
    shaded = at_width(monkeypatch, 1, run)
    same_bits(shaded, at_width(monkeypatch, widest(precision), run), "shaded")
    assert np.ptp(shaded["shaded"]) > 0
    points = np.concatenate([origins[:1000], origins[:1000] + 0.02 * directions[:1000]])
    inside = at_width(monkeypatch, 1, lambda: pyclray.occupancy(scene, points, precision=precision))
    same_bits(inside, at_width(monkeypatch, widest(precision), lambda: pyclray.occupancy(scene, points, precision=precision)),
              "occupancy")


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_instances_far_from_the_origin_give_the_same_bits(monkeypatch, scenes_dir, precision):
    """The same instances placed 1e6 from the origin (a view and rays among them), and rays from 1e6
    away toward them near the origin."""
    need(precision)
    far = lit(instances_of_meshes(scenes_dir, offset=(1e6, -1e6, 1e6)))
    origins, directions = rays_at(far, 1000, seed=11)
    one = assert_same_at_widths(monkeypatch, far, precision, origins, directions)
    assert np.isfinite(one["cast"]["depth"]).mean() > 0.2
    run = lambda: pyclray.render(far, ("shaded", "depth", "id"), precision, acceleration="bvh")  # noqa: E731
    same_bits(at_width(monkeypatch, 1, run), at_width(monkeypatch, widest(precision), run), "shaded")
    near = scene_of(instances_of_meshes(scenes_dir))
    origins, directions = rays_at(near, 1000, seed=12, far=1e6)
    one = assert_same_at_widths(monkeypatch, near, precision, origins, directions, hits=False)
    assert np.isfinite(one["cast"]["depth"]).any()


def test_a_sphere_batch_gives_the_same_bits(monkeypatch):
    """20,000 spheres of one batch (the SAH tree: leaves of up to 7)."""
    rng = np.random.default_rng(5)
    shapes = [pyclray.Spheres(rng.uniform(-1, 1, (20_000, 3)), rng.uniform(0.002, 0.02, 20_000))]
    scene = scene_of(shapes, size=(128, 96))
    origins, directions = rays_at(scene, 5000, seed=2)
    one = assert_same_at_widths(monkeypatch, scene, "fp32", origins, directions)
    assert (one["render"]["id"] >= 0).mean() > 0.3


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_analytic_shapes_among_meshes_give_the_same_bits(monkeypatch, scenes_dir, precision):
    need(precision)
    scene = scene_of(mixed(scenes_dir))
    origins, directions = rays_at(scene, seed=3)
    one = assert_same_at_widths(monkeypatch, scene, precision, origins, directions)
    assert len(np.unique(one["cast"]["id"])) >= 6


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_a_shaded_render_with_shadows_gives_the_same_bits(monkeypatch, scenes_dir, precision):
    """Camera rays through the pair nodes, shadow rays from their hits (the binary tree's packets of one)."""
    need(precision)
    lights = (PointLight(position=(3.0, 4.0, 3.0), intensity=(20.0, 20.0, 20.0)),)
    for shapes in (mixed(scenes_dir), instances()):
        scene = scene_of(shapes, lights=lights, shading=Shading(shadows=True))
        run = lambda: pyclray.render(scene, ("shaded", "depth", "id"), precision, acceleration="bvh")  # noqa: E731
        one, eight = at_width(monkeypatch, 1, run), at_width(monkeypatch, 8 if precision == "fp32" else 4, run)
        same_bits(one, eight, "shaded")
        assert np.ptp(one["shaded"]) > 0


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_rays_from_far_away_give_the_same_bits(monkeypatch, scenes_dir, precision):
    """Origins 1e6 from the bunny (the box tests' margins at their largest), and a render from there."""
    need(precision)
    shapes = mixed(scenes_dir)[:-1]
    scene = scene_of(shapes)
    origins, directions = rays_at(scene, seed=4, far=1e6)
    one = assert_same_at_widths(monkeypatch, scene, precision, origins, directions, hits=False)
    assert np.isfinite(one["cast"]["depth"]).any()
    lo, hi = shapes[0].box()
    centre = 0.5 * (lo + hi)
    far = pyclray.Scene(pyclray.Camera(tuple(centre + [0, 0, 1e6]), tuple(centre), (0, 1, 0), 0.00002),
                        pyclray.Image(64, 48), tuple(shapes))
    run = lambda: pyclray.render(far, EVERY, precision, acceleration="bvh")  # noqa: E731
    same_bits(at_width(monkeypatch, 1, run), at_width(monkeypatch, 8 if precision == "fp32" else 4, run), "far render")


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_the_gpu_class_host_path_gives_the_same_bits(monkeypatch, scenes_dir, precision):
    """A GPU's whole path on PoCL: one lane and the GPU class's host path ($PYCLRAY_GPU_CLASS=1: the rays
    uploaded and cast in their order, engine/queries/cast_device.py) against the CPU's 8 lanes and host path."""
    need(precision)
    scene = scene_of(mixed(scenes_dir) + instances()[:2])
    origins, directions = rays_at(scene, 5000, seed=8)  # (5000: a batch the CPU's host path orders)
    with monkeypatch.context() as patch:
        patch.setenv("PYCLRAY_GPU_CLASS", "1")
        one = at_width(monkeypatch, 1, lambda: queries(scene, precision, origins, directions))
    eight = at_width(monkeypatch, 8 if precision == "fp32" else 4, lambda: queries(scene, precision, origins, directions))
    for name in one:
        same_bits(one[name], eight[name], name)


def test_occupancy_gives_the_same_answers(monkeypatch):
    """occupancy's parity rays (count_hits with the surface test: the leaves entered at 0 noted as the
    traversal reaches them, kernels/allhits.cl) through the pair nodes: the 8-lane path's answers, on
    points inside, outside and on the surface of a closed mesh."""
    rng = np.random.default_rng(11)
    v, f = perturbed_sphere(16, 24, 1.0, 0.1, rng)
    scene = scene_of([pyclray.Mesh(v, f)])  # one closed mesh: the count kernel's surface test decides
    on = v[: len(v) // 2]  # its vertices: on the surface, whatever their parity rays' counts
    points = np.concatenate([rng.uniform(-1.5, 1.5, (3000, 3)), on])
    one = at_width(monkeypatch, 1, lambda: pyclray.occupancy(scene, points))
    eight = at_width(monkeypatch, 8, lambda: pyclray.occupancy(scene, points))
    same_bits(one, eight, "occupancy")
    assert 0.05 < one.mean() < 0.95 and one[-len(on):].all()


def test_a_refitted_frame_gives_the_same_bits(monkeypatch):
    """An animation's frame refitted in place (some spheres moved): the handle's pair nodes are made
    anew from the refitted boxes, and its render and cast at one lane are a fresh handle's at 8."""
    rng = np.random.default_rng(9)
    shapes = [pyclray.Sphere(tuple(rng.uniform(-1, 1, 3)), float(rng.uniform(0.05, 0.2))) for _ in range(60)]
    scene = scene_of(shapes)
    moved = list(shapes)
    for i in (3, 17, 40):
        moved[i] = pyclray.Sphere(tuple(np.array(shapes[i].center) + [0.6, -0.3, 0.2]), shapes[i].radius)
    later = pyclray.Scene(scene.camera, scene.image, tuple(moved))
    origins, directions = rays_at(later, 500, seed=6)

    def one_lane():
        tracer = pyclray.prepare(scene)
        tracer.render(aovs=EVERY, acceleration="bvh")  # the pair nodes made for the first frame
        tracer.cast(origins, directions, aovs=EVERY)
        assert tracer.refit(later.shapes, [3, 17, 40])  # in place
        return {"render": tracer.render(aovs=EVERY, acceleration="bvh"),
                "cast": tracer.cast(origins, directions, aovs=EVERY)}

    one = at_width(monkeypatch, 1, one_lane)
    eight = at_width(monkeypatch, 8, lambda: {"render": pyclray.render(later, EVERY, acceleration="bvh"),
                                              "cast": pyclray.cast(later, origins, directions, aovs=EVERY)})
    for name in one:
        same_bits(one[name], eight[name], name)


def test_the_lane_width_one_programs_traverse_the_pair_nodes(monkeypatch, scenes_dir):
    """At a lane width of 1 the programs built for a render through the BVH and for every ray query
    are the pair nodes' (their source has bvh_pairs.h's marker and the kernel takes PairNode nodes;
    a ray query's work-item traces one ray);
    at 8 (and with PYCLRAY_TRAVERSAL=wide) none is: the tests above compare two traversals."""
    scene = scene_of([bunny(scenes_dir)])
    lights = (PointLight(position=(3.0, 4.0, 3.0), intensity=(20.0, 20.0, 20.0)),)
    shaded = scene_of([bunny(scenes_dir)], lights=lights, shading=Shading(shadows=True))
    origins, directions = rays_at(scene, 100)
    built = recorded_builds(monkeypatch)

    def run():
        programs.clear()
        built.clear()
        queries(scene, "fp32", origins, directions)
        pyclray.render(shaded, ("shaded",), acceleration="bvh")
        return {(v.query, v.shadows): source for v, source in built if v.query != "rebase"}

    one = at_width(monkeypatch, 1, run)
    assert {query for query, _ in one} == {"render", "cast", "occluded", "count_hits", "all_hits"}
    assert ("render", True) in one
    for query, source in one.items():
        assert "#define PYCLRAY_PAIR_TRAVERSAL 1" in source and "PairNode*" in source, query
        assert "WideNode* nodes" not in source and "BvhNode* nodes" not in source, query  # shadow rays too
        if query[0] != "render":  # one ray per work-item (kernels/rays.h: CAST_GROUP)
            assert "#define CAST_GROUP 1\n" in source, query
    eight = at_width(monkeypatch, 8, run)
    for query, source in eight.items():
        assert "PYCLRAY_PAIR_TRAVERSAL" not in source and "#define CAST_GROUP 1\n" not in source, query
    with monkeypatch.context() as patch:
        patch.setenv("PYCLRAY_TRAVERSAL", "wide")
        for query, source in at_width(monkeypatch, 1, run).items():
            assert "PYCLRAY_PAIR_TRAVERSAL" not in source, query
    programs.clear()


def test_the_lane_width_one_programs_traverse_the_instances_pair_nodes(monkeypatch, scenes_dir):
    """At a lane width of 1 every program that traverses pair nodes takes the instances' own trees as
    pair nodes too (instance_nodes of PairNode, under PYCLRAY_PAIRS: kernels/instance.cl's
    INSTANCE_TRAVERSE is bvh_pairs.h's), shadow rays' included; a render through tile lists (no pair
    nodes) keeps their binary nodes, as every program at 8 lanes and with PYCLRAY_TRAVERSAL=wide
    does; a scene without instances compiles none of their code."""
    scene = lit(instances_of_meshes(scenes_dir)[8:])  # the one-triangle mesh's instances and the floor
    plain = scene_of([bunny(scenes_dir)])
    origins, directions = rays_at(scene, 100)
    built = recorded_builds(monkeypatch)

    def run(target=scene):
        programs.clear()
        built.clear()
        queries(target, "fp32", origins, directions)
        pyclray.render(target, ("shaded",), acceleration="bvh")
        pyclray.render(target, ("depth",), acceleration="tiles")
        return {(v.query, v.shadows, v.bvh): source for v, source in built if v.query != "rebase"}

    pair_tree, binary_tree = "__global const PairNode* instance_nodes", "__global const BvhNode* instance_nodes"
    one = at_width(monkeypatch, 1, run)
    assert {query for query, _, _ in one} == {"render", "cast", "occluded", "count_hits", "all_hits"}
    assert ("render", True, True) in one and ("render", False, False) in one
    for key, source in one.items():
        through_pairs = key[0] != "render" or key[2]
        assert (pair_tree in source) == through_pairs and (binary_tree in source) != through_pairs, key
        assert ("#define PYCLRAY_PAIRS 1" in source) == through_pairs, key
    for width, traversal in ((8, ""), (1, "wide")):
        with monkeypatch.context() as patch:
            patch.setenv("PYCLRAY_TRAVERSAL", traversal)
            for key, source in at_width(monkeypatch, width, run).items():
                assert binary_tree in source and pair_tree not in source and "#define PYCLRAY_PAIRS 1" not in source, key
    for key, source in at_width(monkeypatch, 1, lambda: run(plain)).items():
        assert "#define INSTANCE_TRAVERSE" not in source and "instance_nodes" not in source, key
    programs.clear()


def test_the_instances_pair_nodes_start_at_half_their_root():
    """Each shared mesh's tree takes an even count of binary nodes (a spare one after its own), and its
    pair nodes start at root / 2, within the tree's half of the slots: pair node p of binary node k
    holds k's children's boxes and codes (a pair node's index from the tree's first, or a leaf's
    ~(first * 8 + count)), so that the kernel finds them from the instance's root alone."""
    from pyclray.engine.scene import instances as instance_trees

    rng = np.random.default_rng(4)
    meshes = []
    for rings in (3, 12):  # a small tree and a larger one
        v, f = perturbed_sphere(rings, rings + 2, 1.0, 0.2, rng)
        meshes.append(pyclray.Mesh(v, f))
    meshes.append(pyclray.Mesh(np.eye(3), np.array([[0, 1, 2]])))  # one triangle: a tree that is a leaf
    scene = scene_of([m.placed(translate=(float(i), 0.0, 0.0)) for m in meshes for i in range(2)])
    kind = tracer_for(scene, context_for(), "fp32").prepared.kinds["instance"]
    binary, roots = kind.shared_host[2], np.unique(kind.world["root"])  # (instances.SHARED's order)
    assert len(roots) == 3 and not (roots % 2).any() and len(binary) % 2 == 0
    pairs = instance_trees.pair_nodes(binary, kind.world["root"])
    assert len(pairs) == len(binary) // 2

    def code_of(node, name):
        return int(node[f"{name}_lo"][3:].view(np.int32)[0])

    def first_count(k):
        return int(binary[k]["lo"][3:].view(np.int32)[0]), int(binary[k]["hi"][3:].view(np.int32)[0])

    for root, end in zip(roots, [*roots[1:], len(binary)]):
        base, leaves = root // 2, []

        def walk(k, p):  # binary node root + k is pair node base + p
            assert 0 <= p < (end - root) // 2
            first, _ = first_count(root + k)
            for side, name in ((0, "left"), (1, "right")):
                child = root + first + side
                assert np.array_equal(pairs[base + p][f"{name}_lo"][:3], binary[child]["lo"][:3])
                assert np.array_equal(pairs[base + p][f"{name}_hi"][:3], binary[child]["hi"][:3])
                child_first, child_count = first_count(child)
                if child_count:
                    assert code_of(pairs[base + p], name) == ~(child_first * 8 + child_count)
                    leaves.append(child)
                else:
                    assert code_of(pairs[base + p], name) > p  # children after their parents
                    walk(first + side, code_of(pairs[base + p], name))

        first, count = first_count(root)
        if count:  # a tree that is a leaf: one pair node, the leaf its first child, no second
            assert code_of(pairs[base], "left") == ~(first * 8 + count) and code_of(pairs[base], "right") == 0
            assert np.array_equal(pairs[base]["left_lo"][:3], binary[root]["lo"][:3])
        else:
            walk(0, 0)
            assert len(leaves) == (end - root) // 2  # every leaf of the tree (2L - 1 nodes and a spare one)


def test_the_pair_nodes_hold_the_binary_trees_boxes_and_leaves():
    """Each internal binary node is one pair node holding both children's packed boxes and codes
    (a node's index, or its leaf's wide code); a tree of one leaf is one node with no second child."""
    rng = np.random.default_rng(0)
    lo = rng.uniform(-1, 1, (500, 3))
    tree = build(np.stack([lo, lo + 0.01], axis=1), 4)
    from pyclray.engine.bvh.tree import pack_nodes

    binary = pack_nodes(tree, np.zeros(3))
    pairs = pack_pairs(tree, binary, leaf_codes(tree))
    assert pairs.dtype.itemsize == 64 and layout(PAIR_NODE, "fp32").itemsize == 64
    inner = np.flatnonzero(tree.count == 0)
    assert len(pairs) == len(inner)
    index = {int(k): i for i, k in enumerate(inner)}
    seen_leaves = []
    for i, k in enumerate(inner):
        for side, name in ((0, "left"), (1, "right")):
            child = int(tree.first[k]) + side
            assert np.array_equal(pairs[i][f"{name}_lo"][:3], binary[child]["lo"][:3])
            assert np.array_equal(pairs[i][f"{name}_hi"][:3], binary[child]["hi"][:3])
            code = int(pairs[i][f"{name}_lo"][3:].view(np.int32)[0])
            if tree.count[child]:
                assert code == ~(int(tree.first[child]) * 8 + int(tree.count[child]))
                seen_leaves.append(child)
            else:
                assert code == index[child] and code > i  # children after their parents
    assert sorted(seen_leaves) == sorted(np.flatnonzero(tree.count > 0).tolist())
    one = build(np.stack([lo[:3], lo[:3] + 0.01], axis=1), 4)
    single = pack_pairs(one, pack_nodes(one, np.zeros(3)), leaf_codes(one))
    assert len(single) == 1 and int(single[0]["right_lo"][3:].view(np.int32)[0]) == 0


# -- the closest-point queries (engine/queries/closest.py): a point per work-item, through the pair
# nodes of the query's own BVH at one lane (kernels/bvh_pairs.h: PAIR_CLOSEST_TRAVERSE), against the
# wide tree's search at 8. Both keep every child box whose distance can still beat or tie the best,
# and closest_take's tie rule picks one winner whatever the order: every output is the same bits.
def closest_queries(scene, precision, points, signs=("parity",)):
    """closest_points (every output), distance, signed_distance and occupancy (each sign asked)."""
    out = {f"closest {k}": v for k, v in pyclray.closest_points(scene, points, precision=precision).items()}
    out["distance"] = pyclray.distance(scene, points, precision=precision)
    for sign in signs:
        out[f"signed {sign}"] = pyclray.signed_distance(scene, points, sign, precision=precision)
        out[f"occupancy {sign}"] = pyclray.occupancy(scene, points, sign, precision=precision)
    return out


def at_default_width(monkeypatch, fn):
    """fn at the device's own lane width (8 lanes fp32, 4 fp64 on PoCL's CPU; no $PYCLRAY_LANES: the
    occupancy's exact pass takes its own fp64 handle, which a width of 8 would not fit)."""
    with monkeypatch.context() as patch:
        patch.delenv("PYCLRAY_LANES", raising=False)
        assert programs.lanes_for(context_for().device, "fp32") == 8
        return fn()


def assert_closest_same_at_widths(monkeypatch, scene, precision, points, signs=("parity",)):
    one = at_width(monkeypatch, 1, lambda: closest_queries(scene, precision, points, signs))
    eight = at_default_width(monkeypatch, lambda: closest_queries(scene, precision, points, signs))
    same_bits(one, eight, "closest")
    return one


def surface_points(mesh, offset: float, rng) -> np.ndarray:
    """A mesh's vertices, its edges' midpoints and its faces' centroids (on its surface, to rounding),
    and the centroids moved off the face by offset either way."""
    v = mesh.world_vertices()
    a, b, c = (v[mesh.faces[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    centroid = (a + b + c) / 3
    off = centroid + offset * rng.choice([-1.0, 1.0], (len(centroid), 1)) * normal
    return np.concatenate([v, 0.5 * (a + b), 0.5 * (b + c), centroid, off])


def points_around(shapes, count, rng, grow=0.3):
    """Uniform points in the bounded shapes' box grown by grow of its size each way."""
    boxes = [s.box() for s in shapes if s.bounded]
    lo, hi = np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)
    return rng.uniform(lo - grow * (hi - lo), hi + grow * (hi - lo), (count, 3))


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_closest_queries_on_a_mesh_give_the_same_bits(monkeypatch, scenes_dir, precision):
    """The bunny: uniform points around it, its vertices, edges' midpoints and faces' centroids, and
    points just off its faces (more than COHERENT_FROM: the points' Morton order on the host)."""
    need(precision)
    mesh = bunny(scenes_dir)
    rng = np.random.default_rng(21)
    points = np.concatenate([points_around([mesh], 3000, rng), surface_points(mesh, 1e-3, rng)])
    assert len(points) > 4096
    one = assert_closest_same_at_widths(monkeypatch, scene_of([mesh]), precision, points)
    assert (one["distance"][3000:3000 + len(mesh.vertices)] == 0).all()  # its vertices: on the surface
    assert 0.05 < one["occupancy parity"].mean() < 0.95 and (one["signed parity"] < 0).any()


@pytest.mark.parametrize("tree", ["shared", "own"])
def test_closest_queries_among_analytic_shapes_give_the_same_bits(monkeypatch, scenes_dir, tree):
    """Meshes, a sphere batch, spheres, boxes, cylinders, disks, rectangles and a plane: through the
    prepared scene's BVH (two meshes of their own arrays: "shared"), or through the query's own tree
    where mesh instances share their arrays ("own": the instances' triangles as the query's entries,
    ClosestInputs); both signs (an open mesh's winding number keeps the wide nodes: its expansions
    are theirs)."""
    rng = np.random.default_rng(22)
    v, f = perturbed_sphere(10, 14, 0.05, 0.2, rng)
    shapes = mixed(scenes_dir)
    lo, hi = shapes[0].box()
    base = pyclray.Mesh(v, f)
    extra = ([pyclray.Mesh(v, f, translate=tuple(hi))] if tree == "shared"  # arrays of its own
             else [base.placed(translate=tuple(hi)), base.placed(translate=tuple(lo), scale=1.5)])  # instances
    shapes = shapes + extra + [pyclray.Mesh(*grid(4, 4, 0.2), translate=tuple(0.5 * (lo + hi))),  # open: winding's
                               pyclray.Sphere(tuple(lo), 0.05), pyclray.Box(tuple(hi), (0.02, 0.03, 0.04)),
                               pyclray.Cylinder(tuple(hi), tuple(hi + [0.1, 0.0, 0.0]), 0.02, caps=False),
                               pyclray.Disk(tuple(lo), (1, 1, 0), 0.04)]
    scene = scene_of(shapes)
    inputs = tracer_for(scene, context_for(), "fp32").closest_inputs()
    assert (inputs.bvh is tracer_for(scene, context_for(), "fp32").prepared.bvh) == (tree == "shared")
    points = np.concatenate([points_around(shapes[:-1], 3000, rng), surface_points(shapes[0], 1e-4, rng)[::4]])
    one = assert_closest_same_at_widths(monkeypatch, scene, "fp32", points, ("parity", "winding"))
    assert len(np.unique(one["closest id"])) >= 10 and 0 < one["occupancy winding"].mean() < 1


def test_closest_queries_on_a_sphere_batch_give_the_same_bits(monkeypatch):
    """20,000 spheres of one batch (leaves of up to 7): points around them, their centres (every
    point of the sphere equally near) and points on them."""
    rng = np.random.default_rng(23)
    centres, radii = rng.uniform(-1, 1, (20_000, 3)), rng.uniform(0.002, 0.02, 20_000)
    shapes = [pyclray.Spheres(centres, radii)]
    away = rng.normal(size=(2000, 3))
    on = centres[:2000] + radii[:2000, None] * away / np.linalg.norm(away, axis=1)[:, None]
    points = np.concatenate([points_around(shapes, 3000, rng), centres[::10], on])
    one = assert_closest_same_at_widths(monkeypatch, scene_of(shapes), "fp32", points)
    assert len(np.unique(one["closest primitive"])) > 1000 and one["occupancy parity"].any()


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_closest_queries_far_away_give_the_same_bits(monkeypatch, scenes_dir, precision):
    """The bunny and a sphere 1e6 from the origin, points near them (the box distances' margins at
    their largest), and points 1e6 from the bunny at the origin (far outside the scene's box)."""
    need(precision)
    rng = np.random.default_rng(24)
    base = bunny(scenes_dir)
    offset = np.array([1e6, -1e6, 1e6])
    moved = [pyclray.Mesh(base.vertices, base.faces, translate=tuple(offset)), pyclray.Sphere(tuple(offset + 0.6), 0.1)]
    points = np.concatenate([points_around(moved, 2000, rng), surface_points(moved[0], 1e-3, rng)[::8]])
    one = assert_closest_same_at_widths(monkeypatch, scene_of(moved), precision, points)
    assert (one["distance"] < 1.0).mean() > 0.9
    away = rng.normal(size=(1000, 3))
    far = 1e6 * away / np.linalg.norm(away, axis=1)[:, None]
    one = assert_closest_same_at_widths(monkeypatch, scene_of([base]), precision, far)
    assert (one["distance"] > 9e5).all()


@pytest.mark.parametrize("meshes", [1, 2])
def test_closest_ties_give_the_same_bits(monkeypatch, meshes):
    """Two parallel grids (y = 1 and y = -1, coordinates multiples of 1/8: every point below exact,
    the tree's leaves split between them). Points midway (y = 0): every one inside is as near to a
    triangle of each, and to several at a vertex or an edge; the tie rule keeps the lower id (two
    meshes), then the lower primitive (one mesh: the upper grid's triangles come first), whatever
    order either traversal visits them in. Points exactly on the upper grid: on its vertices, its
    edges (their midpoints, the cells' diagonals included) and its faces, at distance 0."""
    v, f = grid(8, 8, 2.0)
    top, bottom = v + [0.0, 1.0, 0.0], v - [0.0, 1.0, 0.0]
    if meshes == 2:
        shapes = [pyclray.Mesh(top, f), pyclray.Mesh(bottom, f.copy())]
    else:
        shapes = [pyclray.Mesh(np.concatenate([top, bottom]), np.concatenate([f, f + len(v)]))]
    rng = np.random.default_rng(25)
    corners = v[f][:, :, [0, 2]]  # (F, 3, 2): each triangle's corners' x, z
    edges = np.concatenate([(corners[:, k] + corners[:, (k + 1) % 3]) / 2 for k in range(3)])
    xz = np.concatenate([v[:, [0, 2]], edges, rng.uniform(-1.2, 1.2, (3000, 2))])
    midway = np.stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]], axis=1)
    on = np.stack([xz[:, 0], np.ones(len(xz)), xz[:, 1]], axis=1)
    one = assert_closest_same_at_widths(monkeypatch, scene_of(shapes), "fp32", np.concatenate([midway, on]))
    inside = np.all(np.abs(xz) <= 1.0, axis=1)
    assert (one["distance"][: len(xz)][inside] == 1.0).all() and (one["distance"][len(xz):][inside] == 0.0).all()
    if meshes == 2:
        assert (one["closest id"][: len(xz)][inside] == 0).all()
    else:
        assert (one["closest primitive"][: len(xz)][inside] < len(f)).all()


def test_the_gpu_class_host_path_gives_the_same_closest_bits(monkeypatch, scenes_dir):
    """A GPU's whole path on PoCL for the closest-point queries: one lane and the GPU class's host
    path ($PYCLRAY_GPU_CLASS=1: no Morton order, the parity rays through count_hits' device path)
    against the CPU's 8 lanes and host path; a batch the CPU orders."""
    scene = scene_of(mixed(scenes_dir) + instances()[:2])
    rng = np.random.default_rng(26)
    points = points_around(scene.shapes, 5000, rng)
    with monkeypatch.context() as patch:
        patch.setenv("PYCLRAY_GPU_CLASS", "1")
        one = at_width(monkeypatch, 1, lambda: closest_queries(scene, "fp32", points, ("parity", "winding")))
    eight = at_default_width(monkeypatch, lambda: closest_queries(scene, "fp32", points, ("parity", "winding")))
    same_bits(one, eight, "closest")


def test_the_lane_width_one_closest_programs_search_the_pair_nodes(monkeypatch, scenes_dir):
    """At a lane width of 1 the closest-point query's programs (the nearest point, the distance, the
    inside test) search the pair nodes (PYCLRAY_PAIRS: bvh_pairs.h's PAIR_CLOSEST_TRAVERSE, PairNode
    nodes), but the winding number's, which keeps the wide nodes; at 8, and with
    PYCLRAY_TRAVERSAL=wide, none does."""
    scene = scene_of(mixed(scenes_dir) + [pyclray.Mesh(*grid(4, 4, 0.2))])  # an open mesh: the winding number's kernel
    points = points_around(scene.shapes, 100, np.random.default_rng(27))
    built = recorded_builds(monkeypatch)

    def run():
        programs.clear()
        built.clear()
        closest_queries(scene, "fp32", points, ("parity", "winding"))
        return {v.aovs: source for v, source in built if v.query == "closest"}

    one = at_width(monkeypatch, 1, run)
    assert ("distance",) in one and ("inside",) in one and ("winding",) in one and len(one) >= 4
    for aovs, source in one.items():
        pairs = "winding" not in aovs
        assert ("#define PYCLRAY_PAIRS 1" in source and "#define PAIR_CLOSEST_TRAVERSE" in source) == pairs, aovs
        assert ("PairNode* nodes" in source) == pairs and ("WideNode* nodes" in source) != pairs, aovs
    for aovs, source in at_default_width(monkeypatch, run).items():
        assert "#define PYCLRAY_PAIRS" not in source and "PairNode" not in source, aovs
    with monkeypatch.context() as patch:
        patch.setenv("PYCLRAY_TRAVERSAL", "wide")
        for aovs, source in at_width(monkeypatch, 1, run).items():
            assert "#define PYCLRAY_PAIRS" not in source and "WideNode* nodes" in source, aovs
    programs.clear()


def test_a_one_lane_handle_holds_the_closest_querys_pair_nodes_alone(monkeypatch, scenes_dir):
    """The closest-point query's nodes are made when first asked: at one lane its pair nodes (the
    bytes of its own BVH's pair nodes), at 8 its wide nodes; neither handle holds the other's."""
    scene = scene_of([bunny(scenes_dir)])
    points = points_around(scene.shapes, 200, np.random.default_rng(28))

    def held():
        with pyclray.prepare(scene) as tracer:
            tracer.closest_inputs()
            before = tracer.nbytes
            tracer.distance(points)
            inputs = tracer.closest_inputs()
            return tracer.nbytes - before, inputs.bvh.pair_nodes(inputs.anchor).nbytes, inputs.bvh.nodes(inputs.anchor).nbytes

    one, pairs, wide = at_width(monkeypatch, 1, held)
    eight = at_width(monkeypatch, 8, held)[0]
    assert one == pairs and eight == wide and pairs != wide
