"""Errors of a render against the float64 oracle (used by the benchmarks, stored in extra_info)."""
from __future__ import annotations

import numpy as np

from pyclray import oracle

GRAZING_COS = 0.02  # silhouettes: |cos incidence| below this are left out of every error


def _ulps(value, reference):
    """|value - reference| in units of float32's spacing at the reference."""
    spacing = np.spacing(np.abs(reference).astype(np.float32)).astype(np.float64)
    return np.abs(np.asarray(value, np.float64) - reference) / spacing


def _stats(values) -> dict:
    if values.size == 0:
        return {"max": 0.0, "p99": 0.0}
    return {"max": float(values.max()), "p99": float(np.percentile(values, 99))}


def compare(scene, images: dict, reference: dict, exclude=None) -> dict:
    """Depth error in float32 ulps, normal error (|n - n_ref|, ~ the angle in radians) and id
    mismatches, over the pixels that are not grazing (|cos incidence| >= GRAZING_COS by the oracle)
    and not in ``exclude`` (e.g. Mitsuba's plane beyond its stand-in disk)."""
    _, directions = oracle.camera_rays(scene)
    cos = oracle.incidence_cosine(scene, directions, reference["id"], reference["normal"])
    valid = cos >= GRAZING_COS
    if exclude is not None:
        valid &= ~exclude
    ref_hit = reference["id"] >= 0
    out = {"pixels": int(valid.sum()), "excluded": int((~valid).sum())}
    if "id" in images:
        same = images["id"] == reference["id"]
        out["id_mismatches"] = int((valid & ~same).sum())
    else:  # depth only: agree on hit or miss
        same = np.isfinite(images["depth"]) == ref_hit
        out["id_mismatches"] = int((valid & ~same).sum())
    both = valid & same & ref_hit
    if "depth" in images:
        d = _stats(_ulps(images["depth"][both], reference["depth"][both]))
        out["depth_ulps_max"], out["depth_ulps_p99"] = d["max"], d["p99"]
    if "normal" in images:
        diff = np.linalg.norm(np.asarray(images["normal"], np.float64)[both] - reference["normal"][both], axis=-1)
        n = _stats(diff)
        out["normal_err_max"], out["normal_err_p99"] = n["max"], n["p99"]
    return out
