"""The cross-check of pyclray's float32 images against Mitsuba 3, pixel by pixel and ray by ray
(the comparisons are in pyclray.reference.validation, the error model in
pyclray.reference.error_model; the command is pyclray.apps.cli.check).

The tolerances' derivation and measurements (the error model's docstring has the model):
- same rays: Mitsuba intersects in float32 world coordinates of size L = max(|eye|, |anchor|,
  |eye - anchor|) (the scalar variants solve a sphere's quadratic in float64, but from float32 rays
  and centres); measured below 2.8 eps (t + L) / cos over 75 random scenes (random spheres and a
  tilted plane, moved 0, 100 and 1000 units off the world origin) in both variants, and pyclray's
  own error against the float64 oracle is below 3.7 eps t / cos, so K = 6 leaves room for both;
- cameras: Mitsuba's sensor's to_world was a float32 look_at matrix built from target - eye
  rounded in float32 (now the float64 look-at rounded once, as Mitsuba's XML parser builds it,
  which rounds less), so its ray directions differ from pyclray's pixel rays by up to
  alpha = 3 eps (1 + S) (measured 3.3 eps on tp02, where the bound is 6 eps; at most 2.1 eps (1 + S)
  over the random scenes), and its origins, the eye rounded to float32 and moved to the near-clip
  plane, lie within 2 eps max(|eye|, 1) of pyclray's rays (measured 1.6). A direction off by alpha
  moves the hit sideways by t alpha: images measured below 0.33 of their bound over the random
  scenes; without the camera term, scenes 1000 units off the origin exceed K eps (t + L) / cos by 1.9.

Where the model ends (counted apart, not judged): silhouettes, edges, pixels next to an id change
and near ties; pixels whose ray meets a shape where its Mitsuba stand-in ends (the plane beyond its
disk) are left out of everything and counted.
"""
from __future__ import annotations

from ..model.shapes import REGISTRY
from . import error_model
from .error_model import ORIGIN_K, SILHOUETTE_COS
from .validation.files import heat_map, save
from .validation.images import ImageCheck, cross_check, format_image_check, next_to_id_change
from .validation.rays import DEFAULT_RAYS, RayCheck, format_ray_check, ray_level

VARIANTS = ("scalar_rgb", "llvm_ad_rgb")

__all__ = ["DEFAULT_RAYS", "ImageCheck", "RayCheck", "cross_check", "format_image_check", "format_ray_check", "heat_map",
           "next_to_id_change", "ray_level", "save", "tolerance_text"]


def tolerance_text() -> list[str]:
    """The error model's tolerances, as printed by the command."""
    K, camera_k = error_model.K_MITSUBA, error_model.CAMERA_K
    return [
        "tolerances (eps = 2^-24; t = distance, cos = |cos incidence| from the float64 oracle, r = radius of curvature,",
        "  L = max(|eye|, |anchor|, |eye - anchor|): the size of the float32 world coordinates Mitsuba works in,",
        "  anchor = the point the shape is intersected from (a centre, an end, the plane's disk centre);",
        "  S = max(|eye|, |target|) / |target - eye| (a camera from intrinsics: max(tan_x, tan_y) (1 + 2 |offset|),",
        "  offset = the principal point's from the image's centre, in image sizes):",
        f"  same rays: |depth difference| <= {K:g} eps (t + L) / cos, normal angle <= {K:g} eps (1 + (t + L) / (r cos))",
        f"  cameras:   direction angle <= alpha = {camera_k:g} eps (1 + S), origin off our ray <= {ORIGIN_K:g} eps max(|eye|, 1)",
        f"  images:    |depth difference| <= D = eps ({K:g} (t + L) + {camera_k:g} (1 + S) t + {ORIGIN_K:g} max(|eye|, 1)) / cos,"
        f" normal angle <= {K:g} eps + D / r",
        f"  not judged: silhouettes (|cos| < {SILHOUETTE_COS:g}), hits within D of an edge, and for ids also pixels next",
        "  to an id change and near ties (the second-nearest surface within D)",
    ] + [f"  {kind}: K x {cls.mitsuba_error_scale:g} (its Mitsuba counterpart is less exact)"
         for kind, cls in REGISTRY.items() if cls.mitsuba_error_scale != 1.0]
