"""The all-hits comparison of ``pyclray check``: every hit along Mitsuba's own primary rays (as the
ray-level comparison takes them) from pyclray.all_hits, from Mitsuba's ray_intersect repeated from
just past each hit (what a user of a one-hit API does), and from the float64 oracle
(oracle.all_hits: each crossing once, ties decided in exact arithmetic).

The oracle judges: pyclray's count of a ray must be the oracle's, and each hit's depth within
pyclray's cast tolerance of the oracle's, except on rays that pass within the tolerance of an edge
(a shared edge, a rim, a border) or touch a surface (|cos| below the silhouette cosine), where
either count of a tangent (0 or 2) is right; those are counted apart. Mitsuba's counts are
reported beside, not judged (its re-casts can skip or repeat a hit at a shared edge or within the
offset)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import error_model
from ..error_model import SILHOUETTE_COS
from .summary import Summary, table

# Mitsuba's re-cast starts this far (relative to the hit's distance and coordinates) past each hit
RECAST_OFFSET = 2.0**-16
MOST_HITS = 64  # Mitsuba's re-casts of one ray stop there


@dataclass
class HitsCheck:
    rays: int
    counts: dict
    depth_ratio: Summary
    failures: list = field(default_factory=list)


def mitsuba_all_hits(mi_scene, ids, origins, directions) -> np.ndarray:
    """The hit counts of Mitsuba's ray_intersect cast again from just past each hit (RECAST_OFFSET)."""
    from .. import mitsuba

    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    counts = np.zeros(len(origins), np.int32)
    travelled = np.zeros(len(origins))
    going = np.ones(len(origins), bool)
    for _ in range(MOST_HITS):
        rows = np.flatnonzero(going)
        if not len(rows):
            break
        start = origins[rows] + travelled[rows, None] * unit[rows]
        hit = mitsuba.intersect(mi_scene, ids, start, unit[rows])
        found = np.isfinite(hit["depth"])
        counts[rows[found]] += 1
        point = travelled[rows] + hit["depth"]
        offset = RECAST_OFFSET * (np.abs(point) + np.abs(start).max(axis=1) + 1.0)
        travelled[rows] = np.where(found, point + offset, travelled[rows])
        going[rows[~found]] = False
    return counts


def all_hits_check(scene, variant: str = "scalar_rgb", n_rays: int = 256, seed: int = 0, device=None) -> HitsCheck:
    """all_hits of n_rays of Mitsuba's primary rays (pixels chosen with this seed) against the oracle,
    Mitsuba's repeated ray_intersect beside."""
    from .. import mitsuba, oracle
    from ...engine.api import all_hits
    from ...io.progress import step

    width, height = scene.image.width, scene.image.height
    rng = np.random.default_rng(seed)
    flat = np.sort(rng.choice(width * height, size=min(n_rays, width * height), replace=False))
    rows, columns = np.divmod(flat, width)
    step(f"all hits: Mitsuba {variant}, repeated ray_intersect")
    mitsuba.import_mitsuba(variant)
    mi_scene, ids = mitsuba.load(scene, variant)
    origins, directions = mitsuba.primary_rays(mi_scene, scene, rows, columns)
    theirs = mitsuba_all_hits(mi_scene, ids, origins, directions)
    step("all hits: pyclray all_hits, float64 oracle, comparison")
    ours = all_hits(scene, origins, directions, precision="fp32", device=device)
    truth = oracle.all_hits(scene, origins, directions)
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    # per oracle hit: its incidence, its distance from an edge, its tolerance
    ray, t, hit_ids = truth["ray"], truth["depth"], truth["id"]
    points = origins[ray] + t[:, None] * unit[ray]
    cos, edge = np.ones(len(t)), np.full(len(t), np.inf)
    for index, shape in enumerate(scene.shapes):
        mine = hit_ids == index
        if mine.any():
            cos[mine] = np.abs(np.einsum("ij,ij->i", shape.oracle_normal(points[mine]), unit[ray][mine]))
            edge[mine] = shape.edge_distance(points[mine])
    tolerance, _ = error_model.pyclray_tolerances(scene, {"depth": t, "id": hit_ids}, cos, origins[ray], "fp32",
                                                  directions=unit[ray])
    apart_hit = (cos < SILHOUETTE_COS) | (edge <= tolerance * cos)
    apart = np.bincount(ray[apart_hit], minlength=len(origins)) > 0
    ours_count, true_count = np.diff(ours["offsets"]), np.diff(truth["offsets"])
    judged = ~apart
    agree = ours_count == true_count
    # each ray's hits by shape, then distance (two shapes' hits within rounding of each other, such
    # as a sphere resting on a plane, may come in either order)
    ours_order = np.lexsort((ours["depth"], ours["id"], ours["ray"]))
    true_order = np.lexsort((t, hit_ids, ray))
    both = true_order[np.repeat(judged & agree, true_count)[true_order]]
    mine = ours_order[np.repeat(judged & agree, ours_count)[ours_order]]
    same_shapes = np.array_equal(ours["id"][mine], hit_ids[both])
    ratio = np.abs(ours["depth"][mine].astype(np.float64) - t[both]) / tolerance[both] if same_shapes else np.zeros(0)
    result = HitsCheck(
        rays=len(origins),
        counts={
            "rays": len(origins),
            "hits (float64 oracle)": int(true_count.sum()),
            "judged rays (away from edges and tangents)": int(judged.sum()),
            "  pyclray's count is the oracle's": int((judged & agree).sum()),
            "  with the oracle's shapes": int((judged & agree).sum()) if same_shapes else "no",
            "rays at edges or tangents (apart)": int(apart.sum()),
            "  pyclray's count of the oracle's parity": int(((ours_count % 2) == (true_count % 2))[apart].sum()),
            "Mitsuba's repeated ray_intersect: count is the oracle's": int((theirs == true_count)[judged].sum()),
        },
        depth_ratio=Summary.of(ratio),
    )
    wrong = int((judged & ~agree).sum())
    if wrong:
        result.failures.append(f"all hits: pyclray's count differs from the float64 oracle's on {wrong} rays")
    if not same_shapes:
        result.failures.append("all hits: pyclray's hits are not on the oracle's shapes")
    if len(ratio) and result.depth_ratio.max > 1:
        result.failures.append("all hits: pyclray's depths off the float64 oracle beyond the tolerance")
    return result


def format_hits_check(result: HitsCheck) -> str:
    rows = [*[(name, str(value)) for name, value in result.counts.items()],
            ("depth: difference from the oracle / tolerance", result.depth_ratio)]
    return table(f"all hits along {result.rays} of Mitsuba's primary rays: pyclray.all_hits against the float64 "
                 "oracle (Mitsuba's ray_intersect repeated past each hit beside)", rows)
