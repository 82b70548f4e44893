"""Occupancy's parity rays and large batches: each point's ray goes toward the nearest face of its
closed meshes' box (engine/queries/closest.py: parity_directions), and batches of COHERENT_FROM
points or more take the compiled passes (engine/queries/point_passes.py: the nearest faces, the
points' Morton order). Any ray is exact (count_hits' tie rule), so the answers are the exact
inside: held here to a truth known by construction (the unit cube's, on points of dyadic
coordinates: on its faces, edges and corners too, where a point is on the surface and so inside)
and to the float64 oracle; the compiled passes to numpy's own computation of the same thing."""
import numpy as np
import pytest

import pyclray
from pyclray.engine.queries.closest import COHERENT_FROM, PARITY_FACES, parity_directions
from pyclray.engine.queries.point_passes import coherent_order, nearest_face_directions
from pyclray.model.shapes.mesh_shapes import torus
from pyclray.reference import oracle

CAMERA = pyclray.Camera((0, 0, 10), (0, 0, 0))


def scene_of(shapes) -> pyclray.Scene:
    return pyclray.Scene(CAMERA, pyclray.Image(8, 8), tuple(shapes))


def cube_mesh(shift: float) -> pyclray.Mesh:
    """The cube [0, 1]^3 + shift as 12 outward triangles (its faces along the axes: the parity rays'
    nearly axial directions meet its edges and faces at grazing angles)."""
    vertices = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64) + shift
    faces = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
             [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    return pyclray.Mesh(vertices=vertices, faces=np.array(faces))


@pytest.mark.parametrize("shift, precision", [(0.0, "fp32"), (1e6, "fp64")])
@pytest.mark.parametrize("sign", ["parity", "winding"])
def test_cube_large_batch_exact_on_and_off_the_surface(shift, precision, sign):
    """COHERENT_FROM + 500 points of the grid {-1/4, 0, 1/8, ..., 1, 5/4}^3 + shift (exact in
    float64): inside is 0 < x, y, z < 1 or on a face (a coordinate 0 or 1 and the others in [0, 1])."""
    rng = np.random.default_rng(5)
    grid = np.array([-0.25, 0.0, 0.125, 0.25, 0.5, 0.75, 1.0, 1.25])
    local = grid[rng.integers(0, len(grid), (COHERENT_FROM + 500, 3))]
    expected = ((local >= 0) & (local <= 1)).all(axis=1)
    points = local + shift
    assert np.array_equal(points - shift, local)
    scene = scene_of([cube_mesh(shift)])
    got = pyclray.occupancy(scene, points, sign=sign, precision=precision)
    assert np.array_equal(got.astype(bool), expected)
    # the first 100 alone (below COHERENT_FROM: numpy's directions, no order): the same answers
    assert np.array_equal(pyclray.occupancy(scene, points[:100], sign=sign, precision=precision), got[:100])


@pytest.mark.parametrize("sign", ["parity", "winding"])
def test_closed_meshes_large_batch_against_oracle(sign):
    """A torus and a perturbed sphere (closed), COHERENT_FROM + 200 points in and around them: the
    oracle's exact inside wherever the point is off the surface; their vertices (on it) are inside."""
    rng = np.random.default_rng(21)
    v, f = torus(12, 20, 1.0, 0.35)
    shapes = [pyclray.Mesh(v, f), pyclray.Mesh.random(rng, 0.0)]
    scene = scene_of(shapes)
    points = rng.uniform(-2, 2, (COHERENT_FROM + 200, 3))
    expected = oracle.inside(scene, points, sign)
    clear = oracle.closest_points(scene, points)["distance"] > 0
    got = pyclray.occupancy(scene, points, sign=sign, precision="fp64")
    assert np.array_equal(got.astype(bool)[clear], expected[clear])
    vertices = np.vstack([s.world_vertices() for s in shapes])
    on = np.vstack([vertices] * (COHERENT_FROM // len(vertices) + 1))
    assert pyclray.occupancy(scene, on, sign=sign, precision="fp64").all()


def test_nearest_face_directions_match_numpy():
    """The compiled pass picks numpy's argmin of the six gaps (the first nearest face on ties)."""
    rng = np.random.default_rng(2)
    lo, hi = np.array([-1.0, 0.0, 2.0]), np.array([1.0, 3.0, 2.5])
    points = np.vstack([rng.uniform(lo - 1, hi + 1, (3000, 3)), np.array([[0.0, 1.5, 2.25], [-1.0, 0.0, 2.0]])])
    gaps = np.concatenate([points - lo, hi - points], axis=1)
    assert np.array_equal(nearest_face_directions(points, lo, hi, PARITY_FACES), PARITY_FACES[np.argmin(gaps, axis=1)])


def test_parity_directions_point_out_through_the_nearest_face():
    """Each direction's largest component is along the nearest face's axis, outward; none is along an
    axis exactly."""
    scene = scene_of([cube_mesh(0.0)])
    rng = np.random.default_rng(4)
    points = rng.uniform(-0.5, 1.5, (COHERENT_FROM + 10, 3))
    with pyclray.prepare(scene) as tracer:
        directions = parity_directions(tracer.mesh_handle(closed=True), points)
    axis = np.argmax(np.abs(directions), axis=1)
    gaps = np.concatenate([points, 1.0 - points], axis=1)
    nearest = np.argmin(gaps, axis=1)
    assert np.array_equal(axis, nearest % 3)
    assert np.array_equal(np.sign(directions[np.arange(len(points)), axis]), np.where(nearest < 3, -1.0, 1.0))
    assert (directions != 0).all()


def test_point_order_is_numpys_morton_order():
    """The compiled order: the stable argsort of the 30-bit Morton codes of the points' cells in their
    box (1023 cells' widths per axis), as numpy computes them."""
    rng = np.random.default_rng(6)
    points = np.vstack([rng.uniform(-3, 5, (5000, 3)), np.zeros((50, 3))])
    lo, hi = points.min(axis=0), points.max(axis=0)
    cells = np.minimum((points - lo) * (1023.0 / (hi - lo)), 1023.0).astype(np.uint64)
    code = np.zeros(len(points), np.uint64)
    for axis in range(3):
        for bit in range(10):
            code |= ((cells[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    assert np.array_equal(coherent_order(points), np.argsort(code, kind="stable"))
    flat = np.ones((20, 3))  # a box of no extent: the order given
    assert np.array_equal(coherent_order(flat), np.arange(20))
