"""What the exact sphere formulation costs: tp02 rendered with kernels/sphere.cl against the
textbook one (b^2 - a c discriminant, roots (b -+ sqrt)/a, normal from p - C), in the same run.

    pytest bench/test_exact_cost.py --benchmark-only
"""
from pathlib import Path

import pytest

import pyclray
from pyclray.engine import programs

SIMPLE_SPHERE = """
/* The textbook sphere, for the cost comparison only: b^2 - a c, (b -+ sqrt) / a, p - C. */
inline realv sphere_hit(__global const Sphere* sphere, const RayPacket* ray)
{
    const vec3v F = v3_sub(v3_splat(sphere->center), ray->origin);
    const realv c = v3_dot(F, F) - SPLAT(sphere->center.w);
    const realv b = v3_dot(F, ray->dir);
    const realv disc = b * b - ray->a * c;
    const realv root = v_sqrt(disc);
    const realv near = (b - root) / ray->a, far = (b + root) / ray->a;
    const realv s = near > 0 ? near : (far > 0 ? far : SPLAT(MISS));
    return disc >= 0 ? s : SPLAT(MISS);
}

inline vec3v sphere_normal(__global const Sphere* sphere, const RayPacket* ray, const Basis* basis)
{
    const realv s = sphere_hit(sphere, ray);
    return world_from_basis(basis, v3_normalize(v3_sub(v3_scale(ray->dir, s), v3_sub(v3_splat(sphere->center), ray->origin))));
}
"""

SCENE = Path(__file__).resolve().parent.parent / "scenes" / "tp02.toml"


@pytest.fixture
def simple_sphere(monkeypatch):
    read = programs._read
    monkeypatch.setattr(programs, "_read", lambda name: SIMPLE_SPHERE if name == "sphere.cl" else read(name))
    monkeypatch.setattr(programs, "_programs", {})
    monkeypatch.setenv("PYCLRAY_CACHE_DIR", "off")


@pytest.mark.parametrize("aovs", [("depth",), ("depth", "normal", "id")], ids=["depth", "all"])
@pytest.mark.parametrize("formulation", ["exact", "simple"])
def test_tp02_sphere_formulation(benchmark, request, formulation, aovs):
    if formulation == "simple":
        request.getfixturevalue("simple_sphere")
    scene = pyclray.load_scene(SCENE)
    pyclray.render(scene, aovs=aovs)  # build and warm
    benchmark.group = f"exact vs simple sphere, tp02 512x512, {'+'.join(aovs)}"
    benchmark.pedantic(pyclray.render, args=(scene,), kwargs={"aovs": aovs}, rounds=60, iterations=1, warmup_rounds=5)
