"""The shaded image against Mitsuba 3's ``direct`` integrator (part of ``pyclray check``).

For a diffuse scene (specular 0, no ambient, black background) the shading model is Mitsuba's direct
illumination of a diffuse BSDF, up to Mitsuba's 1/pi: Mitsuba's diffuse BSDF is albedo / pi, pyclray's
term albedo max(0, n_s.L), so pyclray's shaded = pi x Mitsuba's. The bridge:

- the same scene (pyclray.mitsuba.scene_dict: pixel-centre sensor, one sample per pixel, the same
  shapes), each shape with a ``twosided`` ``diffuse`` BSDF of its colour (pyclray shades the side the
  viewer sees, n_s; Mitsuba's diffuse BSDF is one-sided);
- the lights as Mitsuba ``point`` (intensity) and ``directional`` (irradiance) emitters, the headlight
  where the scene has no lights;
- one deterministic emitter sample per pixel: the ``direct`` integrator with emitter_samples = 1 and
  bsdf_samples = 0 samples one of the scene's emitters at random, so each light is rendered in a scene
  of its own (a delta emitter's only sample is deterministic) and the images are summed.

A scene that is not diffuse is checked in its diffuse version (specular, ambient and background set
to 0): the geometry, lights, colours and shadows are what is compared.

Tolerance (printed): both images are the shading model at hit points and normals that the error model
bounds, pyclray's against the float64 oracle (K = 4) and Mitsuba's (K = 6, plus the difference of the
two cameras); ``pyclray.reference.shading.tolerance`` turns each into a bound on the colour, and the two bounds
add. Left out, each counted: silhouettes and pixels whose ids differ (the image check judges those),
terminators, and shadow edges: where the float64 visibility changes when the hit point moves by
SHADOW_EDGE_K times the larger of the two engines' shadow-ray offsets (pyclray's 16 eps |p|, or for
an orthographic camera, whose render casts its rays, 16 (eps t + eps64 (|p|_1 + R)): engine/queries/shade.py;
Mitsuba's spawn_ray offset, RayEpsilon (1 + max |p_k|) with RayEpsilon = 1500 eps), or when it is
lifted along the normal by either engine's own offset (where that offset decides the shadow).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field, replace

import numpy as np

from ...engine.queries.shade import shadow_offset, shape_sizes
from ...engine.scene.lighting import shadow_reach
from ...model.lights import DirectionalLight, Material, Shading, effective_lights
from .. import error_model, shading
from .arbitrate import Verdicts, decide

EPSILON = 2.0**-24
MITSUBA_RAY_EPSILON = 1500 * EPSILON  # Mitsuba 3's math::RayEpsilon<float>
SHADOW_EDGE_K = 4


def diffuse_version(scene):
    """The scene with specular 0, no ambient and a black background (what Mitsuba's direct
    integrator with a diffuse BSDF computes)."""
    shapes = tuple(replace(s, material=Material(s.material.color, 0.0, s.material.shininess)) for s in scene.shapes)
    return replace(scene, shapes=shapes, shading=Shading((0, 0, 0), (0, 0, 0), scene.shading.shadows))


def direct_scene_dict(scene, light, variant: str) -> dict:
    """Mitsuba's scene for one light: the shapes with two-sided diffuse BSDFs, the direct integrator."""
    from .. import mitsuba

    out = mitsuba.scene_dict(scene, variant)
    out["integrator"] = {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0}
    out["sensor"]["film"]["pixel_format"] = "rgb"
    for key, value in out.items():
        found = re.fullmatch(r"shape_0*(\d+)(?:_.*)?", key)
        if found and isinstance(value, dict):
            color = scene.shapes[int(found.group(1))].material.color
            value["bsdf"] = {"type": "twosided",
                             "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(color)}}}
    out["light"] = mitsuba.emitter_dict(light)
    return out


def render_direct(scene, variant: str = "scalar_rgb") -> np.ndarray:
    """pi x Mitsuba's direct illumination of the scene's diffuse version, (height, width, 3) float64."""
    from .. import mitsuba

    mi = mitsuba.import_mitsuba(variant)
    total = np.zeros((scene.image.height, scene.image.width, 3))
    for light in effective_lights(scene):
        if not scene.shading.shadows:
            raise ValueError("Mitsuba's direct integrator always casts shadow rays: the scene has shadows = false")
        mi_scene = mitsuba.load_dict(mi, direct_scene_dict(scene, light, variant))
        with mitsuba.quiet_interrupts(mi):
            image = mi.render(mi_scene, spp=1)
        total += np.array(image, np.float64)[..., :3]
    return np.pi * total


@dataclass
class ShadedCheck:
    pixels: int  # judged
    lit: int
    shadowed: int
    left_out: dict
    worst: float  # largest |difference| / tolerance over the judged pixels
    max_difference: float
    median_tolerance: float
    failures: list
    variant: str = ""
    verdict: Verdicts = field(default_factory=Verdicts)  # where the two disagree, who the oracle says is wrong

    @property
    def passed(self) -> bool:
        return not self.failures


def cross_check_shaded(scene, variant: str = "scalar_rgb", device=None, truth=None) -> ShadedCheck:
    """pyclray's shaded image (fp32) against pi x Mitsuba's direct integrator, on the diffuse version.
    truth: the oracle's trace of the pixels (with "second"), if at hand (ImageCheck.truth)."""
    from ..mitsuba import beyond_counterparts
    from ...engine.api import render
    from ...io.progress import step

    scene = diffuse_version(scene)
    if variant.startswith("llvm") and any(isinstance(light, DirectionalLight) for light in effective_lights(scene)):
        # Mitsuba 3.9.1's llvm variants abort the process in their LLVM back end on a directional
        # emitter under the direct integrator (AVX-512: "Cannot select" an fma of v16f32)
        variant = "scalar_rgb"
    step("shaded: pyclray render")
    ours = render(scene, aovs=("depth", "id", "shaded"), device=device)
    step(f"shaded: Mitsuba {variant} render")
    theirs = render_direct(scene, variant)
    step("shaded: float64 oracle and comparison")
    ref = error_model.reference(scene, truth)
    O, D = ref["origins"], ref["directions"]
    ref["points"] = O + np.where(np.isfinite(ref["depth"]), ref["depth"], 0)[..., None] * D
    hit = ref["id"] >= 0
    # per pixel: the larger of the two engines' shadow-ray offsets at its hit point
    if scene.camera.rays_from_eye:  # the render kernel's offset (kernels/shading.h)
        ours_offset = shadow_reach(np.linalg.norm(ref["points"] - O, axis=-1), EPSILON)
    else:  # a render by casting (orthographic): engine/queries/shade.py's, its depth from the ray's origin
        sizes = shape_sizes(scene.shapes)[np.where(hit, ref["id"], -1)]
        ours_offset = shadow_offset(np.where(hit, ref["depth"], 0.0), ref["points"], sizes, "fp32")
    theirs_offset = MITSUBA_RAY_EPSILON * (1 + np.abs(ref["points"]).max(axis=-1))
    blur = SHADOW_EDGE_K * np.maximum(ours_offset, theirs_offset)
    V, edges = shading.reference_visibility(scene, ref["points"], ref["normal"], D, ref["id"], blur=blur,
                                            lifts=(ours_offset, theirs_offset))
    # the error model's bounds on each engine's hit point and normal, made bounds on the colour
    # (a render by casting: each ray traced on its own, cast's bounds)
    space_origin = scene.camera.eye if scene.camera.rays_from_eye else None
    our_depth, our_normal = error_model.pyclray_tolerances(scene, ref, ref["cos"], O, "fp32", space_origin, D)
    their_depth, their_normal = error_model.mitsuba_tolerances(scene, ref["depth"], ref["id"], ref["cos"], cameras=True)
    ours_tol, jump = shading.tolerance(scene, D, ref, our_depth, our_normal, EPSILON)
    theirs_tol, jump2 = shading.tolerance(scene, D, ref, their_depth, their_normal, EPSILON)
    tolerance = ours_tol + theirs_tol
    # the rays outside the error model, by either engine's rules (error_model.judged_pixels)
    outside = error_model.judged_pixels(ours, ref, "fp32")
    for name, mask in error_model.judged_pixels({}, ref, "mitsuba").items():
        outside[name] = outside[name] | mask
    left_out = {
        "silhouette": outside["silhouette"], "near tie": outside["near_tie"], "edge": outside["edge"],
        "id differs from the oracle": ours["id"] != ref["id"], "terminator": jump | jump2,
        "shadow edge": np.any(edges, axis=0), "beyond Mitsuba's counterpart": beyond_counterparts(scene, O, D),
    }
    excluded = np.zeros(hit.shape, bool)
    counts = {}
    for name, mask in left_out.items():
        counts[name] = int((mask & ~excluded).sum())
        excluded |= mask
    judged = ~excluded
    difference = np.abs(ours["shaded"].astype(np.float64) - theirs).max(axis=-1)
    ratio = difference[judged] / np.maximum(tolerance[judged], 1e-300)
    lit = np.zeros(hit.shape, bool)
    for v in V:
        lit |= v > 0
    # where they disagree, the shading model in float64 at the oracle's hits decides (arbitrate.py)
    truth_colour = shading.reference_shading(scene, D, ref, V)
    ours_off = np.abs(ours["shaded"].astype(np.float64) - truth_colour).max(axis=-1) > ours_tol
    theirs_off = np.abs(theirs - truth_colour).max(axis=-1) > theirs_tol
    verdict = decide(judged & (difference > tolerance), ours_off, theirs_off)
    failures = []
    if verdict.pyclray:
        failures.append(f"shaded: pyclray wrong by the float64 oracle at {verdict.pyclray} pixels where it disagrees "
                        f"with Mitsuba (worst difference / tolerance {ratio.max():.3g})")
    return ShadedCheck(
        pixels=int(judged.sum()), lit=int((judged & hit & lit).sum()), shadowed=int((judged & hit & ~lit).sum()),
        left_out=counts, worst=float(ratio.max(initial=0.0)), max_difference=float(difference[judged].max(initial=0.0)),
        median_tolerance=float(np.median(tolerance[judged & hit])) if (judged & hit).any() else 0.0, failures=failures,
        variant=variant, verdict=verdict,
    )


def format_shaded_check(result: ShadedCheck) -> str:
    lines = [
        f"shaded (diffuse version: specular, ambient, background 0) against pi x Mitsuba's direct integrator ({result.variant})",
        "  tolerance per pixel: pyclray.reference.shading.tolerance of pyclray's (K=4 vs the oracle) and of Mitsuba's",
        "  (K=6, plus the cameras) hit-point and normal bounds (pyclray.reference.error_model), added; shadow edges: visibility changes",
        f"  within {SHADOW_EDGE_K} x max(pyclray's 16 eps |p|, Mitsuba's 1500 eps (1 + |p|)) of the hit, or where",
        "  the hit point lifted along its normal by either engine's offset sees the light otherwise",
        f"  judged {result.pixels} pixels ({result.lit} lit, {result.shadowed} in shadow); max |difference| "
        f"{result.max_difference:.3g}, median tolerance {result.median_tolerance:.3g}; worst difference / tolerance "
        f"{result.worst:.3g}",
        "  left out: " + ", ".join(f"{name} {count}" for name, count in result.left_out.items()),
        f"  arbitration by the float64 shading model: {result.verdict.disagree} pixels outside the tolerance; "
        f"pyclray's fault {result.verdict.pyclray}, Mitsuba's fault {result.verdict.mitsuba}, undecided "
        f"{result.verdict.undecided}",
    ]
    return "\n".join(lines)
