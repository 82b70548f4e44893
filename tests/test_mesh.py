"""Triangle meshes (pyclray.Mesh, kernels/mesh.cl): watertightness (pbrt-v4's and Embree's tests),
exactness far from the origin in fp32 and fp64, the primitive and barycentric images, transforms,
zero-area triangles, and the arrays Mesh.load and placed share. Files and bad input are in
tests/test_mesh_files.py. The generic suite (tests/test_shapes.py) runs meshes too."""
import numpy as np
import pytest

import pyclray
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.model.shapes.mesh_shapes import grid, perturbed_sphere, torus, uv_sphere
from pyclray.reference import oracle

from oracle_checks import assert_agrees_with_oracle, assert_primitives_agree, judge


def need(precision):
    if precision == "fp64" and not has_fp64(context_for().device):
        pytest.skip("device lacks cl_khr_fp64")


def scene_of(*shapes, eye=(0, 0, 6), target=(0, 0, 0), size=(64, 48)):
    return pyclray.Scene(pyclray.Camera(eye, target), pyclray.Image(*size), tuple(shapes))


def edge_points(vertices, faces, rng, count):
    """Points on the mesh's edges (at random positions along random edges)."""
    pick = rng.integers(0, len(faces), count)
    k = rng.integers(0, 3, count)
    a = vertices[faces[pick, k]]
    b = vertices[faces[pick, (k + 1) % 3]]
    s = rng.uniform(0, 1, (count, 1))
    return a + s * (b - a)


# -- watertightness ------------------------------------------------------------------------------
@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_pbrt_watertight_closed_perturbed_sphere(precision):
    """pbrt-v4's watertightness test (shapes_test.cpp): a closed sphere with perturbed vertices,
    rays from points inside aimed at random points, at its vertices and at points of its edges:
    every one hits (a miss is a ray slipping between two triangles). The mesh is placed off the
    origin, so that its vertices are not small numbers."""
    need(precision)
    rng = np.random.default_rng(7)
    vertices, faces = perturbed_sphere(24, 48, 1.0, 0.3, rng)
    mesh = pyclray.Mesh(vertices, faces, translate=(3.0, -2.0, 5.0))
    world = mesh.world_vertices()
    centre = np.array([3.0, -2.0, 5.0])
    targets = np.concatenate([world, edge_points(world, faces, rng, 20000),
                              centre + rng.normal(size=(5000, 3))])
    origins = centre + rng.uniform(-0.5, 0.5, (len(targets), 3))  # inside (radii >= 0.7)
    hits = pyclray.cast(scene_of(mesh), origins, targets - origins, aovs=("id",), precision=precision)
    assert np.all(hits["id"] == 0), f"{np.sum(hits['id'] != 0)} of {len(targets)} rays slipped through"


def test_embree_watertight_sphere_and_far_grid():
    """Embree's watertightness test (its verify tool): a sphere of radius 2 with 200 segments, and a
    200 x 200 grid placed at (148376, 1234, -223423), where float32 world coordinates have an ulp of
    1/64: rays from the sphere's centre at its vertices and edges, and rays from above the grid at
    its vertices and edges, all hit (fp32, cast and a render from the sphere's centre)."""
    rng = np.random.default_rng(11)
    vertices, faces = uv_sphere(200, 200, 2.0)
    sphere = pyclray.Mesh(vertices, faces, translate=(148376.0, 1234.0, -223423.0), name="sphere")
    centre = np.array([148376.0, 1234.0, -223423.0])
    world = sphere.world_vertices()
    targets = np.concatenate([world, edge_points(world, faces, rng, 30000)])
    hits = pyclray.cast(scene_of(sphere), centre, targets - centre, aovs=("id",))
    assert np.all(hits["id"] == 0), f"{np.sum(hits['id'] != 0)} rays slipped through the sphere"
    inside = pyclray.Scene(pyclray.Camera(tuple(centre), tuple(centre + [0.3, 0.2, 1.0]), fov=120.0),
                           pyclray.Image(256, 256), (sphere,))
    assert np.all(pyclray.render(inside, aovs=("id",))["id"] == 0)

    g_vertices, g_faces = grid(200, 200, 50.0)
    plane = pyclray.Mesh(g_vertices, g_faces, translate=(148376.0, 1234.0, -223423.0), name="grid")
    world = plane.world_vertices()
    targets = np.concatenate([world, edge_points(world, g_faces, rng, 30000)])
    inner = np.all(np.abs(targets - centre)[:, [0, 2]] < 24.9, axis=1)  # not the grid's boundary
    targets = targets[inner]
    origins = targets + np.array([0.0, 10.0, 0.0]) + rng.uniform(-5, 5, (len(targets), 3))
    hits = pyclray.cast(scene_of(plane), origins, targets - origins, aovs=("id",))
    assert np.all(hits["id"] == 0), f"{np.sum(hits['id'] != 0)} rays slipped through the grid"
    above = pyclray.Scene(pyclray.Camera(tuple(centre + [0.0, 8.0, 0.0]), tuple(centre), up=(0, 0, 1), fov=60.0),
                          pyclray.Image(256, 256), (plane,))
    assert np.all(pyclray.render(above, aovs=("id",))["id"] == 0)


# -- exactness, near and far ---------------------------------------------------------------------
@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("offset", [0.0, 1e6, 3e7])
def test_render_agrees_with_the_oracle_far_from_the_origin(precision, offset):
    """A torus and a perturbed sphere on a grid, the whole scene (camera included) moved by offset:
    depth and normal within the error model of the camera-relative frame, ids and primitives
    right wherever a ray is judged; the same for cast rays of random origins."""
    need(precision)
    rng = np.random.default_rng(3)
    shift = np.array([offset, -0.5 * offset, 0.25 * offset])
    v, f = torus(24, 16, 1.0, 0.35)
    ring = pyclray.Mesh(v, f, axis=(1, 0, 0), angle=60.0, translate=tuple(shift + [-1.0, 0.8, 0.0]))
    v, f = perturbed_sphere(12, 24, 0.8, 0.2, rng)
    ball = pyclray.Mesh(v, f, translate=tuple(shift + [1.3, 0.8, 0.3]))
    v, f = grid(8, 8, 8.0)
    floor = pyclray.Mesh(v, f, translate=tuple(shift))
    scene = pyclray.Scene(pyclray.Camera(tuple(shift + [0.0, 2.5, 6.0]), tuple(shift + [0.0, 0.5, 0.0])),
                          pyclray.Image(48, 36), (ring, ball, floor))
    frame = pyclray.render(scene, aovs=("depth", "normal", "id", "primitive"), precision=precision)
    origins, directions = oracle.camera_rays(scene)
    origins, directions = origins.reshape(-1, 3), directions.reshape(-1, 3)
    result = {k: frame[k].reshape(len(directions), *frame[k].shape[2:]) for k in ("depth", "normal", "id")}
    truth, cos, judged, _, _, _ = judge(scene, origins, directions, result, precision, scene.camera.eye)
    assert_agrees_with_oracle(scene, origins, directions, result, precision)
    assert judged.sum() > 0.9 * np.sum(truth["id"] >= 0)
    assert_primitives_agree(scene, origins, directions, frame, truth, judged)
    far = shift + rng.normal(size=(2000, 3)) * 4
    aim = shift + rng.normal(size=(2000, 3)) * 1.0
    assert_agrees_with_oracle(scene, far, aim - far, pyclray.cast(scene, far, aim - far, precision=precision), precision)


def test_barycentric_image():
    """barycentric (u, v): hit = (1 - u - v) a + u b + v c of the triangle hit, as the oracle's,
    within float32 rounding relative to the triangle; (0, 0) on a miss and on other shapes."""
    v, f = perturbed_sphere(8, 12, 1.0, 0.2, np.random.default_rng(1))
    mesh = pyclray.Mesh(v, f)
    scene = scene_of(mesh, pyclray.Sphere((2.2, 0, 0), 0.5), size=(40, 30))
    frame = pyclray.render(scene, aovs=("id", "primitive", "barycentric"))
    assert frame["barycentric"].shape == (30, 40, 2) and frame["barycentric"].dtype == np.float32
    origins, directions = oracle.camera_rays(scene)
    t, which, uv = mesh.oracle_hits(origins.reshape(-1, 3), directions.reshape(-1, 3))
    mine = (frame["id"].reshape(-1) == 0) & (frame["primitive"].reshape(-1) == which)
    assert mine.sum() > 150
    got = frame["barycentric"].reshape(-1, 2)
    assert np.abs(got[mine] - uv[mine]).max() < 1e-4
    assert np.all(got[frame["id"].reshape(-1) != 0] == 0)


def test_zero_area_triangles_are_never_hit():
    """Degenerate triangles (a repeated vertex, three collinear vertices) are never hit and give no
    NaN, in render and cast, also when a ray runs along them."""
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [0.5, 0.5, 0.0]], np.float64)
    faces = np.array([[0, 1, 1], [0, 1, 3], [1, 4, 2], [0, 1, 2]])
    mesh = pyclray.Mesh(vertices, faces)
    assert np.all(mesh.face_normals()[:3] == 0)
    scene = scene_of(mesh, eye=(0.3, 0.3, 3), target=(0.3, 0.3, 0), size=(32, 32))
    frame = pyclray.render(scene, aovs=("depth", "normal", "id", "primitive"))
    for value in frame.values():
        assert not np.isnan(np.asarray(value, np.float64)).any()
    assert set(np.unique(frame["primitive"])) <= {-1, 3}
    origins = np.array([[0.5, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.5, 0.5, 1.0]])
    directions = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    hits = pyclray.cast(scene, origins, directions)
    assert not np.isnan(hits["depth"]).any()
    assert hits["id"][1] == -1  # along the collinear triangles and the edge of the real one: no hit


def test_two_sided_and_mirrored_normals():
    """A triangle is hit from both sides; its normal is cross(b - a, c - a) of the world vertices,
    never flipped toward the viewer: a mirroring scale turns it around (one across the triangle's own
    plane moves no vertex, and keeps it)."""
    vertices = np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], np.float64)
    faces = np.array([[0, 1, 2]])
    for scale, expected in ((1.0, 1.0), ((1.0, 1.0, -1.0), 1.0), ((-1.0, 1.0, 1.0), -1.0)):
        mesh = pyclray.Mesh(vertices, faces, scale=scale)
        for eye in ((0, 0, 3), (0, 0, -3)):
            frame = pyclray.render(scene_of(mesh, eye=eye, size=(9, 9)), aovs=("depth", "normal", "id"))
            assert frame["id"][4, 4] == 0
            assert np.allclose(frame["normal"][4, 4], (0, 0, expected))
            assert abs(frame["depth"][4, 4] - 3.0) < 1e-6


def test_matrix_equals_scale_rotate_translate():
    """matrix = T R S gives the same world vertices as scale, axis, angle and translate, and the same
    image bit for bit."""
    from pyclray.model.shapes.box import rotation

    v, f = torus(12, 8)
    placed = pyclray.Mesh(v, f, scale=(1.0, 2.0, 0.5), axis=(1, 1, 0), angle=30.0, translate=(0.5, -0.2, 0.1))
    m = np.eye(4)
    m[:3, :3] = rotation((1, 1, 0), 30.0) * np.array([1.0, 2.0, 0.5])
    m[:3, 3] = (0.5, -0.2, 0.1)
    same = pyclray.Mesh(v, f, matrix=m)
    assert np.array_equal(placed.world_vertices(), same.world_vertices())
    a = pyclray.render(scene_of(placed), aovs=("depth", "id"))
    b = pyclray.render(scene_of(same), aovs=("depth", "id"))
    assert np.array_equal(a["depth"], b["depth"])


def test_placed_shares_the_arrays():
    """Mesh.placed keeps the very arrays (no copy per placement); the placements render apart."""
    v, f = uv_sphere(8, 12, 0.5)
    base = pyclray.Mesh(v, f)
    copies = [base.placed(translate=(x, 0.0, 0.0), name=f"ball{x}") for x in (-1.5, 0.0, 1.5)]
    assert all(c.vertices is base.vertices and c.faces is base.faces for c in copies)
    frame = pyclray.render(scene_of(*copies, size=(64, 16)), aovs=("id",))
    assert set(np.unique(frame["id"])) == {-1, 0, 1, 2}
