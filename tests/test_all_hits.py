"""pyclray.all_hits and count_hits (kernels/allhits.cl, engine/queries/hits.py): every hit along a ray,
each crossing of a surface once.

Against the float64 oracle (pyclray.reference.oracle.all_hits: each shape's oracle_crossings, a
mesh's triangles by the same tie rule in exact rational arithmetic): the same hits (count, id,
primitive, order) on random rays, whose chance of passing within rounding of an edge or a tangent
is far below one in these batches, and depths within the one error model (error_model's cast
tolerances, per hit). On closed meshes the parity of the count is the truth for every ray,
including rays aimed exactly at each vertex and each edge's midpoint (where the watertight test
alone would count a crossing twice or not at all): even from outside, odd from inside, in fp32
and fp64, at the world's origin and 1e6 away from it.
"""
import numpy as np
import pytest

import pyclray
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.model.shapes.mesh_shapes import perturbed_sphere, torus, uv_sphere
from pyclray.reference import error_model, oracle

PRECISIONS = ("fp32", "fp64")


def need(precision):
    if precision == "fp64" and not has_fp64(context_for().device):
        pytest.skip("device lacks cl_khr_fp64")


def camera(shift=0.0):
    shift = np.broadcast_to(shift, 3)
    return pyclray.Camera(tuple(shift + [0.0, 0.0, 12.0]), tuple(shift))


def cube():
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    f = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6], [0, 2, 6],
         [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    return v, np.array(f)


def icosphere(levels=2):
    """An icosahedron subdivided levels times, projected on the unit sphere (closed, 20 * 4^levels faces)."""
    t = (1 + 5**0.5) / 2
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
         [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6],
         [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
         [8, 6, 7], [9, 8, 1]]
    v = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(levels):
        middle, faces = {}, []

        def mid(i, j):
            key = (min(i, j), max(i, j))
            if key not in middle:
                p = v[i] + v[j]
                v.append(p / np.linalg.norm(p))
                middle[key] = len(v) - 1
            return middle[key]

        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            faces += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = faces
    return np.array(v), np.array(f)


def targets(v, f):
    """Every vertex and every edge's midpoint (float64)."""
    edges = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    return np.concatenate([v, 0.5 * (v[edges[:, 0]] + v[edges[:, 1]])])


CLOSED = {"cube": cube, "icosphere": icosphere, "uv sphere": lambda: uv_sphere(8, 12),
          "perturbed sphere": lambda: perturbed_sphere(9, 13, 1.0, 0.3, np.random.default_rng(3))}


def every_shape_scene(shift=0.0):
    """Every shape type (a torus mesh, its instances, a batch of spheres and the analytic shapes)."""
    s = np.broadcast_to(shift, 3)

    def at(p):
        return tuple(np.add(p, s))

    v, f = torus(20, 10)
    base = pyclray.Mesh(v, f)
    shapes = (
        pyclray.Mesh(v + s, f, name="torus"),
        base.placed(scale=(1.3, 0.6, -0.9), axis=(1.0, 2.0, 3.0), angle=40.0, translate=at((0, 0, 2.5))),
        base.placed(scale=0.5, translate=at((2.5, 2.5, 0))),
        pyclray.Sphere(at((3, 0, 0)), 1.0),
        pyclray.Spheres(np.array([[0, 3, 0], [0.5, 3.2, 0.3]]) + s, np.array([0.5, 0.7])),
        pyclray.Box(at((-3, 0, 0)), (1.0, 2.0, 1.0), (1.0, 1.0, 0.0), 30.0),
        pyclray.Cylinder(at((0, -3, 0)), at((0, -4, 1)), 0.5),
        pyclray.Cylinder(at((-3, -3, 0)), at((-3, -4, 1)), 0.6, caps=False),
        pyclray.Disk(at((2, -2, 2)), (0, 0, 1), 0.7),
        pyclray.Rectangle(at((-2, 2, 2)), (0.5, 0, 0), (0, 0.5, 0)),
        pyclray.Plane((0, 0, 1), float(5.0 - s[2])),
    )
    return pyclray.Scene(camera(shift), pyclray.Image(8, 8), shapes)


def random_rays(seed, count, shift=0.0):
    rng = np.random.default_rng(seed)
    origins = rng.uniform(-5, 5, (count, 3)) + shift
    directions = rng.normal(size=(count, 3)) * rng.uniform(0.01, 100.0, (count, 1))
    return origins, directions


def hit_tolerances(scene, origins, directions, got, ref, precision):
    """The error model's depth tolerance of each hit (cast's, for the hit's ray and shape)."""
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    ray = ref["ray"]
    O, D, t, ids = origins[ray], unit[ray], ref["depth"], ref["id"]
    points = O + t[:, None] * D
    cos = np.ones(len(t))
    for index, shape in enumerate(scene.shapes):
        mine = ids == index
        if mine.any():
            cos[mine] = np.abs(np.einsum("ij,ij->i", shape.oracle_normal(points[mine]), D[mine]))
    depth, _ = error_model.pyclray_tolerances(scene, {"depth": t, "id": ids}, cos, O, precision, directions=D)
    return depth


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("shift", [0.0, 1e6])
def test_agrees_with_oracle_on_every_shape_type(precision, shift):
    need(precision)
    scene = every_shape_scene(shift)
    origins, directions = random_rays(1, 3000, shift)
    got = pyclray.all_hits(scene, origins, directions, precision=precision)
    ref = oracle.all_hits(scene, origins, directions)
    assert got["offsets"].dtype == np.int64 and got["ray"].dtype == np.int64
    assert got["depth"].dtype == (np.float32 if precision == "fp32" else np.float64)
    assert got["id"].dtype == np.int32 and got["primitive"].dtype == np.int32
    assert np.array_equal(got["offsets"], ref["offsets"]), "hit counts differ from the oracle's"
    assert np.array_equal(got["ray"], ref["ray"])
    assert np.array_equal(got["id"], ref["id"]) and np.array_equal(got["primitive"], ref["primitive"])
    # every shape type crossed somewhere, the analytic solids twice on some rays
    assert set(np.unique(got["id"])) == set(range(len(scene.shapes)))
    tolerance = hit_tolerances(scene, origins, directions, got, ref, precision)
    error = np.abs(got["depth"].astype(np.float64) - ref["depth"])
    assert (error <= tolerance).all(), f"depth off by {error.max()} (tolerance {tolerance[np.argmax(error)]})"
    # nearest first; count_hits is the number of rows
    assert np.array_equal(pyclray.count_hits(scene, origins, directions, precision=precision), np.diff(got["offsets"]))


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("shift", [0.0, 1e6])
@pytest.mark.parametrize("name", CLOSED)
def test_parity_on_closed_meshes_through_every_vertex_and_edge_midpoint(name, shift, precision):
    """Rays aimed exactly at each vertex and each edge's midpoint: from outside the count is even
    (two, or none where the ray only touches the mesh there), from inside odd; the full line
    (from outside, through the target and beyond) is even. The oracle's parity is the same."""
    need(precision)
    v, f = CLOSED[name]()
    v = v + shift
    scene = pyclray.Scene(camera(shift), pyclray.Image(8, 8), (pyclray.Mesh(v, f),))
    goal = targets(v, f)
    centre = np.full(3, shift)
    rng = np.random.default_rng(5)
    # outside: from 4 to 6 radii away in random directions (every mesh lies within radius 1.3)
    away = rng.normal(size=goal.shape)
    outside = centre + 4 * away / np.linalg.norm(away, axis=1, keepdims=True) * rng.uniform(1, 1.5, (len(goal), 1))
    count = pyclray.count_hits(scene, outside, goal - outside, precision=precision)
    assert count.dtype == np.int32
    assert (count % 2 == 0).all(), f"{np.sum(count % 2)} rays from outside count odd"
    assert (count > 0).sum() > len(goal) // 2  # most of them cross the mesh
    assert np.array_equal(count % 2, oracle.count_hits(scene, outside, goal - outside) % 2)
    # inside: from points near the centre (every mesh here holds the ball of radius 0.3 around it)
    inside = centre + rng.uniform(-0.1, 0.1, goal.shape)
    count = pyclray.count_hits(scene, inside, goal - inside, precision=precision)
    assert (count % 2 == 1).all(), f"{np.sum(count % 2 == 0)} rays from inside count even"
    assert np.array_equal(count % 2, oracle.count_hits(scene, inside, goal - inside) % 2)
    # from the centre itself, one origin for every ray
    count = pyclray.count_hits(scene, centre, goal - centre, precision=precision)
    assert (count % 2 == 1).all()


@pytest.mark.parametrize("precision", PRECISIONS)
def test_rays_along_a_grid_s_shared_edges_and_through_its_vertices_count_once(precision):
    """A flat grid of triangles seen head on, rays exactly through its vertices (where six
    triangles meet) and along its edges: exactly one hit each (the watertight test alone finds
    two to six at a vertex), also for the instances of a box-shaped closed mesh (two hits)."""
    need(precision)
    from pyclray.model.shapes.mesh_shapes import grid

    v, f = grid(6, 6, size=4.0)
    v = v[:, [0, 2, 1]]  # the xy plane
    scene = pyclray.Scene(camera(), pyclray.Image(8, 8), (pyclray.Mesh(v, f),))
    inner = v[(np.abs(v[:, 0]) < 1.9) & (np.abs(v[:, 1]) < 1.9)]
    edges = targets(v, f)
    edges = edges[(np.abs(edges[:, 0]) < 1.9) & (np.abs(edges[:, 1]) < 1.9)]
    for goal in (inner, edges):
        origins = goal + [0.0, 0.0, 3.0]
        hits = pyclray.all_hits(scene, origins, [0.0, 0.0, -1.0] * np.ones_like(goal), precision=precision)
        assert (np.diff(hits["offsets"]) == 1).all()
        assert np.allclose(hits["depth"], 3.0)
    base = pyclray.Mesh(*cube())
    boxes = pyclray.Scene(camera(), pyclray.Image(8, 8), (base.placed(translate=(0.0, 0.0, 0.0)),
                                                          base.placed(scale=0.5, translate=(3.0, 0.0, 0.0))))
    goal = targets(*cube())
    goal = goal[goal[:, 2] == 1]  # the top face's vertices and edge midpoints
    count = pyclray.count_hits(boxes, goal + [0.0, 0.0, 5.0], [0.0, 0.0, -1.0] * np.ones_like(goal), precision=precision)
    silhouette = (np.abs(goal[:, 0]) == 1) | (np.abs(goal[:, 1]) == 1)
    assert (count[~silhouette] == 2).all() and (count % 2 == 0).all()


@pytest.mark.parametrize("precision", PRECISIONS)
def test_analytic_tangent_rays_count_zero_or_two(precision):
    """A ray touching a sphere, grazing a box's edge or corner, or a capped cylinder's rim or side
    counts 0 or 2 crossings, never 1; crossing through counts 2."""
    need(precision)
    shapes = (pyclray.Sphere((0.0, 0.0, 0.0), 1.0), pyclray.Box((4.0, 0.0, 0.0), (2.0, 2.0, 2.0)),
              pyclray.Cylinder((8.0, -1.0, 0.0), (8.0, 1.0, 0.0), 1.0))
    scene = pyclray.Scene(camera(), pyclray.Image(8, 8), shapes)
    origins = np.array([[0, 1, 5], [1, 0, 5], [0, 0, 5],  # sphere: tangent, tangent, through
                        [5, 0, 5], [5, 1, 5], [4, 0, 5],  # box: edge, corner, through
                        [9, 0, 5], [9, 1, 5], [8, 0, 5], [8, 1.0, 5]], float)  # cylinder: side, rim, through, rim
    count = pyclray.count_hits(scene, origins, np.tile([0.0, 0.0, -1.0], (len(origins), 1)), precision=precision)
    assert (count % 2 == 0).all(), count
    assert count[2] == 2 and count[5] == 2 and count[8] == 2


@pytest.mark.parametrize("precision", PRECISIONS)
def test_tmin_and_tmax_keep_the_hits_between(precision):
    """(tmin, tmax), one number or one per ray: exactly the hits of the whole ray that lie between."""
    need(precision)
    scene = every_shape_scene()
    origins, directions = random_rays(2, 1500)
    whole = pyclray.all_hits(scene, origins, directions, precision=precision)
    rng = np.random.default_rng(2)
    tmin = rng.uniform(0.0, 4.0, len(origins))
    tmax = tmin + rng.uniform(0.5, 6.0, len(origins))
    part = pyclray.all_hits(scene, origins, directions, tmin=tmin, tmax=tmax, precision=precision)
    t = whole["depth"].astype(np.float64)
    # away from the ends (a hit within rounding of tmin is tested from tmin's point: either way)
    margin = 1e-4 * (1 + t)
    keep = (t > tmin[whole["ray"]] + margin) & (t < tmax[whole["ray"]] - margin)
    near_end = (np.abs(t - tmin[whole["ray"]]) <= margin) | (np.abs(t - tmax[whole["ray"]]) <= margin)
    counts = np.diff(part["offsets"])
    expected = np.bincount(whole["ray"][keep], minlength=len(origins))
    unsure = np.bincount(whole["ray"][near_end], minlength=len(origins)) > 0
    assert np.array_equal(counts[~unsure], expected[~unsure])
    assert (part["depth"] > tmin[part["ray"]]).all() and (part["depth"] < tmax[part["ray"]]).all()
    assert 0 < counts.sum() < len(whole["ray"])
    # one number for every ray
    counts = pyclray.count_hits(scene, origins, directions, tmin=2.0, tmax=7.0, precision=precision)
    t_ok = (t > 2.0 + margin) & (t < 7.0 - margin)
    unsure = np.bincount(whole["ray"][(np.abs(t - 2.0) <= margin) | (np.abs(t - 7.0) <= margin)], minlength=len(origins)) > 0
    assert np.array_equal(counts[~unsure], np.bincount(whole["ray"][t_ok], minlength=len(origins))[~unsure])


def test_any_leading_shape_float32_input_and_the_handle():
    """(2, 3, 4, 3) rays give (2, 3, 4) counts and offsets over the rays in C order; float32 arrays
    give what their float64 values give; Tracer.all_hits and count_hits are the functions."""
    scene = every_shape_scene()
    origins, directions = random_rays(3, 24)
    origins = origins.reshape(2, 3, 4, 3).astype(np.float32)
    directions = directions.reshape(2, 3, 4, 3).astype(np.float32)
    count = pyclray.count_hits(scene, origins, directions)
    assert count.shape == (2, 3, 4) and count.dtype == np.int32
    flat = pyclray.count_hits(scene, origins.reshape(-1, 3).astype(np.float64), directions.reshape(-1, 3).astype(np.float64))
    assert np.array_equal(count.ravel(), flat)
    hits = pyclray.all_hits(scene, origins, directions, aovs=("depth", "id", "primitive", "label", "position"))
    assert len(hits["offsets"]) == 25 and np.array_equal(np.diff(hits["offsets"]), count.ravel())
    assert hits["position"].shape == (len(hits["ray"]), 3) and hits["label"].dtype == np.int32
    unit = directions.reshape(-1, 3).astype(np.float64)
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    expected = origins.reshape(-1, 3)[hits["ray"]] + hits["depth"][:, None].astype(np.float64) * unit[hits["ray"]]
    assert np.allclose(hits["position"], expected, atol=1e-5)
    with pyclray.prepare(scene) as tracer:
        assert np.array_equal(tracer.count_hits(origins, directions), count)
        again = tracer.all_hits(origins, directions)
        assert all(np.array_equal(again[k], hits[k]) for k in ("offsets", "ray", "depth", "id", "primitive"))
    empty = pyclray.all_hits(scene, np.zeros((0, 3)), np.zeros((0, 3)))
    assert np.array_equal(empty["offsets"], [0]) and empty["depth"].shape == (0,)
    assert pyclray.count_hits(scene, np.zeros((0, 3)), np.zeros((0, 3))).shape == (0,)


@pytest.mark.parametrize("precision", PRECISIONS)
def test_normals_and_barycentrics_of_every_hit(precision):
    """all_hits' normal and barycentric: the first hit's are cast's (a mesh's triangle normal the same
    bits, an analytic shape's within the error model's angle, barycentrics within rounding); every
    hit's normal is unit and, for a solid, points out (against the ray where it enters, along it
    where it leaves); barycentrics give the hit point on the triangle."""
    need(precision)
    scene = every_shape_scene()
    origins, directions = random_rays(6, 2000)
    aovs = ("depth", "normal", "id", "primitive", "barycentric", "position")
    hits = pyclray.all_hits(scene, origins, directions, aovs=aovs, precision=precision)
    real = np.float32 if precision == "fp32" else np.float64
    assert hits["normal"].dtype == real and hits["normal"].shape == (len(hits["ray"]), 3)
    assert hits["barycentric"].dtype == real and hits["barycentric"].shape == (len(hits["ray"]), 2)
    cast = pyclray.cast(scene, origins, directions, aovs=("id", "normal", "primitive", "barycentric"), precision=precision)
    has = np.diff(hits["offsets"]) > 0
    first = hits["offsets"][:-1][has]
    assert np.array_equal(cast["id"][has], hits["id"][first])
    angle = error_model.angle_between(cast["normal"][has].astype(np.float64), hits["normal"][first].astype(np.float64))
    assert np.median(angle) < 1e-5 and np.mean(angle < 1e-3) > 0.999
    mesh = hits["id"][first] == 0  # the torus: the same float64 normal; its instances' differ in rounding
    assert np.array_equal(cast["normal"][has][mesh], hits["normal"][first][mesh])
    placed = np.isin(hits["id"][first], [1, 2])
    assert np.allclose(cast["normal"][has][placed], hits["normal"][first][placed], rtol=0, atol=1e-6)
    assert np.abs(cast["barycentric"][has].astype(np.float64) - hits["barycentric"][first]).max() < 1e-3
    assert np.allclose(np.linalg.norm(hits["normal"].astype(np.float64), axis=1), 1.0, atol=1e-6)
    # a sphere's (id 3) normals point against the ray where it enters, along it where it leaves
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    sphere = hits["id"] == 3
    facing = np.einsum("ij,ij->i", hits["normal"][sphere].astype(np.float64), unit[hits["ray"][sphere]])
    inside = np.linalg.norm(origins[hits["ray"][sphere]] - [3.0, 0.0, 0.0], axis=1) < 1.0
    second = np.zeros(len(hits["ray"]), bool)
    second[1:] = (hits["ray"][1:] == hits["ray"][:-1]) & (hits["id"][1:] == hits["id"][:-1])
    leaving = second[sphere] | inside
    assert (facing[leaving] > 0).all() and (facing[~leaving] < 0).all()
    triangles = np.isin(hits["id"], [0, 1, 2])
    for index in (0, 1, 2):
        rows = hits["id"] == index
        a, b, c = (x[hits["primitive"][rows]] for x in scene.shapes[index].corners())
        u, v = (hits["barycentric"][rows, k, None].astype(np.float64) for k in (0, 1))
        assert np.abs((1 - u - v) * a + u * b + v * c - hits["position"][rows]).max() < 1e-4
    assert (hits["barycentric"][~triangles] == 0).all()


def test_labels_of_hits():
    shapes = (pyclray.Sphere((0.0, 0.0, 0.0), 1.0, label=3), pyclray.Sphere((0.0, 0.0, -3.0), 1.0))
    scene = pyclray.Scene(camera(), pyclray.Image(8, 8), shapes)
    hits = pyclray.all_hits(scene, (0.0, 0.0, 5.0), [[0.0, 0.0, -1.0]], aovs=("label", "id"))
    assert list(hits["id"]) == [0, 0, 1, 1] and list(hits["label"]) == [3, 3, -1, -1]


def test_the_lane_width_changes_nothing(monkeypatch):
    """PYCLRAY_LANES=1 (and any width): the same hits, bit for bit."""
    scene = every_shape_scene()
    origins, directions = random_rays(4, 500)
    default = pyclray.all_hits(scene, origins, directions)
    monkeypatch.setenv("PYCLRAY_LANES", "1")
    pyclray.clear_cache()
    one = pyclray.all_hits(scene, origins, directions)
    assert all(np.array_equal(default[k], one[k]) for k in default)


BAD = [
    # (origins, directions, keywords, words the message must hold)
    ((0, 1, 5), [[0.0, -1.0]], {}, ["directions", "(..., 3)"]),
    ((0, 1, 5), [[0, 0, -1], [0, 0, 0]], {}, ["directions", "row 1", "zero length"]),
    ((0, 1, 5), [[0, 0, -1], [0, np.nan, -1]], {}, ["directions", "row 1", "not finite"]),
    ([[0, 1, 5], [0, 1, np.inf]], np.ones((2, 3)), {}, ["origins", "row 1", "not finite"]),
    (np.zeros((2, 3)), np.ones((3, 3)), {}, ["origins", "(3, 3)", "(2, 3)"]),
    ((0, 1, 5), np.ones((3, 3)), {"tmin": [0.0, -1.0, 0.0]}, ["tmin", ">= 0", "row 1"]),
    ((0, 1, 5), np.ones((3, 3)), {"tmin": np.inf}, ["tmin", ">= 0"]),
    ((0, 1, 5), np.ones((3, 3)), {"tmax": [1.0, 1.0, np.nan]}, ["tmax", "> 0", "row 2"]),
    ((0, 1, 5), np.ones((3, 3)), {"tmax": np.ones(2)}, ["tmax", "shape"]),
]


@pytest.mark.parametrize("origins, directions, keywords, words", BAD)
@pytest.mark.parametrize("query", ["count_hits", "all_hits"])
def test_bad_arrays_are_clear_errors(query, origins, directions, keywords, words):
    scene = every_shape_scene()
    with pytest.raises(pyclray.RequestError) as error:
        getattr(pyclray, query)(scene, origins, directions, **keywords)
    assert isinstance(error.value, ValueError)
    message = str(error.value)
    assert "\n" not in message
    for word in words:
        assert word in message, f"{word!r} not in {message!r}"


def test_bad_aovs_are_clear_errors():
    scene = every_shape_scene()
    for aovs in (("depth", "colour"), ("depth", "depth"), "shaded", 5):
        with pytest.raises(pyclray.RequestError, match="aovs"):
            pyclray.all_hits(scene, (0, 1, 5), [[0.0, 0.0, -1.0]], aovs=aovs)


def test_check_compares_all_hits_with_the_oracle_and_mitsuba(monkeypatch):
    """pyclray check's all-hits comparison (reference/validation/hits.py): passes on a scene of a
    closed mesh and solids, and fails where pyclray's hits are not the oracle's (one dropped)."""
    from pyclray.reference.validation import hits as hits_check

    from conftest import SCENES

    scene = pyclray.load_scene(SCENES / "shapes.toml")
    scene = pyclray.Scene(scene.camera, pyclray.Image(48, 36), scene.shapes + (pyclray.Mesh(*icosphere(1), translate=(0.0, 1.0, -2.0)),))
    result = hits_check.all_hits_check(scene, n_rays=200)
    assert not result.failures, result.failures
    assert result.counts["  pyclray's count is the oracle's"] == result.counts["judged rays (away from edges and tangents)"] > 150
    assert result.counts["hits (float64 oracle)"] > result.rays  # rays cross solids twice
    real = pyclray.all_hits

    def dropping(*args, **kwargs):  # every ray with two hits or more loses its last one
        out = dict(real(*args, **kwargs))
        counts = np.diff(out["offsets"])
        rows = out["offsets"][1:][counts >= 2] - 1
        counts = np.where(counts >= 2, counts - 1, counts)
        out = {name: np.delete(value, rows, axis=0) for name, value in out.items() if name != "offsets"}
        return {**out, "offsets": np.concatenate([[0], np.cumsum(counts)])}

    import pyclray.engine.api as api

    monkeypatch.setattr(api, "all_hits", dropping)
    assert hits_check.all_hits_check(scene, n_rays=200).failures


def test_hits_at_the_same_distance_come_by_id_then_primitive():
    """Two copies of a sphere and of a mesh (its arrays copied: two meshes) at the same place: each
    distance twice, the lower id first, as the oracle orders them."""
    v, f = icosphere(1)
    shapes = (pyclray.Mesh(v + [0.0, 0.0, -4.0], f), pyclray.Sphere((0.0, 0.0, 0.0), 1.0), pyclray.Sphere((0.0, 0.0, 0.0), 1.0),
              pyclray.Mesh(np.array(v) + [0.0, 0.0, -4.0], np.array(f)))
    scene = pyclray.Scene(camera(), pyclray.Image(8, 8), shapes)
    origins, directions = np.array([[0.1, 0.05, 5.0], [0.0, 0.0, 0.5]]), np.array([[0.0, 0.0, -1.0], [0.01, 0.0, -1.0]])
    got = pyclray.all_hits(scene, origins, directions)
    ref = oracle.all_hits(scene, origins, directions)
    assert list(got["id"][:8]) == [1, 2, 1, 2, 0, 3, 0, 3]
    assert all(np.array_equal(got[k], ref[k]) for k in ("offsets", "ray", "id", "primitive"))


# -- Open3D's cases for these queries (its python/test/t/geometry/test_raycasting_scene.py), ported --------
def unit_box_scene():
    """The unit box [0, 1]^3 as 12 triangles: a ray along z through (0.5, 0.5) crosses each z face
    exactly on the diagonal its two triangles share."""
    v, f = cube()
    return pyclray.Scene(camera(), pyclray.Image(8, 8), (pyclray.Mesh((v + 1.0) / 2.0, f),))


@pytest.mark.parametrize("precision", PRECISIONS)
def test_open3d_box_counts_and_lists(precision):
    """From below the box: two crossings (t = 1, 2); from its centre: one (t = 0.5); far off: none.
    Both z faces are crossed on a shared diagonal, where the tie rule must count one triangle."""
    need(precision)
    scene = unit_box_scene()
    origins = np.array([[0.5, 0.5, -1.0], [0.5, 0.5, 0.5], [10.0, 10.0, 10.0]])
    directions = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    assert list(pyclray.count_hits(scene, origins, directions, precision=precision)) == [2, 1, 0]
    hits = pyclray.all_hits(scene, origins, directions, precision=precision)
    assert list(hits["offsets"]) == [0, 2, 3, 3] and list(hits["ray"]) == [0, 0, 1]
    assert np.allclose(hits["depth"], [1.0, 2.0, 0.5], rtol=1e-6, atol=1e-6)


def test_open3d_single_triangle_occlusion_with_tmin_and_tmax():
    """One triangle (0, 0, 0), (1, 0, 0), (1, 1, 0): the ray from (0.2, 0.1, 1) down hits it at t = 1,
    the other ray misses; with tmax = 0.5 or tmin = 1.5 neither is occluded nor hits."""
    scene = pyclray.Scene(camera(), pyclray.Image(8, 8),
                          (pyclray.Mesh(np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]]), np.array([[0, 1, 2]])),))
    origins = np.array([[0.2, 0.1, 1.0], [10.0, 10.0, 10.0]])
    directions = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    assert list(pyclray.occluded(scene, origins, directions)) == [True, False]
    assert not pyclray.occluded(scene, origins, directions, tmax=0.5).any()
    assert not pyclray.occluded(scene, origins, directions, tmin=1.5).any()
    assert list(pyclray.count_hits(scene, origins, directions)) == [1, 0]
    assert list(pyclray.count_hits(scene, origins, directions, tmin=1.5)) == [0, 0]
    cast = pyclray.cast(scene, origins, directions, tmin=0.5, tmax=2.0, aovs=("depth", "primitive", "barycentric"))
    assert cast["depth"][0] == 1.0 and np.isinf(cast["depth"][1]) and list(cast["primitive"]) == [0, -1]
    assert np.allclose(cast["barycentric"][0], [0.1, 0.1])  # (0.2, 0.1, 0) = 0.8 a + 0.1 b + 0.1 c


@pytest.mark.parametrize("shape", [[11], [1, 2, 3], [32, 14]])
def test_open3d_output_shapes(shape):
    """Rays of any leading shape: count_hits has that shape, all_hits' offsets one more than the rays
    and one row per hit in every other array."""
    scene = unit_box_scene()
    rng = np.random.default_rng(123)
    rays = rng.uniform(size=shape + [6])
    count = pyclray.count_hits(scene, rays[..., :3], rays[..., 3:] + 1e-3)
    assert list(count.shape) == shape
    hits = pyclray.all_hits(scene, rays[..., :3], rays[..., 3:] + 1e-3, aovs=("depth", "normal", "id", "primitive",
                                                                               "barycentric", "label", "position"))
    total = int(count.sum())
    assert hits["offsets"].shape == (int(np.prod(shape)) + 1,)
    for name, tail in (("ray", ()), ("depth", ()), ("normal", (3,)), ("id", ()), ("primitive", ()),
                       ("barycentric", (2,)), ("label", ()), ("position", (3,))):
        assert hits[name].shape == (total,) + tail, name
