"""The ray-level comparison: Mitsuba's own float32 primary rays (its sensor's ``sample_ray`` at
pixel centres) cast through ``pyclray.cast`` and through Mitsuba's ``ray_intersect``: first how
far Mitsuba's camera rays are from pyclray's, then the intersections of the very same rays
(tolerances: ``error_model.mitsuba_tolerances`` without the cameras' term)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import error_model
from ..error_model import EPSILON, ORIGIN_K, angle_between
from .arbitrate import decide, verdict_rows, wrong_hits
from .summary import Summary, disagreement_kinds, table

EPS32 = EPSILON["fp32"]
DEFAULT_RAYS = 1024


@dataclass
class RayCheck:
    """The outcome of ``ray_level``."""

    variant: str
    rays: int
    camera_angle: Summary  # radians between Mitsuba's ray direction and pyclray's pixel ray
    camera_origin: Summary  # distance of Mitsuba's ray origin from pyclray's ray line, / (eps max(|eye|, 1))
    camera_tolerance: float  # radians, for camera_angle
    counts: dict
    depth_relative: Summary
    depth_ratio: Summary
    normal_angle: Summary
    normal_ratio: Summary
    ids: dict
    failures: list = field(default_factory=list)
    verdicts: dict = field(default_factory=dict)  # AOV -> arbitrate.Verdicts

    @property
    def passed(self) -> bool:
        return not self.failures


def ray_level(
    scene, variant: str = "scalar_rgb", n_rays: int = DEFAULT_RAYS, seed: int = 0, device=None, mitsuba_scene=None
) -> RayCheck:
    """Cast Mitsuba's own primary rays of n_rays pixels (chosen with this seed) through pyclray.cast
    and through Mitsuba's ray_intersect; compare the cameras and the intersections of those rays.

    mitsuba_scene: the scene Mitsuba intersects, if not the same one (for tests)."""
    from .. import mitsuba, oracle
    from ...engine.api import cast

    width, height = scene.image.width, scene.image.height
    rng = np.random.default_rng(seed)
    flat = np.sort(rng.choice(width * height, size=min(n_rays, width * height), replace=False))
    rows, columns = np.divmod(flat, width)

    from ...io.progress import step

    step(f"ray level: Mitsuba {variant}")
    mitsuba.import_mitsuba(variant)
    mi_scene, ids = mitsuba.load(scene if mitsuba_scene is None else mitsuba_scene, variant)
    origins, directions = mitsuba.primary_rays(mi_scene, scene, rows, columns)

    # the cameras: Mitsuba's rays against pyclray's pixel rays (float64 oracle)
    eye = np.array(scene.camera.eye)
    pixel_origins, pixel_directions = oracle.camera_rays(scene)
    ours_directions = pixel_directions[rows, columns]
    offset = origins - pixel_origins[rows, columns]  # (the eye, but for an orthographic camera's rays)
    sideways = offset - np.einsum("nk,nk->n", offset, ours_directions)[:, None] * ours_directions
    camera_angle = angle_between(directions, ours_directions)
    # (per ray, the size of what its origin is summed from in float32: the eye, and for an orthographic
    # camera the pixel's offset on the plane through it)
    terms = max(np.linalg.norm(eye), 1.0) + np.linalg.norm(pixel_origins[rows, columns] - eye, axis=-1)
    camera_origin = np.linalg.norm(sideways, axis=1) / (EPS32 * terms)
    camera_tolerance = error_model.camera_angle_tolerance(scene)

    # the same rays through both
    theirs = mitsuba.intersect(mi_scene, ids, origins, directions)
    step("ray level: pyclray cast, float64 oracle, comparison")
    ours = cast(scene, origins, directions, precision="fp32", device=device)
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    truth = oracle.trace(scene, origins, unit, aovs=("depth", "normal", "id", "second"))
    cos = oracle.incidence_cosine(scene, unit, truth["id"], truth["normal"])
    origin_scale = np.linalg.norm(origins, axis=1)
    depth_tolerance, normal_tolerance = error_model.mitsuba_tolerances(
        scene, truth["depth"], truth["id"], cos, cameras=False, origin_scale=origin_scale
    )
    beyond = mitsuba.beyond_counterparts(scene, origins, unit)
    radius = error_model.silhouette_radii(scene)[np.maximum(truth["id"], 0)]
    silhouette = error_model.silhouettes(truth["id"], cos, depth_tolerance, radius) & ~beyond
    farthest = np.fmax.reduce([np.where(np.isfinite(d), d, 0.0) for d in (truth["depth"], ours["depth"], theirs["depth"])])
    band, _ = error_model.mitsuba_tolerances(scene, farthest, truth["id"], cos, cameras=False, origin_scale=origin_scale)
    edge = error_model.at_edges(scene, origins, unit, [(truth["id"], truth["depth"]), (ours["id"], ours["depth"]),
                                                    (theirs["id"], theirs["depth"])], band * cos) & ~beyond
    same = (ours["id"] == theirs["id"]) & (ours["id"] >= 0) & ~beyond
    judged = same & ~silhouette & ~edge
    with np.errstate(invalid="ignore", divide="ignore"):
        difference = np.abs(ours["depth"].astype(np.float64) - theirs["depth"])
        relative = difference / truth["depth"]
        depth_ratio = difference / depth_tolerance
    angle = angle_between(ours["normal"], theirs["normal"])
    disagree = (ours["id"] != theirs["id"]) & ~beyond
    truth["cos"] = cos
    near_tie = error_model.near_ties(truth, lambda t, i, c: error_model.mitsuba_tolerances(
        scene, t, i, c, cameras=False, origin_scale=origin_scale)[0])
    kinds = {"agree": int((~disagree & ~beyond).sum()),
             **disagreement_kinds(disagree, (("silhouette", silhouette), ("edge", edge), ("near tie", near_tie)))}

    result = RayCheck(
        variant=variant,
        rays=len(flat),
        camera_angle=Summary.of(camera_angle),
        camera_origin=Summary.of(camera_origin),
        camera_tolerance=camera_tolerance,
        counts={
            "rays": len(flat),
            "both hit the same shape": int(same.sum()),
            "  of which judged": int(judged.sum()),
            "  of which silhouettes (apart)": int((same & silhouette).sum()),
            "  of which at edges (apart)": int((same & edge & ~silhouette).sum()),
            "both miss": int(((ours["id"] < 0) & (theirs["id"] < 0) & ~beyond).sum()),
            "beyond a Mitsuba stand-in (left out)": int(beyond.sum()),
        },
        depth_relative=Summary.of(relative[judged]),
        depth_ratio=Summary.of(depth_ratio[judged]),
        normal_angle=Summary.of(angle[judged]),
        normal_ratio=Summary.of((angle / normal_tolerance)[judged]),
        ids=kinds,
    )
    if result.camera_angle.max > camera_tolerance:
        result.failures.append(f"ray level: Mitsuba's camera rays off ours by up to {result.camera_angle.max:.3g} radians")
    if result.camera_origin.max > ORIGIN_K:
        result.failures.append("ray level: Mitsuba's camera ray origins off the eye")
    # where they disagree, the oracle of the very same rays decides who is wrong (arbitrate.py)
    ours_wrong = wrong_hits(ours, truth, *error_model.pyclray_tolerances(scene, truth, cos, origins, "fp32",
                                                                        directions=unit))
    theirs_wrong = wrong_hits(theirs, truth, depth_tolerance, normal_tolerance)
    with np.errstate(invalid="ignore"):
        result.verdicts = {
            "depth": decide(judged & (depth_ratio > 1), ours_wrong["depth"], theirs_wrong["depth"]),
            "normal": decide(judged & (angle > normal_tolerance), ours_wrong["normal"], theirs_wrong["normal"]),
            "id (hits and misses)": decide(disagree, ours_wrong["id"], theirs_wrong["id"], silhouette | edge | near_tie),
        }
    for name, verdict in result.verdicts.items():
        if verdict.pyclray:
            result.failures.append(f"ray level, {name}: pyclray wrong by the float64 oracle on {verdict.pyclray} rays "
                                   "where it disagrees with Mitsuba")
    return result


def format_ray_check(result: RayCheck) -> str:
    camera = [
        ("direction angle (radians)", result.camera_angle),
        ("direction angle / 2^-24", result.camera_angle.scaled(1 / EPS32)),
        ("direction angle / tolerance", result.camera_angle.scaled(1 / result.camera_tolerance)),
        ("origin off our ray / (2^-24 max(|eye|, 1))", result.camera_origin),
    ]
    hits = [
        *[(name, str(value)) for name, value in result.counts.items()],
        ("depth: relative difference / 2^-24", result.depth_relative.scaled(1 / EPS32)),
        ("depth: difference / tolerance", result.depth_ratio),
        ("normal: angle (radians)", result.normal_angle),
        ("normal: angle / tolerance", result.normal_ratio),
        *[(f"id: {name}", str(value)) for name, value in result.ids.items()],
    ]
    return "\n\n".join(
        [
            table(f"ray level, cameras: Mitsuba's primary rays against pyclray's pixel rays ({result.rays} pixels)", camera),
            table("ray level, intersections of the very same rays: pyclray.cast against Mitsuba's ray_intersect", hits),
            table("ray level, arbitration by the float64 oracle of the same rays", verdict_rows(result.verdicts)),
        ]
    )
