"""Framed renders (pyclray.engine.scene.prepared.FROM_WORLD_FROM, Shape.tested_from_world): a large scene on a
device with float64 holds its spheres' float64 world entries only, and the render kernel frames each
sphere on the eye where it tests it, with the per-view pass's own function (kernels/space.h, the
shapes' <type>_rebase) compiled as the pass is. Its images must be the per-view copy's, bit for bit,
whatever the offset, precision, acceleration or view history: the copy's images are held to the
float64 oracle by the rest of the suite (test_render.py, test_shapes.py, test_views.py), so this
holds the from_world path to the same exactness. FROM_WORLD_FROM is set to 0 (frame every scene) or out of
reach (copy every scene) to compare the two on small scenes. Meshes are indexed (shared vertices and
faces, engine/scene/indexed.py) on every device with float64, from-world scene or not: prepared.INDEXED False
gives them the per-view copy (devices without float64) to compare with."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import pyclray
from pyclray.engine import api
from pyclray.engine.scene import prepared
from pyclray.engine.opencl.device import context_for

from test_views import ALL, every_shape, fresh, moving_spheres, need, same


def rendered(monkeypatch, from_world: bool, scene, indexed: bool | None = None, **options):
    """The scene's render from a freshly prepared scene, from_world or copied (its meshes indexed or
    copied: as from_world unless said)."""
    indexed = from_world if indexed is None else indexed
    monkeypatch.setattr(prepared, "FROM_WORLD_FROM", 0 if from_world else 10**12)
    monkeypatch.setattr(prepared, "INDEXED", indexed)
    image = fresh(scene, **options)
    kinds = api.tracer_for(scene, context_for(None), options.get("precision", "fp32")).prepared.kinds
    assert kinds["spheres"].from_world == from_world and (kinds["mesh"].indexed is not None) == indexed  # what this compares
    return image


@pytest.mark.parametrize("acceleration", ["tiles", "bvh"])
@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("offset", [0.0, 1e5, 1e8])
def test_a_framed_render_is_the_copied_render_bit_for_bit(monkeypatch, precision, offset, acceleration):
    """Every shape type (spheres from_world, the others copied), lit with shadows, every image, near the
    origin and 1e5 and 1e8 away (camera and lights moved with the shapes)."""
    need(precision)
    scene = every_shape((offset, 0.3 * offset, -offset))
    copied = rendered(monkeypatch, False, scene, aovs=ALL, precision=precision, acceleration=acceleration)
    same(rendered(monkeypatch, True, scene, aovs=ALL, precision=precision, acceleration=acceleration), copied)


@pytest.mark.parametrize("acceleration", ["tiles", "bvh"])
@pytest.mark.parametrize("offset", [0.0, 1e8])
def test_indexed_meshes_beside_copied_shapes_are_the_copied_render_bit_for_bit(monkeypatch, offset, acceleration):
    """A scene too small to be from_world keeps its spheres' per-view copy, and its meshes are still
    indexed (a program with INDEXED and without FRAMED: the mesh functions read private triangles,
    the other shapes their buffers, the winner's normal computed without contraction): the images
    of the copy, every image, lit with shadows, near the origin and 1e8 away."""
    scene = every_shape((offset, 0.3 * offset, -offset))
    copied = rendered(monkeypatch, False, scene, aovs=ALL, acceleration=acceleration)
    same(rendered(monkeypatch, False, scene, indexed=True, aovs=ALL, acceleration=acceleration), copied)


def test_framed_views_after_other_views_are_the_fresh_views(monkeypatch):
    """A from-world scene seen from one camera, then another far off, then the first: each view is the
    fresh scene's (no per-view state left behind)."""
    monkeypatch.setattr(prepared, "FROM_WORLD_FROM", 0)
    scene = every_shape()
    other = dataclasses.replace(scene.camera, eye=(40.0, 30.0, -25.0))
    expected = {camera: fresh(dataclasses.replace(scene, camera=camera), aovs=ALL) for camera in (scene.camera, other)}
    pyclray.clear_cache()
    for camera in (scene.camera, other, scene.camera):
        same(pyclray.render(scene, aovs=ALL, camera=camera), expected[camera])


@pytest.mark.parametrize("refit_max", [1.5, 0.0])  # refit in place; every frame rebuilt
def test_framed_animation_frames_equal_fresh_frames(monkeypatch, refit_max):
    """An animation's frames update a from-world scene's world entries in place (no view buffer to
    bring to the view) and equal the frames' scenes prepared from nothing."""
    monkeypatch.setattr(prepared, "FROM_WORLD_FROM", 0)
    monkeypatch.setattr(prepared.PreparedScene, "REFIT_COST_MAX", refit_max)
    scene = moving_spheres(400, orbit=True)
    pyclray.clear_cache()
    frames = [frame for _, frame in pyclray.render_animation(scene, aovs=ALL)]
    kept = [t.prepared for t in api._tracers.values() if t.prepared.base is scene.shapes]
    assert len(kept) == 1 and kept[0].kinds["sphere"].from_world
    for k, frame in enumerate(frames):
        at = scene.at(scene.animation.frame_time(k))
        same(frame, fresh(pyclray.Scene(at.camera, scene.image, at.shapes), aovs=ALL))


def test_a_framed_sphere_field_holds_at_most_64_bytes_a_sphere(monkeypatch):
    """Issue 22's memory target, counted as PreparedScene.nbytes counts (every buffer the prepared
    scene holds: world entries, ids and primitive indices, BVH nodes, materials; no refs for one
    bounded type): a ground plane and 50,000 spheres of bench/views.py's field (1,000,000 of them:
    63.7 bytes each, python -m bench.views)."""
    from bench import scale

    monkeypatch.setattr(prepared, "FROM_WORLD_FROM", 0)
    centres, radii = scale.sphere_field(50_000)
    scene = pyclray.Scene(pyclray.Camera(scale.EYE, scale.TARGET, fov=scale.FOV), pyclray.Image(32, 32),
                          (pyclray.Plane((0.0, 1.0, 0.0), 0.0), pyclray.Spheres(centres, radii)))
    pyclray.clear_cache()
    pyclray.render(scene, aovs=("depth",))
    held = api.tracer_for(scene, context_for(None), "fp32").prepared.nbytes()
    assert held / 50_000 <= 64


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_cast_through_a_framed_scene_is_casts_through_a_copied_one(monkeypatch, precision):
    """cast reads the world entries (an indexed mesh's packed anew from its shapes when cast asks):
    the same hits from a from-world scene as from a copied one, rays from inside the shapes and far off."""
    need(precision)
    scene = every_shape((1e5, 0.0, 0.0))
    rng = np.random.default_rng(5)
    origins = np.array(scene.camera.eye) + rng.normal(0.0, 3.0, (500, 3))
    directions = rng.normal(size=(500, 3))
    results = []
    for from_world in (False, True):
        monkeypatch.setattr(prepared, "FROM_WORLD_FROM", 0 if from_world else 10**12)
        monkeypatch.setattr(prepared, "INDEXED", from_world)
        pyclray.clear_cache()
        results.append(pyclray.cast(scene, origins, directions, precision=precision))
        assert (api.tracer_for(scene, context_for(None), precision).prepared.kinds["mesh"].indexed is not None) == from_world
    same(*results)
    assert np.isfinite(results[0]["depth"]).sum() > 100  # rays that hit: what this compares


@pytest.mark.parametrize("path", ["from_world", "copied"])
@pytest.mark.parametrize("check", ["embree_watertight", "zero_area", "far_fp32", "far_fp64", "smooth", "smooth_flat"])
def test_the_mesh_tests_hold_for_framed_and_copied_meshes(monkeypatch, check, path):
    """tests/test_mesh.py's watertightness (Embree's sphere and far grid: every ray from inside hits),
    zero-area triangles (never hit, no NaN), oracle tests at 3e7 from the origin, and
    tests/test_mesh_smooth.py's smooth shading (which run on indexed meshes: their triangles assembled
    from shared vertices and faces, their shading normals per vertex, engine/scene/indexed.py), run on
    from_world scenes (indexed meshes beside from_world shapes) and on the per-view copy of each triangle
    (prepared.INDEXED False: the path of devices without float64)."""
    import test_mesh
    import test_mesh_smooth

    if path == "from_world":
        monkeypatch.setattr(prepared, "FROM_WORLD_FROM", 0)
    else:
        monkeypatch.setattr(prepared, "INDEXED", False)
    pyclray.clear_cache()
    if check == "embree_watertight":
        test_mesh.test_embree_watertight_sphere_and_far_grid()
    elif check == "zero_area":
        test_mesh.test_zero_area_triangles_are_never_hit()
    elif check == "smooth":  # vertex normals per shared vertex, interpolated as the float64 model says
        test_mesh_smooth.test_smooth_shading_matches_the_float64_model()
    elif check == "smooth_flat":
        test_mesh_smooth.test_geometric_images_and_the_ground_stay_as_flat()
    else:
        test_mesh.test_render_agrees_with_the_oracle_far_from_the_origin(check[4:], 3e7)
    kept = [t.prepared for t in api._tracers.values() if "mesh" in t.prepared.kinds]
    assert kept and all((p.kinds["mesh"].indexed is not None) == (path == "from_world") for p in kept)  # what this tests
    assert path == "copied" or any(p.from_world for p in kept)
    pyclray.clear_cache()
