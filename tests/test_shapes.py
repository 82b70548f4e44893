"""Every shape type in the registry, one test suite (in the style of pbrt-v4's shapes_test): seeded
random shapes (``Shape.random``) and random rays, some from far away and some starting inside the
solids, through pyclray.cast in fp32 and fp64. Each asserts that

- ids, depths and normals agree with the float64 oracle within the error model
  (pyclray.reference.error_model.pyclray_tolerances; silhouettes, near ties and rays within rounding of an edge
  set apart), which also makes the nearest hit the nearest;
- hits lie on the surface: the hit point's distance to it is at most the depth tolerance times
  |cos| (a move of d along the ray is a move of d |cos| off the surface), plus the float64
  rounding of the point itself;
- hits lie within the shape's world bounds (the BVH's boxes), to the same tolerance;
- normals are unit and outward as the contract says: against the ray for a ray from outside a
  solid, with it for a ray from inside (never flipped toward the viewer);
- the packed struct of every type has the device's layout (tests/test_layout.py covers this over
  the registry);
- every type implements each part of the shape interface (scene, device, reference) and each
  capability it takes, and the base interface holds no capability's member.
"""
import inspect

import numpy as np
import pytest

import pyclray
from pyclray.reference import error_model
from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.model.shapes import REGISTRY
from pyclray.model.shapes.base import SceneShape, Shape
from pyclray.model.shapes.capabilities import CAPABILITIES
from pyclray.model.shapes.device import DevicePacking
from pyclray.model.shapes.reference import ReferenceShape

from oracle_checks import assert_agrees_with_oracle

TYPES = list(REGISTRY)


def random_scene(kind: str, seed: int):
    """1 to 4 random shapes of this type and one random sphere, moved off the origin for odd seeds."""
    rng = np.random.default_rng([seed, TYPES.index(kind)])
    shift = rng.normal(size=3) * (40.0 if seed % 2 else 0.0)
    shapes = [REGISTRY[kind].random(rng, shift) for _ in range(rng.integers(1, 5))]
    shapes.append(pyclray.Sphere.random(rng, shift))
    order = rng.permutation(len(shapes))
    shapes = tuple(shapes[i] for i in order)
    scene = pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(8, 8), shapes)
    return scene, rng, shift


def aimed_rays(scene, rng, shift, count):
    """Rays from around the shapes, most aimed at a point near one of them (so that they hit)."""
    origins = rng.uniform(-6, 6, (count, 3)) + shift
    targets = rng.uniform(-3.5, 3.5, (count, 3)) + shift
    bounded = [s for s in scene.shapes if s.bounded]
    if bounded:
        spheres = [type(s).bounding_spheres([s]) for s in bounded]
        centres = np.array([c[0] for c, _ in spheres])
        radii = np.array([r[0] for _, r in spheres])
        pick = rng.integers(0, len(bounded), count)
        aimed = rng.uniform(0, 1, count) < 0.7
        targets[aimed] = centres[pick[aimed]] + rng.normal(size=(aimed.sum(), 3)) * 0.5 * radii[pick[aimed], None]
    return origins, targets - origins


def inside_rays(scene, rng, origins, directions):
    """From points just past a first hit: (origins, directions, index of the solid each starts
    inside, or -1). The point halfway to the next crossing of that shape lies inside a solid."""
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    new_origins, new_directions, inside = [], [], []
    for index, shape in enumerate(scene.shapes):
        t1 = shape.oracle_distance(origins, unit)
        hit = np.isfinite(t1)
        past = origins[hit] + (t1[hit] * (1 + 1e-7) + 1e-7)[:, None] * unit[hit]
        t2 = shape.oracle_distance(past, unit[hit])
        ok = np.isfinite(t2) & (t2 > 1e-3)
        start = past[ok] + 0.5 * t2[ok, None] * unit[hit][ok]
        new_origins.append(start)
        new_directions.append(rng.normal(size=start.shape))  # any direction from inside
        inside.append(np.full(len(start), index if shape.solid else -1))
    return np.concatenate(new_origins), np.concatenate(new_directions), np.concatenate(inside)


def far_rays(scene, rng, shift, count, origins, directions):
    """Rays from 1e4 to 1e5 away (one far point, origins spread by a unit), aimed at points where
    the near rays (origins, directions) hit, so that most of them hit too. The far point lies on
    the side the first of those points was seen from, within about 60 degrees of its normal (not
    all grazing)."""
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    distances = np.array([shape.oracle_distance(origins, unit) for shape in scene.shapes])
    t, ids = distances.min(axis=0), distances.argmin(axis=0)
    hit = np.flatnonzero(np.isfinite(t))
    chosen = hit[rng.integers(0, len(hit), count)]
    targets = origins[chosen] + t[chosen, None] * unit[chosen]
    first = chosen[0]
    normal = scene.shapes[ids[first]].oracle_normal(targets[:1])[0]
    side = -np.sign(normal @ unit[first]) * normal
    direction = side + 0.5 * rng.normal(size=3)
    far = targets[0] + direction / np.linalg.norm(direction) * 10 ** rng.uniform(4, 5)
    far_origins = far + rng.normal(size=(count, 3))
    return far_origins, targets - far_origins


def need(precision):
    if precision == "fp64" and not has_fp64(context_for().device):
        pytest.skip("device lacks cl_khr_fp64")


def check_properties(scene, origins, directions, precision, inside=None, min_judged=0.1):
    result = pyclray.cast(scene, origins, directions, precision=precision)
    truth, cos, judged, depth_tolerance = assert_agrees_with_oracle(scene, origins, directions, result, precision,
                                                                    min_judged=min_judged)
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    hit = result["id"] >= 0
    t = result["depth"].astype(np.float64)
    points = origins + np.where(hit, t, 0)[:, None] * unit
    rounding = 4 * error_model.ORACLE_EPSILON * (np.linalg.norm(origins, axis=1) + np.where(hit, t, 0))
    slack = np.where(judged, depth_tolerance * cos, np.inf) + rounding
    for index, shape in enumerate(scene.shapes):
        mine = hit & judged & (result["id"] == index)
        if not mine.any():
            continue
        # on the surface
        off = shape.surface_distance(points[mine])
        assert np.all(off <= slack[mine]), f"{shape}: a hit {off.max():.3g} off the surface"
        # within the bounds
        if shape.bounded:
            lo, hi = shape.box()
            outside = np.maximum(lo - points[mine], points[mine] - hi).max(axis=1)
            assert np.all(outside <= slack[mine]), f"{shape}: a hit {outside.max():.3g} outside its bounds"
        # outward normals: against the ray from outside a solid, with it from inside
        if shape.solid and inside is not None:
            along = np.einsum("ij,ij->i", result["normal"][mine].astype(np.float64), unit[mine])
            from_inside = inside[mine] == index
            assert np.all(along[from_inside] > 0), f"{shape}: an inward normal seen from inside"
    return result, truth, judged


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("kind", TYPES)
def test_random_rays_fp32(kind, seed):
    scene, rng, shift = random_scene(kind, seed)
    origins, directions = aimed_rays(scene, rng, shift, 1500)
    check_properties(scene, origins, directions, "fp32")
    inner_origins, inner_directions, inside = inside_rays(scene, rng, origins, directions)
    if len(inner_origins):
        check_properties(scene, inner_origins, inner_directions, "fp32", inside, min_judged=0.05)
    if any(s.bounded for s in scene.shapes):
        origins, directions = far_rays(scene, rng, shift, 500, origins, directions)
        result, truth, judged = check_properties(scene, origins, directions, "fp32", min_judged=0.05)
        # from far outside, a solid is always entered: the normal faces the ray
        unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
        along = np.einsum("ij,ij->i", result["normal"].astype(np.float64), unit)
        solid = np.array([s.solid for s in scene.shapes])[np.maximum(result["id"], 0)] & (result["id"] >= 0)
        assert np.all(along[solid & judged] < 0)


@pytest.mark.parametrize("kind", TYPES)
def test_random_rays_fp64(kind):
    need("fp64")
    scene, rng, shift = random_scene(kind, 101)
    origins, directions = aimed_rays(scene, rng, shift, 1500)
    check_properties(scene, origins, directions, "fp64")
    inner_origins, inner_directions, inside = inside_rays(scene, rng, origins, directions)
    if len(inner_origins):
        check_properties(scene, inner_origins, inner_directions, "fp64", inside, min_judged=0.05)


@pytest.mark.parametrize("kind", TYPES)
def test_the_model_catches_a_moved_shape(kind):
    """The same comparison fails when the oracle's shapes are moved by 1e-4 (a few hundred eps at
    these distances) along a random direction: the tolerance is not so loose that a real geometric
    error would pass, for any type."""
    import dataclasses

    scene, rng, shift = random_scene(kind, 0)
    origins, directions = aimed_rays(scene, rng, shift, 1500)
    result = pyclray.cast(scene, origins, directions)
    move = rng.normal(size=3)
    move *= 1e-4 / np.linalg.norm(move)

    def moved(shape):
        changes = {}
        for field in dataclasses.fields(shape):
            value = getattr(shape, field.name)
            if field.name in ("center", "p0", "p1", "translate"):
                changes[field.name] = tuple(np.add(value, move))
        if isinstance(shape, pyclray.Plane):
            changes["offset"] = shape.offset - float(np.dot(shape.normal, move))
        return dataclasses.replace(shape, **changes)

    wrong = pyclray.Scene(scene.camera, scene.image, tuple(moved(s) for s in scene.shapes))
    with pytest.raises(AssertionError, match="off by|unexplained"):
        assert_agrees_with_oracle(wrong, origins, directions, result, "fp32")


@pytest.mark.parametrize("kind", TYPES)
def test_bounds_hold_every_point_of_the_shape(kind):
    """world_bounds is (N, 2, 3), one box per primitive (a batch's spheres each), and conservative:
    the oracle's hits of many rays lie inside each shape's box; the plane has no bounds (``bounded``
    False) and stays outside the BVH."""
    cls = REGISTRY[kind]
    rng = np.random.default_rng(5)
    shapes = [cls.random(rng) for _ in range(6)]
    if not cls.bounded:
        with pytest.raises(NotImplementedError):
            cls.world_bounds(shapes)
        return
    bounds = cls.world_bounds(shapes)
    assert bounds.shape == (sum(s.primitive_count() for s in shapes), 2, 3) and bounds.dtype == np.float64
    for shape in shapes:
        lo, hi = shape.box()
        origins = rng.normal(size=(4000, 3)) * 8
        centres, radii = cls.bounding_spheres([shape])
        aim = rng.integers(len(centres), size=4000)  # each ray toward one of its primitives
        directions = centres[aim] + rng.normal(size=(4000, 3)) * 0.5 * radii[aim, None] - origins
        unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
        t = shape.oracle_distance(origins, unit)
        points = origins[np.isfinite(t)] + t[np.isfinite(t), None] * unit[np.isfinite(t)]
        assert len(points) > 100
        assert np.all(points >= lo) and np.all(points <= hi)
        # and tight: each side of the box is reached to within a few percent
        assert np.all(points.min(axis=0) <= lo + 0.1 * (hi - lo)) and np.all(points.max(axis=0) >= hi - 0.1 * (hi - lo))


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
def test_every_lane_width_gives_the_same_bits(monkeypatch, scenes_dir, precision):
    """The new shapes' select-style kernels give the same bits at every packet width (a render of
    the every-shape scene at an odd size, and a cast of rays some of which start inside solids)."""
    from test_packets import at_width, widths
    from test_speedups import same

    need(precision)
    scene = pyclray.load_scene(scenes_dir / "shapes.toml").with_size(45, 31)
    rng = np.random.default_rng(3)
    origins, directions = aimed_rays(scene, rng, 0.0, 301)
    inner, inner_directions, _ = inside_rays(scene, rng, origins, directions)
    origins, directions = np.concatenate([origins, inner]), np.concatenate([directions, inner_directions])

    def run():
        return [pyclray.render(scene, precision=precision), pyclray.cast(scene, origins, directions, precision=precision)]

    runs = {w: at_width(monkeypatch, w, run) for w in widths(precision)}
    scalar = runs.pop(1)
    for frames in runs.values():
        for a, b in zip(scalar, frames):
            same(a, b)


# -- the interface: three parts and the capabilities ---------------------------------------------
PARTS = (SceneShape, DevicePacking, ReferenceShape)
# engine/launch/programs.py reads these of every kind (base.py's Shape): they stay on the base, off, until it
# asks capabilities.capability() as the rest of the engine does
READ_BY_PROGRAMS = {"indexed", "cast_blocks", "shared"}


def required_of(cls, part) -> tuple[str, ...]:
    """What a type must define in this part: the part's required_members, and bounds_of where the
    type is bounded, from_mitsuba where it reads Mitsuba plugins."""
    extra = {DevicePacking: ("bounds_of",) if cls.bounded else (),
             SceneShape: ("from_mitsuba",) if cls.mitsuba_plugins else ()}
    return part.required_members + extra.get(part, ())


def members(mixin) -> set[str]:
    """A capability mixin's members: its methods, its switch and the attributes it only annotates."""
    return {n for n in (*vars(mixin), *inspect.get_annotations(mixin)) if not n.startswith("__")}


def to_define(name: str, mixin) -> set[str]:
    """What a type taking the capability defines: the mixin's members but the switch it sets on."""
    return members(mixin) - ({name} & set(vars(mixin)))


def defined_below(cls, name: str, interface) -> bool:
    """Whether one of cls's own classes (not those of the interface) defines name."""
    owner = next((k for k in cls.__mro__ if name in vars(k)), None)
    return owner is not None and owner not in interface


@pytest.mark.parametrize("kind", TYPES)
def test_every_type_implements_each_part_and_its_capabilities(kind):
    """Each part's required members, and each member of the capabilities the type takes (but the
    switch, the mixin's own), are the type's own, not a part's placeholder: a new type missing one
    fails here, naming the part and the member."""
    cls = REGISTRY[kind]
    interface = (*PARTS, Shape, object)
    for part in PARTS:
        missing = [name for name in required_of(cls, part) if not defined_below(cls, name, interface)]
        assert not missing, f"{cls.__name__} does not define {part.__name__}'s {missing}"
    for name, mixin in CAPABILITIES.items():
        if issubclass(cls, mixin):
            missing = [m for m in to_define(name, mixin) if not defined_below(cls, m, (*interface, mixin))]
            assert not missing, f"{cls.__name__} takes the capability {name!r} without {missing}"


def test_each_part_lists_what_a_type_defines():
    """Each part's and each capability's docstring names what a type defines there."""
    for part in PARTS:
        for name in part.required_members:
            assert f"``{name}" in part.__doc__, (part.__name__, name)
    for name, mixin in CAPABILITIES.items():
        for member in to_define(name, mixin):
            assert f"``{member}" in mixin.__doc__, (mixin.__name__, member)


def test_the_base_shape_carries_no_capability():
    """What only meshes and mesh instances do stays behind the capabilities: no part of the base
    interface declares a capability's member, and Shape holds only the switches engine/launch/programs.py
    reads of every kind, off."""
    hooks = set().union(*(members(mixin) for mixin in CAPABILITIES.values()))
    for part in PARTS:
        assert not hooks & set(dir(part)), part.__name__
    on_base = {name for name in hooks if hasattr(Shape, name)}
    assert on_base == READ_BY_PROGRAMS and not any(getattr(Shape, name) for name in on_base)

