"""What the exact sphere formulation costs: tp02 rendered with kernels/sphere.cl against the
textbook one (b^2 - a c discriminant, roots (b -+ sqrt)/a, normal from p - C), in the same run.

    pytest bench/test_exact_cost.py --benchmark-only
"""
from pathlib import Path

import pytest

import pyclray
from pyclray.engine.launch import programs

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
def simple_sphere(monkeypatch, tmp_path):
    """The kernels read from a copy of their folder whose sphere.cl is SIMPLE_SPHERE, built anew."""
    folder = tmp_path / "kernels"
    folder.mkdir()
    for source in programs.kernel_dir().iterdir():
        if source.is_file():
            (folder / source.name).write_bytes(source.read_bytes())
    (folder / "sphere.cl").write_text(SIMPLE_SPHERE, encoding="utf-8")
    monkeypatch.setattr(programs, "kernel_dir", lambda: folder)
    monkeypatch.setenv("PYCLRAY_CACHE_DIR", "off")
    programs.clear()
    yield
    programs.clear()


@pytest.mark.parametrize("aovs", [("depth",), ("depth", "normal", "id")], ids=["depth", "all"])
@pytest.mark.parametrize("formulation", ["exact", "simple"])
def test_tp02_sphere_formulation(benchmark, request, formulation, aovs):
    if formulation == "simple":
        request.getfixturevalue("simple_sphere")
    scene = pyclray.load_scene(SCENE)
    pyclray.render(scene, aovs=aovs)  # build and warm
    benchmark.group = f"exact vs simple sphere, tp02 512x512, {'+'.join(aovs)}"
    benchmark.pedantic(pyclray.render, args=(scene,), kwargs={"aovs": aovs}, rounds=60, iterations=1, warmup_rounds=5)
