"""Errors of a render against the float64 oracle (used by the benchmarks, stored in extra_info):
pyclray's own error model (pyclray.accuracy), so the benchmarks and the tests judge alike."""
from __future__ import annotations

from pyclray.reference import error_model


def compare(scene, images: dict, reference: dict, exclude=None, engine: str = "fp32") -> dict:
    """Depth error in float32 ulps of t times |cos incidence| (max, p99; and the raw max), normal
    error |n - n_ref| times |cos| (max) and id mismatches (depth only: hit/miss disagreements),
    over the pixels that are neither silhouettes (|cos| < 0.02) nor near-ties nor at edges by the
    error model of ``engine`` ("fp32", "fp64" or a Mitsuba variant), nor in ``exclude`` (e.g. Mitsuba's plane beyond its stand-in disk). ``reference`` comes from
    pyclray.reference.error_model.reference(scene)."""
    result = error_model.compare(images, reference, exclude=exclude, engine=engine)
    out = {
        "pixels": result["pixels"],
        "excluded": int(reference["id"].size) - result["pixels"],
        "id_mismatches": result["id_mismatch"] + result.get("miss_mismatch", 0),
    }
    if "depth_ulps_max" in result:
        out["depth_ulps_max"], out["depth_ulps_p99"] = result["depth_ulps_max"], result["depth_ulps_p99"]
        out["depth_ulps_raw_max"] = result["depth_ulps_raw_max"]
    if "normal_cos_max" in result:
        out["normal_err_max"] = result["normal_cos_max"]
        out["normal_err_p99"] = result["normal_cos_p99"]
    return out
