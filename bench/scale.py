"""Scenes of many spheres for the scaling benchmarks (bench/open3d_compare.py), and their Open3D
counterparts (spheres tessellated into triangles, as Open3D's users must).

Spheres: N random centres in the box x, z in [-10, 10], y in [0, 4] above a ground plane y = 0,
radius 0.5 (1000 / N)^(1/3): the spheres fill the same fraction of the box at every N, so an image
of the box shows a similar mix of ground and spheres from 1,000 to 1,000,000 of them.
"""
from __future__ import annotations

import numpy as np

import pyclray

SIDE = 10.0
HEIGHT = 4.0
SPHERE_RESOLUTION = 6  # Open3D's create_sphere(resolution=6): 120 triangles per sphere
EYE = (0.0, 9.0, 24.0)
TARGET = (0.0, 1.0, 0.0)
FOV = 50.0


def sphere_field(count: int, seed: int = 0):
    """(centres (N, 3), radii (N,)) of the benchmark's spheres."""
    rng = np.random.default_rng(seed)
    centres = np.column_stack([
        rng.uniform(-SIDE, SIDE, count), rng.uniform(0.0, HEIGHT, count), rng.uniform(-SIDE, SIDE, count)
    ])
    radii = np.full(count, 0.5 * (1000.0 / count) ** (1.0 / 3.0))
    return centres, radii


def scene(count: int, size: int = 512, ground: bool = True, seed: int = 0) -> pyclray.Scene:
    centres, radii = sphere_field(count, seed)
    shapes = [pyclray.Plane((0.0, 1.0, 0.0), 0.0)] if ground else []
    shapes += [pyclray.Sphere(tuple(c), float(r)) for c, r in zip(centres.tolist(), radii.tolist())]
    return pyclray.Scene(pyclray.Camera(EYE, TARGET, fov=FOV), pyclray.Image(size, size), tuple(shapes))


def random_rays(count: int, seed: int = 1):
    """Rays from random points of the spheres' box in random directions (float64)."""
    rng = np.random.default_rng(seed)
    origins = np.column_stack([
        rng.uniform(-SIDE, SIDE, count), rng.uniform(0.0, HEIGHT, count), rng.uniform(-SIDE, SIDE, count)
    ])
    directions = rng.normal(size=(count, 3))
    return origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)


def open3d_scene(count: int, ground: bool = True, seed: int = 0):
    """(RaycastingScene, triangle count): the same spheres as meshes (and the ground as a large
    quad), in one mesh."""
    import open3d as o3d

    template = o3d.geometry.TriangleMesh.create_sphere(1.0, resolution=SPHERE_RESOLUTION)
    unit_vertices = np.asarray(template.vertices)
    unit_triangles = np.asarray(template.triangles)
    centres, radii = sphere_field(count, seed)
    vertices = (unit_vertices[None] * radii[:, None, None] + centres[:, None]).reshape(-1, 3)
    triangles = (unit_triangles[None] + (np.arange(count) * len(unit_vertices))[:, None, None]).reshape(-1, 3)
    if ground:
        big = 1e4
        quad = np.array([[-big, 0, -big], [big, 0, -big], [big, 0, big], [-big, 0, big]])
        base = len(vertices)
        vertices = np.concatenate([vertices, quad])
        triangles = np.concatenate([triangles, base + np.array([[0, 2, 1], [0, 3, 2]])])
    raycasting = o3d.t.geometry.RaycastingScene()
    raycasting.add_triangles(
        o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(triangles.astype(np.uint32))
    )
    return raycasting, len(triangles)


def open3d_camera_rays(size: int = 512):
    """Open3D's pinhole rays of the same camera (unnormalized: its t_hit is then z-depth)."""
    import open3d as o3d

    return o3d.t.geometry.RaycastingScene.create_rays_pinhole(
        fov_deg=FOV, center=list(TARGET), eye=list(EYE), up=[0.0, 1.0, 0.0], width_px=size, height_px=size
    )


def sphere_boxes(count: int, clustered: bool = False, seed: int = 0) -> np.ndarray:
    """The boxes of the sphere field above (uniform in its box), or clustered: half the spheres in
    eight Gaussian blobs of the box's size / 40, half uniform, radii over two decades."""
    centres, radii = sphere_field(count, seed)
    if clustered:
        rng = np.random.default_rng(seed + 1)
        blobs = rng.uniform((-SIDE, 0, -SIDE), (SIDE, HEIGHT, SIDE), (8, 3))
        near = rng.uniform(size=count) < 0.5
        centres[near] = blobs[rng.integers(0, 8, int(near.sum()))] + rng.normal(scale=SIDE / 40, size=(int(near.sum()), 3))
        radii = radii * 10 ** rng.uniform(-1, 1, count)
    return np.stack([centres - radii[:, None], centres + radii[:, None]], axis=1)
