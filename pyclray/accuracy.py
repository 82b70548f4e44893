"""The error model: how far an image may be from the float64 reference, and the measures of it.

A float32 kernel rounds the ray, the shape and the arithmetic, so its distance t can only be
trusted to a few float32 ulps of t; where the ray meets the surface at incidence angle theta, an
error in the ray's direction moves the hit along the surface by 1/cos(theta) more, so the bound
scales by 1/|cos theta|. Normals are unit vectors and carry the same relative error. Two classes of
pixels are outside any such bound and are counted apart:
- silhouettes: |cos theta| < SILHOUETTE_COS, where a ray in float32 may miss what the float64 ray
  grazes (or the reverse);
- near-ties: a second surface within NEAR_TIE_RELATIVE of the nearest one, where rounding decides
  which is nearer.
"""
from __future__ import annotations

import numpy as np

from . import oracle
from .scene import Scene

SILHOUETTE_COS = 0.02
NEAR_TIE_RELATIVE = 1e-5
ULP_ONE_FP32 = 2.0**-23  # the float32 ulp of 1


def ulp32(x) -> np.ndarray:
    """The float32 ulp of |x| (as float64)."""
    x = np.abs(np.asarray(x, np.float64))
    return np.spacing(x.astype(np.float32)).astype(np.float64)


def reference(scene: Scene) -> dict:
    """The float64 images plus what the error model needs: |cos incidence| and the masks."""
    origins, directions = oracle.camera_rays(scene)
    ref = oracle.trace(scene, origins, directions, aovs=("depth", "normal", "id", "second"))
    cos = oracle.incidence_cosine(scene, directions, ref["id"], ref["normal"])
    hit = ref["id"] >= 0
    ref["cos"] = cos
    # how far the float64 reference's own rounding (2^-53 of the ray's length and of the world
    # coordinates) moves a normal: (t + |origin|) / radius on a sphere, 0 on a plane
    condition = np.zeros(cos.shape)
    reach = ref["depth"] + np.linalg.norm(origins, axis=-1)
    for index, shape in enumerate(scene.shapes):
        if shape.type == "sphere":
            mine = ref["id"] == index
            condition[mine] = reach[mine] / shape.radius
    ref["normal_condition"] = condition
    ref["silhouette"] = hit & (cos < SILHOUETTE_COS)
    with np.errstate(invalid="ignore"):
        ref["near_tie"] = hit & (ref["second"] - ref["depth"] <= NEAR_TIE_RELATIVE * ref["depth"])
    ref["origins"], ref["directions"] = origins, directions
    return ref


def compare(images: dict, ref: dict, exclude=None) -> dict:
    """Errors of a render against the reference, on the pixels that are neither silhouettes nor
    near-ties (nor in ``exclude``): depth in float32 ulps of t times |cos|, relative depth error,
    normal error (Euclidean) times |cos|, id mismatches, and counts of what was left out."""
    excluded = ref["silhouette"] | ref["near_tie"]
    if exclude is not None:
        excluded = excluded | exclude
    judged = ~excluded
    out = {"pixels": int(judged.sum()), "silhouette": int(ref["silhouette"].sum()), "near_tie": int((ref["near_tie"] & ~ref["silhouette"]).sum())}
    if "id" in images:
        out["id_mismatch"] = int(((images["id"] != ref["id"]) & judged).sum())
        same = judged & (images["id"] == ref["id"]) & (ref["id"] >= 0)
    else:  # no id image: a hit where the reference misses, or the reverse, is the mismatch
        hits = np.isfinite(np.asarray(images["depth"], np.float64))
        out["id_mismatch"] = int(((hits != (ref["id"] >= 0)) & judged).sum())
        same = judged & (ref["id"] >= 0) & hits
    cos = ref["cos"][same]
    if "depth" in images:
        test = np.asarray(images["depth"], np.float64)
        miss_ok = judged & (ref["id"] < 0)
        out["miss_mismatch"] = int((np.isfinite(test) & miss_ok).sum())
        error = np.abs(test[same] - ref["depth"][same])
        ulps = error / ulp32(ref["depth"][same]) * cos
        relative = error / ref["depth"][same]
        raw = error / ulp32(ref["depth"][same])
        out["depth_ulps_raw_max"] = float(raw.max()) if raw.size else 0.0
        out["depth_ulps_max"] = float(ulps.max()) if ulps.size else 0.0
        out["depth_ulps_p99"] = float(np.percentile(ulps, 99)) if ulps.size else 0.0
        out["depth_rel_max"] = float(relative.max()) if relative.size else 0.0
        out["depth_rel_cos_max"] = float((relative * cos).max()) if relative.size else 0.0
    if "normal" in images:
        test = np.asarray(images["normal"], np.float64)
        error = np.linalg.norm(test[same] - ref["normal"][same], axis=-1)
        out["normal_max"] = float(error.max()) if error.size else 0.0
        out["normal_cos_max"] = float((error * cos).max()) if error.size else 0.0
        out["normal_cos_p99"] = float(np.percentile(error * cos, 99)) if error.size else 0.0
        # scaled by the normal's conditioning max(1, (t + |origin|) / r): what the float64
        # reference's own rounding moves a far or far-off sphere's normal by
        scaled = error * cos / np.maximum(1.0, ref["normal_condition"][same])
        out["normal_conditioned_max"] = float(scaled.max()) if error.size else 0.0
    return out
