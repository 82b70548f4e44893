"""Shadow rays that neither acne nor leak (kernels/shading.h): skip-self where the winner cannot meet
its own shadow ray (flat primitives, convex ones left on their outer side), the offset K eps |p| along
the facing normal elsewhere, never one that grows with the shape's size. Each scene is rendered
shaded and compared with the float64 model (tests/test_shading.py's compare_shaded: the shading's
error bound from the error model on every judged pixel, shadow edges within 4 times the shadow ray's
reach of p set apart), and must hold both lit and shadowed pixels, so that a leak (an occluder jumped)
or acne (a surface shadowing itself) fails it."""
import numpy as np
import pytest

import pyclray

from pyclray.reference import shading

from test_shading import ball, compare_shaded, ground, lit_scene


def on_ground_sphere(radius):
    """A ground sphere of this radius (its top at y = 0) under a point light, with a ball resting on
    it and a small ball of radius 0.05 beside it: at radius 1e6 the old offset, 16 eps (|p| + R), was
    about a unit and jumped both (806 of 320x240 pixels wrong, issue 25)."""
    shapes = (ball((0.0, -radius, 0.0), radius), ball((0.0, 0.5, 0.0), 0.5), ball((0.9, 0.05, 0.6), 0.05))
    lights = ({"type": "point", "position": [1.5, 5.0, 1.0], "intensity": 30.0},)
    return shapes, lights, ((0.0, 1.6, 3.5), (0.2, 0.2, 0.0))


@pytest.mark.parametrize("radius", [1e4, 1e6, 1e8])
def test_huge_ground_spheres_keep_their_contact_shadows(radius):
    shapes, lights, camera = on_ground_sphere(radius)
    result = compare_shaded(lit_scene(shapes, lights, camera, size=96))
    assert result["lit"] > 2000 and result["shadowed"] > 150, {k: v for k, v in result.items() if k not in ("frame", "ref")}


def test_the_small_ball_casts_its_shadow_on_a_ground_of_radius_1e8():
    """The pixels around the small ball's contact point are in its shadow in the float64 model and in
    the render alike (an offset of a unit would have lit them all)."""
    shapes, lights, camera = on_ground_sphere(1e8)
    scene = lit_scene(shapes, lights, camera, size=96)
    result = compare_shaded(scene)
    ref = result["ref"]
    shadowed_ground = (ref["id"] == 0) & (ref["visibility"][0] == 0)
    assert shadowed_ground.sum() > 100
    assert (result["frame"]["shaded"][shadowed_ground].max(axis=-1) == 0).mean() > 0.95


def test_moved_1e5_huge_ground():
    shapes, lights, camera = on_ground_sphere(1e6)
    result = compare_shaded(lit_scene(shapes, lights, camera, size=80, shift=(1e5, 5e4, -1e5)))
    assert result["lit"] > 1000 and result["shadowed"] > 200


def test_light_inside_a_sphere_lights_its_inner_wall_but_the_shadow():
    """Camera, point light and a ball inside a sphere of radius 20: its inner side is lit (the offset
    path: a ray leaving a convex shape's inner side may meet its far wall, so it is not skipped), and
    the ball's shadow falls on it."""
    shapes = (ball((0.0, 0.0, 0.0), 20.0), ball((0.0, -3.0, -8.0), 2.0))
    lights = ({"type": "point", "position": [0.0, 6.0, 0.0], "intensity": 400.0},)
    result = compare_shaded(lit_scene(shapes, lights, ((0.0, 2.0, 12.0), (0.0, -6.0, -10.0)), size=96))
    assert result["lit"] > 3000 and result["shadowed"] > 200


def test_light_inside_a_box_room():
    """The inner faces of a box (convex, seen from inside), a light and a ball inside."""
    shapes = ({"type": "box", "center": [0.0, 2.0, 0.0], "size": [10.0, 4.0, 10.0]}, ball((0.5, 0.8, -1.0), 0.8))
    lights = ({"type": "point", "position": [-1.0, 3.5, 1.0], "intensity": 40.0},)
    result = compare_shaded(lit_scene(shapes, lights, ((0.0, 2.5, 4.5), (0.0, 0.5, -3.0)), size=96))
    assert result["lit"] > 3000 and result["shadowed"] > 200


@pytest.mark.parametrize("radius", [1e4, 1e8])
def test_a_light_below_a_huge_ground_leaves_everything_above_dark(radius):
    """A light behind the ground (below it): the balls' undersides face it but the ground sphere is in
    the way, tested from points next to it, with a radius of 1e4 or 1e8 (no leak); the directional
    fill from above lights their tops."""
    shapes, _, camera = on_ground_sphere(radius)
    lights = ({"type": "point", "position": [0.5, -2.0, 0.5], "intensity": 30.0},
              {"type": "directional", "direction": [0.2, -1.0, -0.3], "irradiance": 1.0})
    result = compare_shaded(lit_scene(shapes, lights, camera, size=80))
    ref = result["ref"]
    # ball pixels facing the point light below, which the ground hides from them (judged agreeing above)
    L = np.array(lights[0]["position"]) - ref["points"]
    facing = np.einsum("...k,...k", shading.facing_normals(ref["normal"], ref["directions"]), L) > 0
    hidden = (ref["id"] >= 1) & facing & (ref["visibility"][0] == 0)
    assert hidden.sum() > 50 and result["lit"] > 1000


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("case", ["ground 1e8", "moved 1e5", "inside", "below"])
def test_point_light_shadows_through_the_bvh_equal_the_tested_every_shape(case, precision):
    """Through the BVH a point light's shadow packet is box-tested from the light (kernels/shading.h,
    shadow_light_packet: one origin for all lanes), its shapes still from each lane's own origin: the
    box tests must drop no occluder that the shape tests would find, also on huge grounds, far from
    the origin, from inside a sphere and from below the ground, so the image equals the one that
    tests every shape bit for bit."""
    shapes, lights, camera = on_ground_sphere(1e8)
    shift = (0.0, 0.0, 0.0)
    if case == "moved 1e5":
        shapes, lights, camera = on_ground_sphere(1e6)
        shift = (1e5, 5e4, -1e5)
    elif case == "inside":
        shapes = (ball((0.0, 0.0, 0.0), 20.0), ball((0.0, -3.0, -8.0), 2.0))
        lights = ({"type": "point", "position": [0.0, 6.0, 0.0], "intensity": 400.0},)
        camera = ((0.0, 2.0, 12.0), (0.0, -6.0, -10.0))
    elif case == "below":
        lights = ({"type": "point", "position": [0.5, -2.0, 0.5], "intensity": 30.0},)
    scene = lit_scene(shapes, lights, camera, size=64, shift=shift)
    tiles = pyclray.render(scene, aovs=("shaded",), acceleration="tiles", precision=precision)["shaded"]
    through_bvh = pyclray.render(scene, aovs=("shaded",), acceleration="bvh", precision=precision)["shaded"]
    np.testing.assert_array_equal(tiles, through_bvh)
    dark = (tiles == 0).all(axis=-1).mean()
    # shadowed and lit pixels both; below the ground, all dark (the ground hides the light from all)
    assert dark == 1.0 if case == "below" else 0.02 < dark < 0.98


@pytest.mark.parametrize("position, intensity", [((0.0, 1.5, -6.0), 20.0), ((3e3, 8e3, 2e3), 8e7)])
def test_a_light_among_many_spheres_or_far_through_the_bvh(position, intensity):
    """The light packet's box tests start at the light: inside the field's boxes (entries clamped to
    0 there) or 1e4 away (its margin grows with |light|), the BVH drops no occluder: equal to the
    image that tests every shape, with shadows in it."""
    rng = np.random.default_rng(11)
    shapes = [ground()]
    shapes += [ball(rng.uniform([-6, 0.2, -12], [6, 3, 0]), float(rng.uniform(0.1, 0.6))) for _ in range(300)]
    lights = ({"type": "point", "position": list(position), "intensity": intensity},)
    scene = lit_scene(shapes, lights, ((0, 4, 6), (0, 1, -5)), size=64)
    tiles = pyclray.render(scene, aovs=("shaded",), acceleration="tiles")["shaded"]
    through_bvh = pyclray.render(scene, aovs=("shaded",), acceleration="bvh")["shaded"]
    np.testing.assert_array_equal(tiles, through_bvh)
    assert 0.05 < (tiles == 0).all(axis=-1).mean() < 0.95
