"""The closest-point queries (distance, signed_distance, occupancy, closest_points:
engine/queries/closest.py) on a device of the GPU class, forced on PoCL by $PYCLRAY_GPU_CLASS=1: no
per-point pass of numba on the host (the points' Morton order, the parity rays' nearest faces, the
parity grid's lookup) and the parity rays checked and counted through count_hits' device path
(engine/queries/cast_device.py: HitRays). Each point is computed on its own, the parity rays'
directions are the same (numpy's first nearest face is numba's), and a point of the grid's empty
cells counts its own ray as the grid answers (tests/test_occupancy_grid.py): so every result is the
CPU host path's bits, on the same handle, for large batches (>= COHERENT_FROM: the CPU's passes)
and small ones."""
import numpy as np
import pytest

import pyclray
from pyclray.engine.queries import cast as cast_module
from pyclray.engine.queries import hits as hits_module
from pyclray.engine.queries import parity_grid, point_passes, ray_order
from pyclray.engine.queries.closest import COHERENT_FROM
from pyclray.model.shapes.mesh_shapes import perturbed_sphere, torus

from test_cast_device import same


def scene_of(*shapes):
    return pyclray.Scene(pyclray.Camera((0, 0, 6), (0, 0, 0)), pyclray.Image(8, 8), shapes)


def one_closed():
    v, f = perturbed_sphere(16, 24, 1.0, 0.2, np.random.default_rng(5))
    return scene_of(pyclray.Mesh(v, f, name="blob"))


def mixed():
    """Two closed meshes that overlap (each one's own parity: all_hits' ids), an open one (the
    winding rule's hierarchical sum) and a sphere (an analytic solid)."""
    v, f = perturbed_sphere(12, 18, 1.0, 0.2, np.random.default_rng(6))
    tv, tf = torus(24, 12, 1.0, 0.35)
    keep = f[: len(f) // 2]  # half a sphere: open
    return scene_of(pyclray.Mesh(v, f, name="blob"), pyclray.Mesh(tv, tf, translate=(0.3, 0.1, 0.0), name="ring"),
                    pyclray.Mesh(v * 0.5, keep, translate=(0.0, 1.5, 0.0), name="cap"),
                    pyclray.Sphere((1.4, -1.0, 0.2), 0.3))


def points(count, seed):
    return np.random.default_rng(seed).uniform(-1.4, 1.4, (count, 3))


def queries(handle, p):
    out = {"distance": handle.distance(p)}
    for sign in ("parity", "winding"):
        out[f"signed {sign}"] = handle.signed_distance(p, sign)
        out[f"occupancy {sign}"] = handle.occupancy(p, sign)
    out.update({f"closest {k}": v for k, v in handle.closest_points(p).items()})
    return out


@pytest.mark.parametrize("make", [one_closed, mixed])
@pytest.mark.parametrize("count", [50, COHERENT_FROM + 1000])
def test_the_gpu_class_gives_the_host_paths_bits(monkeypatch, make, count):
    p = points(count, count)
    with pyclray.prepare(make()) as handle:
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
        expected = queries(handle, p)
    with pyclray.prepare(make()) as handle:  # (a handle of its own: the CPU's parity grid is kept on one)
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", "1")
        got = queries(handle, p)
    assert set(got) == set(expected)
    for name in expected:
        same(got[name], expected[name])
    occupied = expected["occupancy parity"]
    assert 0 < occupied.sum() < count  # inside and outside both


def test_no_per_point_host_pass_on_the_gpu_class(monkeypatch):
    """The numba passes over the points and rays (point_passes, the parity grid's lookup, cast's
    ray checks and order) and the host path's ray batch are made to raise: the queries of a large
    batch still give the CPU's bits on the GPU class."""
    def forbidden(*args, **kwargs):
        raise AssertionError("per-point host work on the GPU class")

    p = points(COHERENT_FROM + 500, 7)
    for make in (one_closed, mixed):
        with pyclray.prepare(make()) as handle:
            monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
            expected = queries(handle, p)
        with monkeypatch.context() as patch:
            for module, name in [(point_passes, "coherent_order"), (point_passes, "nearest_face_directions"),
                                 (parity_grid, "_lookup"), (ray_order, "scan_codes"), (ray_order, "coherent_order"),
                                 (cast_module, "_cast_rays"), (hits_module, "RayBatch")]:
                patch.setattr(module, name, forbidden)
            patch.setenv("PYCLRAY_GPU_CLASS", "1")
            with pyclray.prepare(make()) as handle:
                got = queries(handle, p)
        for name in expected:
            same(got[name], expected[name])


def test_a_far_point_raises_the_host_paths_line(monkeypatch):
    """A point too far from the shapes for the parity ray's float32 distances: the same one line
    (the host path's, naming the row; its argument is the parity rays' origins)."""
    p = points(10, 8)
    p[4] = (1e30, 0.0, 0.0)
    errors = []
    with pyclray.prepare(one_closed()) as handle:
        for switch in ("0", "1"):
            monkeypatch.setenv("PYCLRAY_GPU_CLASS", switch)
            try:
                result = handle.occupancy(p)
            except pyclray.RequestError as error:
                errors.append(str(error))
            else:
                errors.append(result.tolist())
    assert errors[0] == errors[1] and isinstance(errors[0], str) and "row 4" in errors[0]


def test_the_parity_rays_directions_are_numbas(monkeypatch):
    """The parity rays' directions of a large batch on the GPU class (numpy's passes over the columns)
    are numba's (point_passes.nearest_face_directions): the first nearest face, ties included (points
    at the box's centre and on its diagonals, equally near two or more faces)."""
    from pyclray.engine.queries.closest import parity_directions

    p = points(COHERENT_FROM + 100, 9)
    with pyclray.prepare(one_closed()) as handle:
        closed = handle.mesh_handle(closed=True)
        tree = closed.prepared.bvh.tree
        centre = 0.5 * (tree.lo[0] + tree.hi[0])
        p[:3] = centre
        p[3:10] = centre + np.linspace(-0.5, 0.5, 7)[:, None] * (tree.hi[0] - tree.lo[0])  # the diagonal
        p[10] = tree.lo[0]
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", "0")
        expected = parity_directions(closed, p)
        monkeypatch.setenv("PYCLRAY_GPU_CLASS", "1")
        got = parity_directions(closed, p)
    same(got, expected)
    assert len(np.unique(expected, axis=0)) == 6
