"""Smooth meshes (smooth = true): the shaded image lit by vertex normals interpolated at the hit's
barycentrics (the file's or given ones, else area-weighted), against the float64 model and Mitsuba;
depth, normal and id stay geometric, the shadow rays start on the geometric surface, and the code is
compiled in only with a smooth mesh and the shaded image.

Tolerances: the error model's (tests/test_shading.py's compare_shaded: pyclray.reference.shading.tolerance
of the bounds on the hit point and normal; a smooth mesh's radius is half its smallest altitude, since
a hit moved by e along a triangle turns the interpolated normal by up to 2 e / altitude)."""
from dataclasses import replace

import numpy as np
import pytest

import pyclray
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.engine.api import tracer_for
from pyclray.engine.launch.programs import Variant
from pyclray.model.lights import DirectionalLight, PointLight, Shading
from pyclray.model.shapes.mesh_shapes import grid, perturbed_sphere

from test_shading import compare_shaded


def lit_scene(mesh, shadows=True):
    """The mesh above a plane under a point light (shadows on the plane and on the mesh itself)."""
    ground = pyclray.Plane((0, 1, 0), 1.3)  # y = -1.3
    light = PointLight(position=(3.0, 4.0, 3.0), intensity=(20.0, 20.0, 20.0))
    return pyclray.Scene(pyclray.Camera((0.5, 1.5, 5), (0, 0, 0)), pyclray.Image(80, 60), (ground, mesh),
                         lights=(light,), shading=Shading(shadows=shadows))


def bumpy(smooth=True, **keys):
    vertices, faces = perturbed_sphere(12, 16, 1.0, 0.08, np.random.default_rng(7))
    return pyclray.Mesh(vertices, faces, smooth=smooth, axis=(1, 2, 0), angle=30.0, **keys)


def test_smooth_shading_matches_the_float64_model():
    """Area-weighted vertex normals interpolated by the kernel agree with the float64 model (the
    mesh's shading and its shadow on the plane) on every judged pixel; and the smooth image really
    is another one than the flat (a kernel that ignored smooth would fail here)."""
    scene = lit_scene(bumpy())
    counts = compare_shaded(scene)
    assert counts["lit"] > 1500 and counts["shadowed"] > 100, counts
    flat = pyclray.render(lit_scene(bumpy(smooth=False)), aovs=("shaded",))["shaded"]
    on_mesh = counts["ref"]["id"] == 1
    assert (np.abs(counts["frame"]["shaded"] - flat).max(axis=-1)[on_mesh] > 1e-3).mean() > 0.5


def test_geometric_images_and_the_ground_stay_as_flat():
    """depth, normal, id and primitive are the geometric ones bit for bit; the plane's shaded pixels
    (lit, and in the mesh's shadow: shadow rays from the ground meet the same triangles) too."""
    aovs = ("depth", "normal", "id", "primitive", "shaded")
    smooth = pyclray.render(lit_scene(bumpy()), aovs=aovs)
    flat = pyclray.render(lit_scene(bumpy(smooth=False)), aovs=aovs)
    for name in aovs[:4]:
        assert np.array_equal(smooth[name], flat[name]), name
    ground = smooth["id"] == 0
    assert ground.sum() > 1000 and np.array_equal(smooth["shaded"][ground], flat["shaded"][ground])


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_given_normals_light_the_mesh(precision):
    """A grid facing the camera with one given normal n0 at every vertex, under a directional light:
    every mesh pixel is albedo E max(0, n0.L) (the interpolation of equal unit normals is n0), which a
    geometric normal (0, 0, 1) would not give."""
    vertices, faces = grid(6, 6, 2.0)  # in the xz plane: turned about x by 90 degrees to face +z
    n0 = np.array([0.6, 0.0, 0.8])  # in the world; in the grid's own space (0.6, 0.8, 0)
    mesh = pyclray.Mesh(vertices, faces, smooth=True, normals=np.tile([0.6, 0.8, 0.0], (len(vertices), 1)),
                        axis=(1, 0, 0), angle=90.0, material=pyclray.Material((0.5, 0.5, 0.5)))
    assert np.allclose(mesh.vertex_normals(), n0)
    light = DirectionalLight(direction=(-1.0, 0.0, -1.0), irradiance=(2.0, 2.0, 2.0))
    scene = pyclray.Scene(pyclray.Camera((0, 0, 5), (0, 0, 0)), pyclray.Image(32, 24), (mesh,), lights=(light,),
                          shading=Shading(ambient=(0, 0, 0), shadows=False))
    if precision == "fp64" and not has_fp64(context_for().device):
        pytest.skip("device lacks cl_khr_fp64")
    frame = pyclray.render(scene, aovs=("id", "shaded"), precision=precision)
    expected = 0.5 * 2.0 * float(n0 @ light.toward_light())
    hit = frame["id"] == 0
    assert hit.sum() > 100
    # the interpolation, normalization and dot: a few roundings of the precision's unit
    np.testing.assert_allclose(frame["shaded"][hit], expected, rtol={"fp32": 1e-5, "fp64": 1e-12}[precision])


def test_smooth_is_compiled_in_only_with_a_smooth_mesh_and_shading():
    """PYCLRAY_SMOOTH (the normals buffer, the interpolation) only with a smooth mesh present and
    the shaded image asked for; a flat mesh's scene has no shading-normal buffer."""
    ctx = context_for()
    assert tracer_for(lit_scene(bumpy()), ctx, "fp32").prepared.smooth == ("mesh",)
    assert tracer_for(lit_scene(bumpy(smooth=False)), ctx, "fp32").prepared.smooth == ()
    shaded = Variant("render", ("plane", "mesh"), ("shaded",), "fp32", 8, smooth=("mesh",)).source()
    assert "#define PYCLRAY_SMOOTH 1" in shaded and "} TriangleNormals;" in shaded  # the struct's typedef
    depth = Variant("render", ("plane", "mesh"), ("depth",), "fp32", 8, smooth=("mesh",)).source()
    assert "#define PYCLRAY_SMOOTH 1" not in depth and "} TriangleNormals;" not in depth


def test_smooth_mesh_shaded_equals_mitsuba_direct(scenes_dir):
    """scenes/mesh.toml (a smooth bunny): Mitsuba's mi.Mesh gets the same vertex normals
    (has_vertex_normals) and its direct integrator lights with them, within both engines' bounds."""
    pytest.importorskip("mitsuba")
    from pyclray.reference.validation import shaded as shaded_check

    scene = pyclray.load_scene(scenes_dir / "mesh.toml").with_size(64, 48)
    assert scene.shapes[1].smooth
    result = shaded_check.cross_check_shaded(scene, "scalar_rgb")
    assert result.passed, shaded_check.format_shaded_check(result)
    assert result.lit > 1000, shaded_check.format_shaded_check(result)
    flat = replace(scene, shapes=tuple(replace(s, smooth=False) if s.type == "mesh" else s for s in scene.shapes))
    ours = pyclray.render(scene, aovs=("shaded", "id"))
    assert (np.abs(ours["shaded"] - pyclray.render(flat, aovs=("shaded",))["shaded"])[ours["id"] == 1] > 1e-3).any()
