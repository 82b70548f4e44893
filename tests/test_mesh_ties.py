"""Exact ties on meshes: one winner whatever the order of the visit, and a lane's bits its own.

Rays that pass exactly through a shared vertex or along a shared edge hit two or more triangles of
one mesh at the same s (the watertight test's edge functions of exactly 0, its exact fallback).
PYCLRAY_CONSIDER (kernels/nearest.h) gives such a tie to the lower id, then to the lower key (the
triangle's index): the BVH's order of the visit and the tile lists' (increasing index) then give the
same depth, normal, id, primitive and barycentric images, bit for bit. And the exact fallback
(kernels/mesh.cl: mesh_edges_of) recomputes only the lanes whose edge function rounded to 0, so that
a pixel's bits do not depend on the other rays of its packet: every lane width gives the same images.
"""
from __future__ import annotations

import numpy as np
import pytest

import pyclray
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.model.shapes.mesh_shapes import grid, torus
from test_packets import at_width

AOVS = ("depth", "normal", "id", "primitive", "barycentric")


def same_bits(a, b, what):
    for name in AOVS:
        x, y = np.asarray(a[name]), np.asarray(b[name])
        differ = (x.view(np.uint8).reshape(x.shape[0], x.shape[1], -1) != y.view(np.uint8).reshape(x.shape[0], x.shape[1], -1)).any(-1)
        assert not differ.any(), f"{what}: {name} differs in {int(differ.sum())} pixels"


def kernel_ray(struct, i: int, j: int) -> np.ndarray:
    """Pixel (i, j)'s float32 ray direction in the eye's frame, the render kernel's operations in its
    order (kernels/camera.h: camera_rays), from the camera struct the kernel gets."""
    f = np.float32
    sx = struct["tan_x"][0] * ((f(struct["centre_x"][0] - 1 - 2 * i) + struct["centre_x_low"][0]) / f(struct["width"][0]))
    sy = struct["tan_y"][0] * ((f(struct["centre_y"][0] - 1 - 2 * j) + struct["centre_y_low"][0]) / f(struct["height"][0]))
    length = np.sqrt((sx * sx + sy * sy) + f(1))
    return np.array([sx / length, sy / length, f(1) / length], np.float32)


def fans_scene():
    """Fans of six triangles around a vertex placed exactly on a pixel's float32 ray (4 times its
    direction: the sheared vertex is exactly 0, so every edge function through it is exactly 0): the
    ray hits the fan's six triangles at the same s; the lowest index must win."""
    size = (32, 24)
    camera = pyclray.Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), fov=50.0)
    assert np.array_equal(camera.basis(), [[-1, 0, 0], [0, 1, 0], [0, 0, -1]])  # frame -> world: x, z negated (exact)
    struct = camera.pack(*size, "fp32")
    vertices, faces = [], []
    for i, j in [(3, 4), (10, 7), (17, 12), (25, 20), (30, 2), (8, 19), (21, 5), (14, 15)]:
        centre = 4.0 * kernel_ray(struct, i, j).astype(np.float64)
        ring = [centre + 0.03 * np.array([np.cos(a), np.sin(a), 0.0]) for a in np.linspace(0, 2 * np.pi, 7)[:-1]]
        first = len(vertices)
        vertices += [centre, *ring]
        faces += [[first, first + 1 + (k + 3) % 6, first + 1 + (k + 4) % 6] for k in range(6)]  # not in ring order
    world = np.array(vertices) * np.array([-1.0, 1.0, -1.0])
    return pyclray.Scene(camera, pyclray.Image(*size), (pyclray.Mesh(world, np.array(faces), name="fans"),))


def grid_scene(size):
    """A grid facing the camera head on: rays along its shared edges and through its shared vertices."""
    v, f = grid(8, 8, size=4.0)
    mesh = pyclray.Mesh(v[:, [0, 2, 1]], f[::-1], name="grid")  # the xy plane; faces reversed: index order != visit order
    return pyclray.Scene(pyclray.Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov=60.0), pyclray.Image(*size), (mesh,))


def doubled_scene():
    """The same triangles twice within one mesh (exact ties of one id) and in a second mesh (the lower id wins)."""
    v, f = torus(24, 12)
    shapes = (pyclray.Mesh(v, np.concatenate([f[::-1], f]), name="doubled"), pyclray.Mesh(v, f, name="copy"))
    return pyclray.Scene(pyclray.Camera((0.2, 2.5, 3.0), (0.0, 0.0, 0.0), fov=55.0), pyclray.Image(48, 40), shapes)


SCENES = {"fans": fans_scene, "grid 33x17": lambda: grid_scene((33, 17)), "grid 41x41": lambda: grid_scene((41, 41)),
          "doubled torus": doubled_scene}


@pytest.mark.parametrize("name", SCENES)
def test_exact_ties_have_one_winner_whatever_the_visit_and_the_lane_width(monkeypatch, name):
    if not has_fp64(context_for(None).device):
        pytest.skip("device lacks cl_khr_fp64: the exact fallback is not compiled without it")
    scene = SCENES[name]()
    bvh = pyclray.render(scene, aovs=AOVS, acceleration="bvh")
    same_bits(bvh, pyclray.render(scene, aovs=AOVS, acceleration="tiles"), f"{name}, bvh vs tiles")
    for lanes in (1, 4):
        other = at_width(monkeypatch, lanes, lambda: pyclray.render(scene, aovs=AOVS, acceleration="bvh"))
        same_bits(bvh, other, f"{name}, 8 lanes vs {lanes}")
    assert (bvh["primitive"] >= 0).sum() >= 8
    if name == "doubled torus":  # the copy (id 1) loses every tie to the doubled mesh (id 0)
        assert set(np.unique(bvh["id"])) == {-1, 0}
