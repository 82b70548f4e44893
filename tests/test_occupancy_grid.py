"""Occupancy of a scene of closed meshes (engine/queries/closest.py: occupancy, _one_closed_mesh): a
large batch's points are looked up in the meshes' parity grid (engine/queries/parity_grid.py: its empty
cells' regions, coarse and fine, decided by one exact ray each), the others counted by their parity rays, whose
kernel also tests a point with an even count for lying on the surface, over the leaves whose boxes
hold it (kernels/allhits.cl: PYCLRAY_AOV_SURFACE; the closest-point query where more than
SURFACE_LEAVES do). Held to truths known by construction (points exactly on the triangles, written
in float64; points just off a convex mesh's faces), to the float64 oracle, and to the general path
(the parity count of every point, then the closest-point query's surface search) bit for bit."""
from pathlib import Path

import numpy as np
import pytest

import pyclray
from pyclray.engine.queries import closest, parity_grid
from pyclray.engine.queries.closest import COHERENT_FROM
from pyclray.engine.queries.parity_grid import INSIDE, OUTSIDE, SURFACE
from pyclray.model.shapes.mesh_shapes import perturbed_sphere, torus
from pyclray.reference import oracle

CAMERA = pyclray.Camera((0, 0, 10), (0, 0, 0))


def scene_of(*shapes) -> pyclray.Scene:
    return pyclray.Scene(CAMERA, pyclray.Image(8, 8), tuple(shapes))


def welded(triangles, n: int, shift: float) -> pyclray.Mesh:
    """The closed mesh of triangles given by their corners' integer keys (each key a vertex, its
    coordinates key / n + shift)."""
    index = {}
    faces = [[index.setdefault(key, len(index)) for key in triangle] for triangle in triangles]
    mesh = pyclray.Mesh(np.array(list(index), np.float64) / n + shift, np.array(faces))
    assert mesh.closed
    return mesh


def octahedron(n: int, shift: float = 0.0) -> pyclray.Mesh:
    """|x| + |y| + |z| = 1 (+ shift), each face cut into n^2 triangles: every vertex's coordinates
    are multiples of 1/n, exact in float64 (n a power of two), the faces tilted to every axis."""
    triangles = []
    for sx in (1, -1):
        for sy in (1, -1):
            for sz in (1, -1):
                def at(i, j):  # the face's point (i, j, n - i - j) / n, signed
                    return (sx * i, sy * j, sz * (n - i - j))
                for i in range(n):
                    for j in range(n - i):
                        tri = [(at(i, j), at(i + 1, j), at(i, j + 1))]
                        if i + j < n - 1:
                            tri.append((at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)))
                        for a, b, c in tri:  # outward: the face's normal (sx, sy, sz)
                            triangles.append((a, b, c) if sx * sy * sz > 0 else (a, c, b))
    return welded(triangles, n, shift)


def cube(n: int, shift: float = 0.0) -> pyclray.Mesh:
    """The cube [0, 1]^3 (+ shift), each face cut into n x n squares of two triangles each (the
    vertices' coordinates multiples of 1/n, exact in float64 for n a power of two), outward."""
    triangles = []
    for axis in range(3):
        u, w = (axis + 1) % 3, (axis + 2) % 3
        for side in (0, n):
            def at(i, j):
                key = [0, 0, 0]
                key[axis], key[u], key[w] = side, i, j
                return tuple(key)
            for i in range(n):
                for j in range(n):
                    quad = [(at(i, j), at(i + 1, j), at(i + 1, j + 1)), (at(i, j), at(i + 1, j + 1), at(i, j + 1))]
                    for a, b, c in quad:  # (u, w, axis) is right-handed: outward on the far side
                        triangles.append((a, b, c) if side else (a, c, b))
    return welded(triangles, n, shift)


def on_surface_points(mesh: pyclray.Mesh, interior: bool) -> np.ndarray:
    """Every triangle's vertices and edge midpoints, and with interior its points a/4 + b/4 + c/2:
    exact in float64 for a mesh of coordinates that are multiples of 1/8 near 0 or 1e6; repeated up
    to a large batch."""
    a, b, c = mesh.corners()
    points = [a, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)] + ([0.25 * a + 0.25 * b + 0.5 * c] if interior else [])
    points = np.vstack(points)
    return np.vstack([points] * (COHERENT_FROM // len(points) + 1))


def general_path(tracer, points, sign="parity") -> np.ndarray:
    """The answers without the shortcuts: each point's ray (the closed meshes' count, or signed
    count, exact: its undecided points decided exactly), then the closest-point query's search for
    a surface point at distance 0 of every point not inside, each found confirmed on its nearest
    triangle (or any) in rational arithmetic (a float64 distance 0 may be a rounding off the
    surface: engine/queries/parity_exact.py)."""
    from pyclray.engine.queries.parity_exact import exact_on_surface

    flat, _ = closest.check_points(points)
    inside = closest._mesh_inside(tracer, flat, sign)
    rest = np.flatnonzero(~inside)
    claimed = rest[closest.run_closest(tracer, flat[rest], ("inside",), within=0.0)["inside"].astype(bool)]
    nearest = closest.run_closest(tracer, flat[claimed], ("distance",) + closest.CLOSEST_OUTPUTS)
    inside[claimed] = exact_on_surface(tracer.shapes, flat[claimed], nearest["id"], nearest["primitive"])
    return inside.astype(np.uint8)


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("shift", [0.0, 1e6])
@pytest.mark.parametrize("make, interior", [(octahedron, False), (cube, True)])
def test_points_on_the_triangles_are_inside(make, interior, precision, shift):
    """Points exactly on the triangles (the grid's surface cells, the count kernel's surface test)
    are inside, near the origin and 1e6 from it: the vertices and edge midpoints of the tilted
    octahedron's triangles, and on the cube's faces their interior points too. (The closest-point
    query finds a point inside a tilted face at the distance its rounded unit normal gives, a
    float64 rounding above 0: its inside is then its ray's, as before this grid.)"""
    mesh = make(8, shift)
    points = on_surface_points(mesh, interior)
    assert np.array_equal(points - shift, on_surface_points(make(8), interior))  # exact: no rounding
    assert len(points) >= COHERENT_FROM
    got = pyclray.occupancy(scene_of(mesh), points, precision=precision)
    assert got.all()
    assert pyclray.occupancy(scene_of(mesh), points[:200], precision=precision).all()  # a small batch


@pytest.mark.parametrize("precision, offset", [("fp64", 1e-9), ("fp32", 1e-6)])
@pytest.mark.parametrize("shift", [0.0, 1e6])
def test_points_just_off_the_faces(precision, offset, shift):
    """Points off a face of the (convex) octahedron by offset of its size along its normal: 0
    outside, 1 inside (float32 rounds a triangle tested from a point by about 6e-8 of their
    distance: 1e-6 there, 1e-9 in float64)."""
    mesh = octahedron(8, shift)
    rng = np.random.default_rng(9)
    a, b, c = mesh.corners()
    tri = rng.integers(0, len(a), COHERENT_FROM + 300)
    u = rng.uniform(0.1, 0.8, len(tri))
    v = rng.uniform(0.05, 0.9 - u)
    on = a[tri] + u[:, None] * (b[tri] - a[tri]) + v[:, None] * (c[tri] - a[tri])
    normal = mesh.face_normals()[tri]
    scene = scene_of(mesh)
    assert not pyclray.occupancy(scene, on + 2 * offset * normal, precision=precision).any()
    assert pyclray.occupancy(scene, on - 2 * offset * normal, precision=precision).all()


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_same_bits_as_the_general_path(precision):
    """A perturbed sphere and a torus: uniform points in and around the box, points near the
    surface, the vertices: the grid's and the count kernel's answers are the general path's."""
    rng = np.random.default_rng(12)
    v, f = perturbed_sphere(24, 36, 1.0, 0.1, rng)
    for mesh in (pyclray.Mesh(v + 3.0, f), pyclray.Mesh(*torus(16, 24, 1.0, 0.3))):
        lo, hi = (np.asarray(x) for x in mesh.box())
        uniform = rng.uniform(lo - 0.2, hi + 0.2, (COHERENT_FROM + 1000, 3))
        with pyclray.prepare(scene_of(mesh), precision=precision) as tracer:
            seeds = rng.uniform(lo, hi, (COHERENT_FROM, 3))
            near = tracer.closest_points(seeds)["position"].astype(np.float64)
            near = near + rng.normal(size=near.shape) * 10.0 ** rng.uniform(-9, -2, (len(near), 1))
            vertices = np.vstack([mesh.world_vertices()] * (COHERENT_FROM // len(mesh.world_vertices()) + 1))
            for points in (uniform, near, vertices):
                for sign in ("parity", "winding"):
                    assert np.array_equal(tracer.occupancy(points, sign), general_path(tracer, points, sign))


@pytest.mark.parametrize("sign", ["parity", "winding"])
def test_several_closed_meshes(sign):
    """Two overlapping closed meshes (a torus through a perturbed sphere: winding 2 where both
    hold a point) and a third apart: the grid of all their triangles decides the points of its
    empty cells by the rule's own test of one point per region; the same answers as the general
    path on uniform points and on points near the surfaces (the fine level), and the oracle's off
    the surfaces."""
    rng = np.random.default_rng(16)
    v, f = perturbed_sphere(16, 24, 0.8, 0.1, rng)
    shapes = (pyclray.Mesh(*torus(16, 24, 1.0, 0.3)), pyclray.Mesh(v + [1.0, 0.0, 0.0], f),
              pyclray.Mesh(v * 0.5 + [0.0, 0.0, 3.0], f))
    scene = scene_of(*shapes)
    points = rng.uniform([-1.5, -1.5, -1.0], [2.0, 1.5, 3.6], (COHERENT_FROM + 500, 3))
    with pyclray.prepare(scene) as tracer:
        got = tracer.occupancy(points, sign)
        assert np.array_equal(got, general_path(tracer, points, sign))
        grid = closest._parity_grid(tracer, tracer.mesh_handle(closed=True), sign)
        decided, _ = grid.lookup(points, sign)
        assert decided.mean() > 0.5  # most points decided by the grid
        # points within 1% of the size from the surfaces: the fine level made and used
        on = tracer.closest_points(points)["position"].astype(np.float64)
        near = on + rng.normal(size=on.shape) * rng.uniform(0, 0.03, (len(on), 1))
        assert np.array_equal(tracer.occupancy(near, sign), general_path(tracer, near, sign))
        grid = closest._parity_grid(tracer, tracer.mesh_handle(closed=True), sign)
        assert grid.refined and fine_decided(grid, near, sign).mean() > 0.1
    clear = oracle.closest_points(scene, points)["distance"] > 0
    assert np.array_equal(got.astype(bool)[clear], oracle.inside(scene, points, sign)[clear])


@pytest.mark.parametrize("turned", [True, False])
def test_nested_shells_regions_against_the_oracle(turned):
    """One closed mesh of two spheres, the inner one turned inward (a hollow ball) or not (winding
    number 2 within it: inside by winding, outside by parity): three regions of empty cells (beyond,
    within the shell, the cavity), each decided by its own ray; uniform points and points beyond
    the grid against the oracle's exact inside, by both rules."""
    rng = np.random.default_rng(14)
    v, f = perturbed_sphere(20, 30, 1.0, 0.05, rng)
    inner = f[:, ::-1] if turned else f
    mesh = pyclray.Mesh(np.vstack([v, 0.5 * v]), np.vstack([f, inner + len(v)]))
    assert mesh.closed
    scene = scene_of(mesh)
    points = np.vstack([rng.uniform(-1.3, 1.3, (COHERENT_FROM + 500, 3)), rng.uniform(5, 9, (50, 3))])
    cavity = np.linalg.norm(points, axis=1) < 0.4
    assert cavity.any()
    for sign in ("parity", "winding"):
        got = pyclray.occupancy(scene, points, sign=sign)
        assert np.array_equal(got.astype(bool), oracle.inside(scene, points, sign))
        assert got[cavity].all() == (sign == "winding" and not turned) and got[cavity].any() == got[cavity].all()
        with pyclray.prepare(scene) as tracer:
            grid = closest._parity_grid(tracer, tracer.mesh_handle(closed=True), sign)
            assert {SURFACE, OUTSIDE, INSIDE} <= set(np.unique(grid.states[sign][0]).tolist())


def test_points_in_many_leaves_boxes(monkeypatch):
    """A cone whose apex and base centre are each a corner of 64 triangles (more leaves than the
    count kernel notes: those points go to the closest-point query): the apex, the base centre and
    points around them, against the oracle (on the surface: inside)."""
    count = 64
    angle = 2 * np.pi * np.arange(count) / count
    rim = np.stack([np.cos(angle), np.sin(angle), np.zeros(count)], axis=1)
    vertices = np.vstack([rim, [[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]])
    i = np.arange(count)
    faces = np.vstack([np.stack([i, (i + 1) % count, np.full(count, count)], axis=1),
                       np.stack([(i + 1) % count, i, np.full(count, count + 1)], axis=1)])
    mesh = pyclray.Mesh(vertices, faces)
    assert mesh.closed
    scene = scene_of(mesh)
    rng = np.random.default_rng(15)
    corners = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    points = np.vstack([np.repeat(corners, 100, axis=0),
                        np.repeat(corners, COHERENT_FROM // 2, axis=0) + rng.normal(size=(COHERENT_FROM, 3)) * 1e-3])
    asked = []
    original = closest.run_closest

    def recording(tracer, points, outputs, within=np.inf):
        asked.append(len(points))
        return original(tracer, points, outputs, within)

    monkeypatch.setattr(closest, "run_closest", recording)
    got = pyclray.occupancy(scene, points)
    assert asked and max(asked) >= 200  # the corners at least: more than SURFACE_LEAVES leaves (the grid's regions' points first)
    assert got[:200].all()
    assert np.array_equal(got.astype(bool), oracle.inside(scene, points))


def _slabs_of(tracer):
    """(slabs, codes, inputs): the closest-point tree's leaves' slabs (closest.leaf_slabs), their codes."""
    closed = tracer.mesh_handle(closed=True)
    inputs = closed.closest_inputs()
    nodes = inputs.bvh.nodes(inputs.anchor)
    codes = nodes["child"][nodes["child"] < 0]
    return closest.leaf_slabs(inputs, codes), codes, inputs


@pytest.mark.parametrize("shift", [0.0, 1e6])
def test_leaf_slabs_hold_their_triangles(shift):
    """Each leaf's slab (the count kernel's surface pre-test: a point beyond it lies on none of
    the leaf's triangles) holds every point of its triangles: their corners and random points in
    them (convex combinations, in exact rational arithmetic for a sample), near the origin and 1e6
    from it; and it is thin (a fraction of the leaf's size), or the pre-test would decide nothing."""
    from fractions import Fraction

    rng = np.random.default_rng(21)
    v, f = perturbed_sphere(40, 60, 1.0, 0.05, rng)
    mesh = pyclray.Mesh(v + shift, f)
    with pyclray.prepare(scene_of(mesh)) as tracer:
        slabs, codes, inputs = _slabs_of(tracer)
    first, count = (~codes.astype(np.int64)) >> 3, (~codes.astype(np.int64)) & 7
    world = inputs.worlds["mesh"]
    assert np.isfinite(slabs[:, 3:]).all()  # no sliver here: every leaf has its slab
    thickness = slabs[:, 4] - slabs[:, 3]
    extents = np.zeros(len(codes))
    for leaf in range(len(codes)):
        entries = world[first[leaf]:first[leaf] + count[leaf]]
        corners = np.stack([entries[k][:, :3] for k in ("a", "b", "c")], axis=1)  # (count, 3, 3)
        weights = rng.dirichlet(np.ones(3), (len(corners), 4))
        points = np.concatenate([corners, np.einsum("tsk,tkd->tsd", weights, corners)], axis=1).reshape(-1, 3)
        along = points @ slabs[leaf, :3]
        assert (along >= slabs[leaf, 3]).all() and (along <= slabs[leaf, 4]).all()
        extents[leaf] = float((corners.max(axis=(0, 1)) - corners.min(axis=(0, 1))).max())
        if leaf % 50 == 0:  # exactly: every corner's dot product within the slab, in rationals
            n = [Fraction(float(x)) for x in slabs[leaf, :3]]
            for p in corners.reshape(-1, 3):
                exact = sum(Fraction(float(x)) * y for x, y in zip(p, n))
                assert Fraction(float(slabs[leaf, 3])) <= exact <= Fraction(float(slabs[leaf, 4]))
    assert np.median(thickness / extents) < 0.5


def test_leaf_slabs_leave_slivers_and_other_shapes_tested():
    """A leaf with a sliver (a triangle whose corners are nearly on a line: its nearest points are
    not within rounding of it) gets no slab (-inf, inf: always tested)."""
    # a closed tetrahedron-like mesh with one face cut by a sliver: an almost straight fan
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0],
                         [0.5, 0.5 + 1e-12, 0.0]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 4, 3], [4, 2, 3], [1, 2, 4]])
    mesh = pyclray.Mesh(vertices, faces)
    with pyclray.prepare(scene_of(mesh)) as tracer:
        slabs, codes, _ = _slabs_of(tracer)
    assert len(codes) == 1 and slabs[0, 3] == -np.inf and slabs[0, 4] == np.inf


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("shift", [0.0, 1e6])
def test_slab_pre_test_same_bits(monkeypatch, precision, shift):
    """The count kernel's surface test with the slabs and without them (every leaf tested, as
    before the pre-test): the same answers bit for bit, on points on the triangles (corners, edge
    midpoints, points inside them), points 1e-12 to 1e-2 of the size off them, and uniform points."""
    rng = np.random.default_rng(22)
    v, f = perturbed_sphere(30, 45, 1.0, 0.08, rng)
    mesh = pyclray.Mesh(v + shift, f)
    a, b, c = mesh.corners()
    tri = rng.integers(0, len(a), COHERENT_FROM)
    u = rng.uniform(0, 1, len(tri))
    w = rng.uniform(0, 1 - u)
    on = a[tri] + u[:, None] * (b[tri] - a[tri]) + w[:, None] * (c[tri] - a[tri])
    off = on + rng.normal(size=on.shape) * 10.0 ** rng.uniform(-12, -2, (len(on), 1))
    lo, hi = (np.asarray(x) for x in mesh.box())
    sets = (np.vstack([a, 0.5 * (a + b), (a + b + c) / 3]), on, off, rng.uniform(lo, hi, (COHERENT_FROM, 3)))
    with pyclray.prepare(scene_of(mesh), precision=precision) as tracer:
        with_slabs = [tracer.occupancy(p) for p in sets]
        slabs, _, _ = _slabs_of(tracer)
        assert np.isfinite(slabs[:, 3:]).mean() > 0.9
    everywhere = lambda inputs, codes: np.tile([0.0, 0.0, 0.0, -np.inf, np.inf], (len(codes), 1))
    monkeypatch.setattr(closest, "leaf_slabs", everywhere)
    with pyclray.prepare(scene_of(mesh), precision=precision) as tracer:
        for points, got in zip(sets, with_slabs):
            assert np.array_equal(tracer.occupancy(points), got)
    assert with_slabs[0][:len(a)].all()  # the corners: on the surface


# the parity grid's fine level (engine/queries/parity_grid.py: each coarse surface cell refined into
# BLOCK^3 fine cells, their empty ones joined to the regions): its answers are the rays' too

BUNNY = pyclray.Mesh.load(Path(__file__).resolve().parent.parent / "scenes" / "meshes" / "bunny.ply")


def near_surface(tracer, mesh, band: float, count: int, rng) -> np.ndarray:
    """count points within band of the mesh's size from its surface: the nearest surface points of
    uniform points in the box, moved by up to band along random directions."""
    lo, hi = (np.asarray(x) for x in mesh.box())
    on = tracer.closest_points(rng.uniform(lo, hi, (count, 3)))["position"].astype(np.float64)
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return on + direction * rng.uniform(-band, band, (count, 1)) * float(np.max(hi - lo))


def fine_decided(grid, points, sign="parity") -> np.ndarray:
    """Per point: whether the grid decides it in a fine cell (a coarse surface cell's block)."""
    decided, _ = grid.lookup(points, sign)
    cells = np.floor((points - grid.lo) / grid.size).astype(np.int64)
    inner = np.all((cells >= 0) & (cells < grid.dims), axis=1)
    index = np.zeros(len(points), np.int64)
    index[inner] = (cells[inner, 2] * grid.dims[1] + cells[inner, 1]) * grid.dims[0] + cells[inner, 0]
    return decided & inner & (grid.region[index] < 0)


def test_the_fine_coordinate_is_block_times_the_coarse():
    """The module's claim: fl((x - lo) / (size / BLOCK)) == BLOCK * fl((x - lo) / size) exactly
    (BLOCK a power of two: scaling by it commutes with rounding), so a point's coarse cell (its fine
    cell's index divided by BLOCK) is the one-level grid's floor((x - lo) / size); on random
    coordinates and sizes near 0 and near 1e6, and on the grid's own cell sides."""
    rng = np.random.default_rng(31)
    for shift in (0.0, 1e6):
        lo = shift + rng.normal(size=200_000)
        size = rng.uniform(1e-3, 1.0, 200_000) * 10.0 ** rng.integers(-3, 3, 200_000)
        x = lo + rng.uniform(0, 300, 200_000) * size
        sides = lo[:1000] + np.arange(1000) * size[:1000]  # points on cells' sides (as rounded)
        for xs, los, sizes in ((x, lo, size), (sides, lo[:1000], size[:1000])):
            coarse = (xs - los) / sizes
            fine = (xs - los) / (sizes / parity_grid.BLOCK)
            assert np.array_equal(fine, parity_grid.BLOCK * coarse)
            assert np.array_equal(np.floor(fine) // parity_grid.BLOCK, np.floor(coarse))


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("shift", [0.0, 1e6])
def test_near_points_same_bits_as_the_general_path(precision, shift):
    """The bunny (5,000 triangles) and a perturbed sphere, near the origin and 1e6 from it: points
    within 1%, 0.1% and 1e-6 of the size from the surface, the vertices, edge midpoints and face
    centroids (of every fifth triangle): occupancy (both rules) and signed distance's sign are the
    general path's, bit for bit, and the fine level decides some of the points within 1% (made for
    their batch: enough of them left undecided by the coarse level, closest.FINE_FROM)."""
    rng = np.random.default_rng(32)
    v, f = perturbed_sphere(40, 60, 1.0, 0.08, rng)
    for mesh in (pyclray.Mesh(BUNNY.vertices + shift, BUNNY.faces), pyclray.Mesh(v + shift, f)):
        a, b, c = mesh.corners()
        with pyclray.prepare(scene_of(mesh), precision=precision) as tracer:
            sets = [near_surface(tracer, mesh, band, 3 * COHERENT_FROM, rng) for band in (1e-2, 1e-3, 1e-6)]
            every = slice(None, None, 5)  # a fifth of the triangles (their exact surface checks are the cost)
            sets.append(np.vstack([a[every], 0.5 * (a[every] + b[every]), (a[every] + b[every] + c[every]) / 3]))
            for points in sets:
                for sign in ("parity", "winding"):
                    expected = general_path(tracer, points, sign)
                    assert np.array_equal(tracer.occupancy(points, sign), expected)
                    signed = tracer.signed_distance(points, sign)
                    distance = tracer.distance(points)
                    assert np.array_equal(signed, np.where(expected.astype(bool) & (distance > 0), -distance, distance))
            grid = closest._parity_grid(tracer, tracer.mesh_handle(closed=True), "parity")
            assert fine_decided(grid, sets[0]).mean() > 0.05


def test_the_fine_level_decides_a_large_share_of_near_points():
    """A perturbed sphere of 60,000 triangles (edges about 1.5% of the size; a fine cell is 1/512
    of it, 0.2%): of the points 0.4% to 1% of the size from the surface, most in coarse surface
    cells (1/64 of the size), more than half are decided in empty fine cells (a test that fails if
    the refinement decides nothing: the coarse level alone decides about 10% of them), and of all
    the points within 1% more than 15%; their answers are the general path's."""
    rng = np.random.default_rng(33)
    v, f = perturbed_sphere(150, 200, 1.0, 0.02, rng)
    mesh = pyclray.Mesh(v, f)
    with pyclray.prepare(scene_of(mesh)) as tracer:
        points = near_surface(tracer, mesh, 1e-2, 3 * COHERENT_FROM, rng)
        distance = tracer.distance(points) / 2.0
        band = (distance > 0.004) & (distance < 0.01)
        got = tracer.occupancy(points)
        assert np.array_equal(got, general_path(tracer, points))
        grid = closest._parity_grid(tracer, tracer.mesh_handle(closed=True), "parity")
        fine = fine_decided(grid, points)
    assert band.sum() > 1000
    assert fine[band].mean() > 0.5
    assert fine.mean() > 0.15
    assert 0 < got[fine].mean() < 1  # inside and outside both decided there


def test_the_seeds_lie_in_their_own_empty_cells():
    """Each region's decided point lies in an empty cell of its own region (by the lookup's own
    formula): the grid decides it, as its own ray does; of the nested shells (one region beyond,
    one in the shell, one in the cavity) and the fine pockets."""
    rng = np.random.default_rng(34)
    v, f = perturbed_sphere(20, 30, 1.0, 0.05, rng)
    mesh = pyclray.Mesh(np.vstack([v, 0.5 * v]), np.vstack([f, f[:, ::-1] + len(v)]))
    with pyclray.prepare(scene_of(mesh)) as tracer:
        tracer.occupancy(rng.uniform(-1, 1, (COHERENT_FROM, 3)))
        grid = closest._parity_grid(tracer, tracer.mesh_handle(closed=True), "parity", fine=True)
        decided, inside = grid.lookup(grid.seeds, "parity")
        assert decided.all()
        assert np.array_equal(inside, closest._mesh_inside(tracer, grid.seeds, "parity"))
    assert len(grid.seeds) >= 3 and (grid.blocks >= 0).any()


@pytest.mark.parametrize("cap", ["blocks", "work"])
def test_the_fine_level_falls_back_where_capped(monkeypatch, cap):
    """With room for 20 refined blocks only (MAX_FINE_CELLS; fewer kept where all of a block's fine
    cells are surface cells), the other coarse surface cells stay coarse (their points to their
    rays); with the marking's work over FINE_WORK no block is refined:
    the same answers as the general path, and fewer points decided than with the whole fine level."""
    rng = np.random.default_rng(35)
    v, f = perturbed_sphere(40, 60, 1.0, 0.08, rng)
    mesh = pyclray.Mesh(v, f)
    with pyclray.prepare(scene_of(mesh)) as tracer:
        points = near_surface(tracer, mesh, 1e-2, COHERENT_FROM + 500, rng)
        tracer.occupancy(points)
        whole = fine_decided(closest._parity_grid(tracer, tracer.mesh_handle(closed=True), "parity"), points).sum()
    if cap == "blocks":
        monkeypatch.setattr(parity_grid, "MAX_FINE_CELLS", 20 * parity_grid.BLOCK**3)
    else:
        monkeypatch.setattr(parity_grid, "FINE_WORK", 100)
    with pyclray.prepare(scene_of(mesh)) as tracer:
        for sign in ("parity", "winding"):
            assert np.array_equal(tracer.occupancy(points, sign), general_path(tracer, points, sign))
        grid = closest._parity_grid(tracer, tracer.mesh_handle(closed=True), "parity")
        refined = int((grid.blocks >= 0).sum())
        assert (0 < refined <= 20 if cap == "blocks" else refined == 0) and (grid.region < 0).sum() > 20
        assert fine_decided(grid, points).sum() < whole


@pytest.mark.parametrize("sign", ["parity", "winding"])
def test_the_device_lookup_is_the_hosts(monkeypatch, sign):
    """The GPU class's lookup (cast_device.py: grid_lookup_device, run here on PoCL) gives the
    host's (decided, inside) bit for bit on points near the surface (fine cells), uniform points and
    points beyond the grid; and the GPU class's occupancy and signed distance are the CPU's."""
    from pyclray.engine.queries.cast_device import grid_lookup_device

    rng = np.random.default_rng(36)
    v, f = perturbed_sphere(40, 60, 1.0, 0.08, rng)
    mesh = pyclray.Mesh(v + 1e6, f)
    with pyclray.prepare(scene_of(mesh)) as tracer:
        points = np.vstack([near_surface(tracer, mesh, 1e-2, 3 * COHERENT_FROM, rng),
                            rng.uniform(1e6 - 1.5, 1e6 + 1.5, (COHERENT_FROM, 3))])
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
        occupied, signed = tracer.occupancy(points, sign), tracer.signed_distance(points, sign)
        grid = closest._parity_grid(tracer, tracer.mesh_handle(closed=True), sign)
        host = grid.lookup(points, sign)
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", "1")
        device = grid_lookup_device(tracer, grid, points, sign)
        assert np.array_equal(tracer.occupancy(points, sign), occupied)
        assert np.array_equal(tracer.signed_distance(points, sign), signed)
    assert np.array_equal(device[0], host[0]) and np.array_equal(device[1], host[1])
    assert fine_decided(grid, points, sign).sum() > 100 and 0 < host[1][host[0]].mean() < 1


@pytest.mark.parametrize("shift", [0.0, 1e6])
def test_points_within_the_margin_are_in_surface_cells(shift):
    """The marks' claim (the widened boxes and planes): no point within the margin of a triangle
    lies in an empty cell, coarse or fine. Points on random triangles of a tilted mesh (the
    octahedron's faces, the perturbed sphere's) and of a sliver (a fan whose triangle's angle is
    below SLIVER: marked by its box), moved by 0.999 of the margin along the face normal and along
    random directions, near the origin and 1e6 from it: the grid decides none of them."""
    rng = np.random.default_rng(37)
    v, f = perturbed_sphere(30, 45, 1.0, 0.08, rng)
    sliver = pyclray.Mesh(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0],
                                    [0.5, 0.5 + 1e-12, 0.0]]) + shift,
                          np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 4, 3], [4, 2, 3], [1, 2, 4]]))
    for mesh in (octahedron(8, shift), pyclray.Mesh(v + shift, f), sliver):
        a, b, c = mesh.corners()
        grid = parity_grid.ParityGrid.of((a, b, c))
        grid.decide("parity", lambda points: np.zeros(len(points), bool))
        lo, hi = np.minimum(np.minimum(a, b), c).min(axis=0), np.maximum(np.maximum(a, b), c).max(axis=0)
        margin = max(parity_grid.SURFACE_MARGIN * float(np.abs(np.stack([lo, hi])).max()) + parity_grid.TINY,
                     parity_grid.CLEARANCE * grid.size)
        tri = rng.integers(0, len(a), 20_000)
        u = rng.uniform(0, 1, len(tri))
        w = rng.uniform(0, 1 - u)
        on = a[tri] + u[:, None] * (b[tri] - a[tri]) + w[:, None] * (c[tri] - a[tri])
        direction = rng.normal(size=on.shape)
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        normal = np.cross(b[tri] - a[tri], c[tri] - a[tri])
        length = np.linalg.norm(normal, axis=1, keepdims=True)
        # (at 1e6 the sliver is flat: a random direction instead of its normal)
        normal = np.where(length > 0, normal / np.where(length > 0, length, 1.0), direction)
        for step in (normal, -normal, direction):
            decided, _ = grid.lookup(on + 0.999 * margin * step, "parity")
            assert not decided.any()
        assert (grid.blocks >= 0).any()  # the fine level tested (the sliver's big faces' too: within FINE_WORK)


@pytest.mark.parametrize("shift", [0.0, 1e6])
def test_a_plane_passing_within_the_margin_of_a_cell_marks_it(shift):
    """The widened planes' margin itself: triangles whose plane passes beyond a cell's corner by
    less than the margin (the cell on the other side of the plane, so that only the widening marks
    it), each with a point in that cell within the margin of the triangle: no such point is decided
    by the grid, at the coarse level (a corner on a coarse cell's side) or the fine one. Near the
    origin and 1e6 from it; the grid's box fixed by two small triangles at [0, 1]^3's corners."""
    rng = np.random.default_rng(38)
    frame = [np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]]),
             np.array([[1.0, 1.0, 1.0], [0.99, 1.0, 1.0], [1.0, 0.99, 1.0]])]
    corners = [np.array(t) + shift for t in frame]
    probe = parity_grid.ParityGrid.of(tuple(np.stack([t[k] for t in corners]) for k in range(3)))
    lo, fine = probe.lo, probe.fine_size
    margin = max(parity_grid.SURFACE_MARGIN * (1.0 + shift) + parity_grid.TINY, parity_grid.CLEARANCE * probe.size)
    points = []
    for k in range(300):
        index = rng.integers(40, 470, 3)
        if k % 3 == 0:  # on a coarse cell's corner
            index -= index % parity_grid.BLOCK
        normal = rng.uniform(0.2, 1.0, 3)
        normal /= np.linalg.norm(normal)
        corner = lo + index * fine  # the cell's corner nearest the plane (the normal's components > 0)
        foot = corner - rng.uniform(0.001, 0.98) * margin * normal  # the plane's point nearest the corner
        u = np.cross(normal, [1.0, 0.0, 0.0])
        u /= np.linalg.norm(u)
        w = np.cross(normal, u)
        corners.append(np.array([foot + 0.5 * fine * u, foot - 0.3 * fine * u + 0.4 * fine * w,
                                 foot - 0.3 * fine * u - 0.4 * fine * w]))
        point = corner + 0.01 * margin / normal.sum()  # in the cell, within the margin of the plane
        if np.array_equal(np.floor((point - lo) / fine), index.astype(float)):
            points.append(point)
    grid = parity_grid.ParityGrid.of(tuple(np.stack([t[k] for t in corners]) for k in range(3)))
    assert np.array_equal(grid.lo, lo) and grid.fine_size == fine
    grid.decide("parity", lambda p: np.zeros(len(p), bool))
    points = np.array(points)
    assert len(points) > 250
    decided, _ = grid.lookup(points, "parity")
    assert not decided.any()
    assert (grid.blocks >= 0).sum() > 250  # the test triangles' coarse cells refined: the fine level tested


def test_the_fine_level_is_made_for_batches_near_the_surface():
    """A uniform batch (its points mostly in empty coarse cells) is answered by the coarse level
    alone, made without the fine one; the first batch near the surface (most of its points in coarse
    surface cells: closest.FINE_FROM) makes the fine level, which then serves every batch: the same
    answers as the general path each time."""
    rng = np.random.default_rng(39)
    v, f = perturbed_sphere(40, 60, 1.0, 0.08, rng)
    mesh = pyclray.Mesh(v, f)
    with pyclray.prepare(scene_of(mesh)) as tracer:
        closed = tracer.mesh_handle(closed=True)
        uniform = rng.uniform(-1.2, 1.2, (COHERENT_FROM + 500, 3))
        assert np.array_equal(tracer.occupancy(uniform), general_path(tracer, uniform))
        coarse = closest._parity_grid(tracer, closed, "parity")
        assert not coarse.refined and not (coarse.blocks >= 0).any()
        near = near_surface(tracer, mesh, 1e-2, COHERENT_FROM + 500, rng)
        assert np.array_equal(tracer.occupancy(near), general_path(tracer, near))
        fine = closest._parity_grid(tracer, closed, "parity")
        assert fine is not coarse and fine.refined and (fine.blocks >= 0).any()
        assert np.array_equal(fine.states["parity"][0], coarse.states["parity"][0])  # the same coarse cells' answers
        assert fine_decided(fine, near).mean() > 0.1
        assert np.array_equal(tracer.occupancy(uniform), general_path(tracer, uniform))
        assert closest._parity_grid(tracer, closed, "parity") is fine


def test_large_tilted_triangles_are_refined():
    """The octahedron of 8 triangles, each one's box an eighth of the grid's volume: the fine marks'
    work counts its box's fine cells within refined blocks only (parity_grid._fine_work), so the
    fine level is made, thin along the tilted faces: more than 30% of the points within 1% of the
    size decided in fine cells (46% here), the same answers as the general path."""
    rng = np.random.default_rng(40)
    mesh = octahedron(1)
    with pyclray.prepare(scene_of(mesh)) as tracer:
        points = near_surface(tracer, mesh, 1e-2, COHERENT_FROM + 500, rng)
        for sign in ("parity", "winding"):
            assert np.array_equal(tracer.occupancy(points, sign), general_path(tracer, points, sign))
        grid = closest._parity_grid(tracer, tracer.mesh_handle(closed=True), "parity")
        assert (grid.blocks >= 0).sum() > 1000
        assert fine_decided(grid, points).mean() > 0.3
