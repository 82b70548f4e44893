"""signed_distance and occupancy: the inside of every solid against the float64 oracle (exact where
a sign decides), sign="winding" against the oracle's and libigl's winding numbers, sign="parity"
on closed meshes (count_hits' exact crossings), Mesh.closed, Open3D's own cases for
compute_distance / compute_signed_distance / compute_occupancy (ported), bad arguments.

The distance part is closest_points' (tests/test_closest.py: within a few eps64 of the oracle).
Inside/outside is exact for the analytic solids and, with parity, for closed meshes, for every point
not on a surface; a point on a surface is at distance 0 and inside. The winding number is a
hierarchical approximation (engine/bvh/winding.py) within 1e-3 of the exact sum: its inside is held
to the exact one wherever the exact winding number is not within 1e-3 of 1/2.
"""
import igl
import numpy as np
import pytest

import pyclray
from pyclray.model.shapes import REGISTRY
from pyclray.model.shapes.mesh_shapes import torus, uv_sphere
from pyclray.reference import error_model, oracle

CAMERA = pyclray.Camera((0, 0, 10), (0, 0, 0))


def scene_of(shapes) -> pyclray.Scene:
    return pyclray.Scene(CAMERA, pyclray.Image(8, 8), tuple(shapes))


def unit_cube_mesh(drop=None, flip=None) -> pyclray.Mesh:
    """The cube [0, 1]^3 as 12 outward triangles (Open3D's create_box's solid); drop: leave out that
    face (a hole), flip: turn that face inside out."""
    vertices = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64)
    faces = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
             [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    if flip is not None:
        faces[flip] = faces[flip][::-1]
    if drop is not None:
        del faces[drop]
    return pyclray.Mesh(vertices=vertices, faces=np.array(faces))


def kernel_winding(scene, points):
    """The kernel's hierarchical winding number (the engine's own output, for its accuracy)."""
    from pyclray.engine.queries.closest import run_closest

    with pyclray.prepare(scene, precision="fp64") as tracer:
        return run_closest(tracer, np.asarray(points, np.float64), ("winding",))["winding"]


# -- Mesh.closed -------------------------------------------------------------------------------------
def test_mesh_closed():
    assert unit_cube_mesh().closed
    assert not unit_cube_mesh(drop=3).closed  # a hole: its border's edges have one face
    assert not unit_cube_mesh(flip=3).closed  # a face turned over: its edges run the same way as the neighbours'
    v, f = uv_sphere(8, 12)
    assert pyclray.Mesh(v, f).closed
    v, f = torus(8, 12)
    assert pyclray.Mesh(v, f).closed
    cube = unit_cube_mesh()
    # a fin on an edge: three faces on it
    fin = pyclray.Mesh(np.vstack([cube.vertices, [[0.5, -1, -1]]]), np.vstack([cube.faces, [[0, 4, 8]]]))
    assert not fin.closed
    assert not pyclray.Mesh(np.eye(3), np.array([[0, 1, 2]])).closed


def test_bunny_is_closed(scenes_dir):
    scene = pyclray.load_scene(scenes_dir / "mesh.toml")
    assert [s.closed for s in scene.shapes if s.type == "mesh"] == [True]


# -- analytic solids ---------------------------------------------------------------------------------
@pytest.mark.parametrize("type_name", sorted(t for t in REGISTRY if t != "mesh"))
@pytest.mark.parametrize("shift", [0.0, 1e6])
def test_analytic_solids_agree_with_oracle(type_name, shift):
    """Each type's inside (none for disks and rectangles; an open cylinder none either) against the
    oracle's exact test, both signs, near the origin in fp32 and 1e6 away in fp64."""
    precision = "fp32" if shift == 0 else "fp64"
    rng = np.random.default_rng(3)
    shapes = [REGISTRY[type_name].random(rng, shift) for _ in range(3)]
    if type_name == "cylinder":  # one of each kind
        shapes[0] = pyclray.Cylinder(shapes[0].p0, shapes[0].p1, shapes[0].radius, caps=True)
        shapes[1] = pyclray.Cylinder(shapes[1].p0, shapes[1].p1, shapes[1].radius, caps=False)
    scene = scene_of(shapes)
    points = shift + rng.uniform(-5, 5, (4000, 3))
    truth = oracle.closest_points(scene, points)
    tol = error_model.closest_tolerances(points, truth, precision)
    clear = truth["distance"] > tol["distance"]  # off every surface: inside is exact there
    for sign in ("parity", "winding"):
        expected = oracle.inside(scene, points, sign)
        occupancy = pyclray.occupancy(scene, points, sign=sign, precision=precision)
        assert occupancy.dtype == np.uint8
        assert np.array_equal(occupancy[clear], expected[clear].astype(np.uint8))
        sd = pyclray.signed_distance(scene, points, sign=sign, precision=precision)
        assert np.array_equal((sd < 0)[clear], expected[clear])
        assert (np.abs(np.abs(sd) - truth["distance"]) <= tol["distance"]).all()
    if type_name in ("disk", "rectangle"):
        assert not expected.any()


def test_points_on_surfaces_are_inside_at_distance_zero():
    """A point exactly on a surface (distance 0 in float64) is inside, even of a shape without an
    inside, and its signed distance is 0 (not -0)."""
    scene = scene_of([pyclray.Sphere((0, 0, 0), 1.0), pyclray.Disk((5, 0, 0), (0, 0, 1), 1.0),
                      pyclray.Box(center=(0, 5, 0), size=(2, 2, 2)), pyclray.Plane((0, 0, 1), 10.0)])
    points = np.array([[1.0, 0, 0], [5.5, 0, 0], [1.0, 5, 0.5], [0, 0, -10.0], [5.0, 0, 1.0]])
    for sign in ("parity", "winding"):
        assert pyclray.occupancy(scene, points, sign=sign).tolist() == [1, 1, 1, 1, 0]
        sd = pyclray.signed_distance(scene, points, sign=sign, precision="fp64")
        assert sd.tolist() == [0.0, 0.0, 0.0, 0.0, 1.0] and not np.signbit(sd[:4]).any()


def test_exact_inside_next_to_the_surface():
    """Points one float64 ulp inside and outside a sphere, a box's face and a plane: the kernel's
    inside agrees with the oracle's exact one."""
    scene = scene_of([pyclray.Sphere((0.1, 0.2, 0.3), 0.7), pyclray.Box(center=(3, 0, 0), size=(1, 1, 1)),
                      pyclray.Plane((0, 0, 1), 20.0)])
    x = 0.1 + 0.7
    points = np.array([[np.nextafter(x, 0), 0.2, 0.3], [np.nextafter(x, 1), 0.2, 0.3], [3.5, 0, 0],
                       [np.nextafter(3.5, 4), 0, 0], [0, 0, np.nextafter(-20.0, 0)], [0, 0, np.nextafter(-20.0, -21)]])
    expected = oracle.inside(scene, points)
    assert np.array_equal(pyclray.occupancy(scene, points, precision="fp64").astype(bool), expected)


# -- winding numbers ---------------------------------------------------------------------------------
def open_meshes():
    """Open meshes: the cube with a hole, a sphere with its top cap gone, two overlapping spheres
    (self-intersecting as one mesh) of which one is missing a band."""
    cube = unit_cube_mesh(drop=2)
    v, f = uv_sphere(12, 16, 1.0)
    top = f[(v[f][:, :, 2] > 0.8).any(axis=1)]
    capless = pyclray.Mesh(v, f[~(v[f][:, :, 2] > 0.8).any(axis=1)], translate=(3.0, 0.0, 0.0))
    assert len(top)
    band = np.abs(v[f][:, :, 2]).max(axis=1) < 0.3
    v2, f2 = uv_sphere(12, 16, 0.8)
    both = pyclray.Mesh(np.vstack([v, v2 + [0.5, 0, 0]]), np.vstack([f[~band], f2 + len(v)]), translate=(0.0, 4.0, 0.0))
    return [cube, capless, both]


@pytest.mark.parametrize("index", range(3))
def test_winding_agrees_with_oracle_and_libigl(index):
    mesh = open_meshes()[index]
    assert not mesh.closed
    scene = scene_of([mesh])
    rng = np.random.default_rng(index)
    lo, hi = np.asarray(mesh.box())
    points = rng.uniform(lo - 0.5, hi + 0.5, (3000, 3))
    V, F = mesh.world_vertices(), np.asarray(mesh.faces, np.int64)
    exact = igl.winding_number(V, F, points)
    assert np.allclose(exact, oracle.winding_number(scene, points), atol=1e-9)
    # the hierarchy's error (engine/bvh/winding.py)
    assert np.abs(kernel_winding(scene, points) - exact).max() < 1e-3
    decided = np.abs(exact - 0.5) > 1e-3
    occupancy = pyclray.occupancy(scene, points, sign="winding")
    assert np.array_equal(occupancy[decided].astype(bool), (exact >= 0.5)[decided])
    # libigl's fast (hierarchical) winding numbers, and its signed distance by winding number
    fast = igl.fast_winding_number(V, F, points)
    sure = decided & (np.abs(fast - 0.5) > 1e-2)
    assert np.array_equal(occupancy[sure].astype(bool), (fast >= 0.5)[sure])
    sd = pyclray.signed_distance(scene, points, sign="winding", precision="fp64")
    unsigned, _, _, _ = igl.signed_distance(points, V, F, sign_type=igl.SIGNED_DISTANCE_TYPE_UNSIGNED)
    assert np.allclose(np.abs(sd), unsigned, rtol=0, atol=1e-12)
    # libigl's winding-number signed distance is (1 - 2 w) times the distance: its sign is w's side of 1/2
    S, _, _, _ = igl.signed_distance(points, V, F, sign_type=igl.SIGNED_DISTANCE_TYPE_WINDING_NUMBER)
    assert np.array_equal((sd < 0)[decided], (S < 0)[decided])
    # parity: an open mesh has no inside
    assert not pyclray.occupancy(scene, points, sign="parity").any()


def test_winding_of_bunny_within_1e3(scenes_dir):
    scene = pyclray.load_scene(scenes_dir / "mesh.toml")
    bunny = scene_of([s for s in scene.shapes if s.type == "mesh"])
    mesh = bunny.shapes[0]
    lo, hi = np.asarray(mesh.box())
    points = np.random.default_rng(0).uniform(lo - 0.1, hi + 0.1, (5000, 3))
    exact = igl.winding_number(mesh.world_vertices(), np.asarray(mesh.faces, np.int64), points)
    assert np.abs(kernel_winding(bunny, points) - exact).max() < 1e-3


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_winding_far_from_origin(precision):
    v, f = torus(16, 24, 1.0, 0.3)
    mesh = pyclray.Mesh(v, f, translate=(1e6, -1e6, 1e6))
    scene = scene_of([mesh])
    rng = np.random.default_rng(4)
    points = np.array([1e6, -1e6, 1e6]) + rng.uniform(-1.5, 1.5, (2000, 3))
    exact = oracle.winding_number(scene, points)
    decided = np.abs(exact - 0.5) > 1e-3
    occupancy = pyclray.occupancy(scene, points, sign="winding", precision=precision)
    assert np.array_equal(occupancy[decided].astype(bool), (exact >= 0.5)[decided])
    assert occupancy[decided].any() and not occupancy[decided].all()


# -- parity (count_hits) ------------------------------------------------------------------------------
@pytest.mark.parametrize("shift", [0.0, 1e6])
def test_parity_on_closed_meshes(shift):
    """Closed meshes (a torus and a perturbed sphere, one in the other's hole): parity agrees with the
    exact winding number's parity off the surface, fp32 near the origin and fp64 far from it."""
    rng = np.random.default_rng(8)
    v, f = torus(12, 20, 1.0, 0.35)
    shapes = [pyclray.Mesh(v, f, translate=(shift, shift, 0.0)), pyclray.Mesh.random(rng, shift)]
    scene = scene_of(shapes)
    assert all(s.closed for s in shapes)
    points = np.array([shift, shift, 0.0]) + rng.uniform(-2, 2, (3000, 3))
    precision = "fp32" if shift == 0 else "fp64"
    expected = oracle.inside(scene, points, "parity")
    truth = oracle.closest_points(scene, points)
    clear = truth["distance"] > 0
    occupancy = pyclray.occupancy(scene, points, sign="parity", precision=precision)
    assert np.array_equal(occupancy[clear].astype(bool), expected[clear])
    sd = pyclray.signed_distance(scene, points, sign="parity", precision=precision)
    assert np.array_equal((sd < 0)[clear], expected[clear])


def test_parity_at_vertices_and_edges_grid():
    """Open3D's sphere-occupancy case (ported: a UV sphere of radius 0.8, a 6 x 6 x 6 grid over 1.1
    times its box, whose rays meet its vertices and edges): every point right by parity."""
    v, f = uv_sphere(20, 20, 0.8)
    mesh = pyclray.Mesh(v, f)
    scene = scene_of([mesh])
    lo, hi = v.min(axis=0) * 1.1, v.max(axis=0) * 1.1
    axes = np.linspace(lo, hi, num=6)
    points = np.stack(np.meshgrid(*axes.T), axis=-1)
    radius = np.linalg.norm(points, axis=-1)
    assert not ((radius > 0.77) & (radius < 0.81)).any()  # every point clearly in or out
    expected = (radius < 0.8).astype(np.uint8)
    for sign in ("parity", "winding"):
        assert np.array_equal(pyclray.occupancy(scene, points.astype(np.float32), sign=sign), expected)


# -- Open3D's cases, ported ---------------------------------------------------------------------------
@pytest.mark.parametrize("sign", ["parity", "winding"])
def test_open3d_cube_cases(sign):
    """Open3D's test_compute_distance / _signed_distance / _occupancy on its unit box."""
    scene = scene_of([unit_cube_mesh()])
    points = np.array([[0.5, 0.5, 0.5], [-0.5, -0.5, -0.5], [0, 0, 0]], np.float32)
    assert np.allclose(pyclray.distance(scene, points), [0.5, np.sqrt(3 * 0.5**2), 0.0], rtol=1e-15, atol=0)
    assert np.allclose(pyclray.signed_distance(scene, points, sign=sign), [-0.5, np.sqrt(3 * 0.5**2), 0.0], rtol=1e-15, atol=0)
    assert pyclray.occupancy(scene, points[:2], sign=sign).tolist() == [1, 0]
    # the corner itself is on the surface: inside, at distance 0
    assert pyclray.occupancy(scene, points[2:], sign=sign).tolist() == [1]


def test_open3d_closest_points_case():
    """Open3D's test_compute_closest_points: one triangle, a point above it and one far away."""
    mesh = pyclray.Mesh(vertices=np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]]), faces=np.array([[0, 1, 2]]))
    r = pyclray.closest_points(scene_of([mesh]), np.array([[0.2, 0.1, 1], [10, 10, 10]], np.float32))
    assert (r["id"] == 0).all() and (r["primitive"] == 0).all()
    assert np.allclose(r["position"], [[0.2, 0.1, 0.0], [1, 1, 0]], rtol=0, atol=1e-7)


@pytest.mark.parametrize("shape", ([11], [1, 2, 3], [32, 14]))
def test_open3d_output_shapes(shape):
    """Open3D's test_output_shapes for the point queries: outputs of the points' leading shape."""
    mesh = pyclray.Mesh(vertices=np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]]), faces=np.array([[0, 1, 2]]))
    scene = scene_of([mesh])
    points = np.random.RandomState(123).uniform(size=shape + [3]).astype(np.float32)
    assert list(pyclray.distance(scene, points).shape) == shape
    assert list(pyclray.signed_distance(scene, points).shape) == shape
    assert list(pyclray.occupancy(scene, points).shape) == shape
    r = pyclray.closest_points(scene, points)
    extra = {"position": [3], "normal": [3], "barycentric": [2]}
    for key, value in r.items():
        assert list(value.shape) == shape + extra.get(key, []), key


# -- arguments ----------------------------------------------------------------------------------------
def test_bad_sign():
    scene = scene_of([pyclray.Sphere((0, 0, 0), 1.0)])
    for query in (pyclray.signed_distance, pyclray.occupancy):
        with pytest.raises(ValueError, match=r"sign: expected one of 'parity', 'winding', got 'even'"):
            query(scene, np.zeros((1, 3)), sign="even")


def test_closed_meshes_winding_is_the_signed_crossing_count():
    """A closed mesh's winding number is exact: the signed count of one ray's crossings. Two spheres
    overlapping as one closed, self-intersecting mesh: winding 2 in their overlap (inside by winding,
    even and so outside by parity); one turned inside out: winding -1 (outside by winding)."""
    from pyclray.engine.queries.closest import winding_numbers

    v, f = uv_sphere(16, 24, 1.0)
    overlapping = pyclray.Mesh(np.vstack([v, v + [1.0, 0, 0]]), np.vstack([f, f + len(v)]))
    inverted = pyclray.Mesh(v, f[:, ::-1], translate=(0.0, 5.0, 0.0))
    scene = scene_of([overlapping, inverted])
    assert overlapping.closed and inverted.closed
    points = np.array([[0.5, 0.0, 0.1], [-0.5, 0.0, 0.1], [1.5, 0.0, 0.1], [3.0, 0.0, 0.0], [0.1, 5.0, 0.1]])
    exact = oracle.winding_number(scene, points)
    assert np.allclose(exact, [2, 1, 1, 0, -1], atol=1e-9)
    with pyclray.prepare(scene) as tracer:
        assert winding_numbers(tracer, points).tolist() == [2.0, 1.0, 1.0, 0.0, -1.0]
    assert pyclray.occupancy(scene, points, sign="winding").tolist() == [1, 1, 1, 0, 0]
    assert pyclray.occupancy(scene, points, sign="parity").tolist() == [0, 1, 1, 0, 1]
    rng = np.random.default_rng(12)
    points = rng.uniform([-1.5, -1.5, -1.5], [2.5, 6.5, 1.5], (3000, 3))
    exact = oracle.winding_number(scene, points)
    with pyclray.prepare(scene) as tracer:
        assert np.array_equal(winding_numbers(tracer, points), np.rint(exact))
