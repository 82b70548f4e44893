"""The check's closest points: pyclray's closest_points of points in and around the scene against
the float64 oracle (reference.oracle.closest_points) within error_model.closest_tolerances. Mitsuba
has no closest-point query, so the oracle is the only reference here."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...io.progress import step
from .. import error_model, oracle
from .summary import Summary, table

DEFAULT_POINTS = 2000


@dataclass
class ClosestCheck:
    points: int
    distance: Summary  # |distance - oracle's| over its tolerance
    off_surface: Summary  # the reported point's distance from the named shape's surface over its tolerance
    failures: list = field(default_factory=list)


def sample_points(scene, count: int, seed: int) -> np.ndarray:
    """Half uniform in the bounded shapes' box (10% larger; about the camera's eye without one), half
    jittered about the oracle's nearest surface points of other uniform points."""
    rng = np.random.default_rng(seed)
    boxes = [np.asarray(s.box(), np.float64) for s in scene.shapes if type(s).bounded]
    if boxes:
        lo, hi = np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)
    else:
        lo = hi = np.asarray(scene.camera.eye, np.float64)
    margin = 0.1 * max(float(np.max(hi - lo)), 1.0)
    lo, hi = lo - margin, hi + margin
    uniform = rng.uniform(lo, hi, (count - count // 2, 3))
    seeds = rng.uniform(lo, hi, (count // 2, 3))
    if not scene.shapes:
        return np.concatenate([uniform, seeds])
    on = oracle.closest_points(scene, seeds)["position"]
    return np.concatenate([uniform, on + rng.normal(size=on.shape) * 1e-3 * margin])


def closest_check(scene, count: int = DEFAULT_POINTS, seed: int = 0, device=None, precision: str = "fp32") -> ClosestCheck:
    from ...engine.api import closest_points

    points = sample_points(scene, count, seed)
    step("closest points: pyclray, float64 oracle")
    mine = closest_points(scene, points, precision=precision, device=device)
    truth = oracle.closest_points(scene, points)
    tol = error_model.closest_tolerances(points, truth, precision)
    found = np.isfinite(truth["distance"])
    with np.errstate(invalid="ignore", divide="ignore"):
        distance = np.where(found, np.abs(mine["distance"] - truth["distance"]) / np.maximum(tol["distance"], 1e-300), 0)
    off = np.zeros(len(points))
    position = mine["position"].astype(np.float64)
    for index, shape in enumerate(scene.shapes):
        here = mine["id"] == index
        if here.any():
            off[here] = shape.surface_distance(position[here]) / tol["position"][here]
    result = ClosestCheck(len(points), Summary.of(distance), Summary.of(off))
    bad = int(np.sum(distance > 1))
    if bad:
        result.failures.append(f"closest points: {bad} distances outside the tolerance")
    if np.any(mine["id"][~found] != -1) or np.any(mine["id"][found] < 0):
        result.failures.append("closest points: a point without a nearest shape, or one with one where the oracle has none")
    bad = int(np.sum(off > 1))
    if bad:
        result.failures.append(f"closest points: {bad} nearest points off their shape's surface")
    return result


def format_closest_check(check: ClosestCheck) -> str:
    return table(
        f"closest points of {check.points} points (pyclray fp32) against the float64 oracle (Mitsuba has no "
        "closest-point query); errors in units of the tolerance (error_model.closest_tolerances)",
        [("|distance - oracle's|", check.distance), ("position off the named shape", check.off_surface)],
    )
