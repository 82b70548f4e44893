"""The image comparison: pyclray's fp32 render against Mitsuba 3's, pixel by pixel.

Both render the scene (pyclray fp32, Mitsuba's aov integrator); the float64 oracle of the same
pixel rays says, per pixel, which shape is hit, at what distance t and at what incidence. Depth
and normals are compared where both hit the same shape, away from silhouettes and edges; ids and
misses everywhere, with the pixels whose disagreement the geometry explains counted apart
(silhouettes, edges, pixels next to an id change, near ties: pyclray.reference.error_model). Tolerances:
``error_model.mitsuba_tolerances`` with the difference of the cameras.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import error_model
from ..error_model import EPSILON, angle_between
from .arbitrate import decide, verdict_rows, wrong_hits
from .summary import Summary, disagreement_kinds, table

EPS32 = EPSILON["fp32"]


def next_to_id_change(ids: np.ndarray) -> np.ndarray:
    """Pixels with a differently-identified pixel among their 8 neighbours."""
    padded = np.pad(ids, 1, mode="edge")
    height, width = ids.shape
    out = np.zeros(ids.shape, bool)
    for dj in (-1, 0, 1):
        for di in (-1, 0, 1):
            out |= padded[1 + dj : 1 + dj + height, 1 + di : 1 + di + width] != ids
    return out


@dataclass
class ImageCheck:
    """The outcome of ``cross_check``: the counts, the summaries and the verdict."""

    variant: str
    width: int
    height: int
    device: str
    counts: dict
    depth_absolute: Summary
    depth_relative: Summary
    depth_ratio: Summary  # |difference| / tolerance
    silhouette_depth_ratio: Summary
    normal_angle: Summary  # radians
    normal_ratio: Summary
    ids: dict
    misses: dict
    failures: list = field(default_factory=list)
    images: dict = field(default_factory=dict, repr=False)  # ours, mitsuba, relative error, judged
    verdicts: dict = field(default_factory=dict)  # AOV -> arbitrate.Verdicts
    truth: dict = field(default_factory=dict, repr=False)  # the oracle's pixels (the shaded check reuses them)

    @property
    def passed(self) -> bool:
        return not self.failures


def cross_check(scene, variant: str = "scalar_rgb", device=None, mitsuba_scene=None) -> ImageCheck:
    """Render the scene with pyclray (fp32) and Mitsuba and compare the images (see the docstring).

    mitsuba_scene: the scene Mitsuba renders, if not the same one (tests pass a slightly moved
    scene to see the check fail)."""
    from .. import mitsuba, oracle
    from ...engine.api import render
    from ...io.progress import step

    step("pyclray render")
    # a camera rendered by casting its rays (orthographic) makes no primitive image: none are compared
    primitives = scene.camera.rays_from_eye
    ours = render(scene, aovs=("depth", "normal", "id") + (("primitive",) if primitives else ()), precision="fp32",
                  device=device)
    if not primitives:
        ours["primitive"] = np.full(ours["id"].shape, -1, np.int32)  # (a Frame is a dict)
    step(f"Mitsuba {variant} render")
    theirs = mitsuba.render(scene if mitsuba_scene is None else mitsuba_scene, variant)
    step("float64 oracle")
    origins, directions = oracle.camera_rays(scene)
    truth = oracle.trace(scene, origins, directions, aovs=("depth", "normal", "id", "second"))
    step("comparison")
    cos = oracle.incidence_cosine(scene, directions, truth["id"], truth["normal"])
    depth_tolerance, normal_tolerance = error_model.mitsuba_tolerances(scene, truth["depth"], truth["id"], cos, cameras=True)

    # the pixels each comparison covers
    beyond = mitsuba.beyond_counterparts(scene, origins, directions)
    radius = error_model.silhouette_radii(scene)[np.maximum(truth["id"], 0)]
    silhouette = error_model.silhouettes(truth["id"], cos, depth_tolerance, radius) & ~beyond
    farthest = np.fmax.reduce([np.where(np.isfinite(d), d, 0.0) for d in (truth["depth"], ours["depth"], theirs["depth"])])
    band, _ = error_model.mitsuba_tolerances(scene, farthest, truth["id"], cos, cameras=True)
    edge = error_model.at_edges(scene, origins, directions, [(truth["id"], truth["depth"]), (ours["id"], ours["depth"]),
                                                          (theirs["id"], theirs["depth"])], band * cos) & ~beyond
    same = (ours["id"] == theirs["id"]) & (ours["id"] >= 0) & ~beyond
    judged = same & ~silhouette & ~edge
    both_miss = (ours["id"] < 0) & (theirs["id"] < 0) & ~beyond

    # depth: distance from the eye
    with np.errstate(invalid="ignore", divide="ignore"):
        difference = np.abs(ours["depth"].astype(np.float64) - theirs["depth"])
        relative = np.where(same, difference / truth["depth"], np.nan)
        depth_ratio = difference / depth_tolerance
    # normals: angle between pyclray's and Mitsuba's geometric normals
    angle = angle_between(ours["normal"], theirs["normal"])

    # ids and misses: explained disagreements counted apart
    disagree = (ours["id"] != theirs["id"]) & ~beyond
    truth["cos"] = cos
    near_tie = error_model.near_ties(truth, lambda t, ids, c: error_model.mitsuba_tolerances(scene, t, ids, c, cameras=True)[0])
    adjacent = next_to_id_change(truth["id"]) | next_to_id_change(ours["id"])
    reasons = (("silhouette", silhouette), ("edge", edge), ("next to an id change", adjacent), ("near tie", near_tie))
    id_disagree = disagree & (ours["id"] >= 0) & (theirs["id"] >= 0)
    ours_only = disagree & (ours["id"] >= 0) & (theirs["id"] < 0)
    theirs_only = disagree & (ours["id"] < 0) & (theirs["id"] >= 0)

    # primitives (a mesh's triangle: Mitsuba's prim_index) where both judge the same shape
    numbered = np.array([s.mitsuba_primitives for s in scene.shapes] or [False])[np.maximum(ours["id"], 0)] & primitives
    primitive_judged = judged & numbered
    primitive_wrong = primitive_judged & (ours["primitive"] != theirs["primitive"])
    # primitives against the float64 oracle, judged by pyclray's own edge band (error_model's
    # render_reach: camera-relative float32, a few eps of the hit's distance from the axis): far from
    # the origin Mitsuba's float32 vertices move by up to eps |v| per coordinate (1/32 at 1e6, the
    # size of a scanned mesh's triangles), its edge band covers whole triangles and it judges no
    # primitive there; pyclray's does not grow with the distance to the origin
    ref = {**truth, "cos": cos, "origins": origins, "directions": directions, "scene": scene}
    ours_apart = error_model.judged_pixels(ours, ref, "fp32")
    oracle_judged = ((ours["id"] == truth["id"]) & (ours["id"] >= 0) & ~ours_apart["silhouette"] & ~ours_apart["edge"]
                     & primitives)
    oracle_primitive = np.full(ours["id"].shape, -1, np.int64)
    for index, shape in enumerate(scene.shapes):
        mine = oracle_judged & (ours["id"] == index)
        found = shape.oracle_primitives(origins[mine], directions[mine]) if mine.any() else None
        if found is None:
            oracle_judged &= ~mine
        else:
            oracle_primitive[mine] = found
    oracle_wrong = oracle_judged & (ours["primitive"] != oracle_primitive)

    counts = {
        "pixels": ours["id"].size,
        "both hit the same shape": int(same.sum()),
        "  of which judged": int(judged.sum()),
        "  of which silhouettes (apart)": int((same & silhouette).sum()),
        "  of which at edges (apart)": int((same & edge & ~silhouette).sum()),
        "  of which primitives compared (meshes)": int(primitive_judged.sum()),
        "  of which primitives that differ": int(primitive_wrong.sum()),
        "primitives against the float64 oracle": int(oracle_judged.sum()),
        "  of which differ": int(oracle_wrong.sum()),
        "both miss": int(both_miss.sum()),
        "beyond a Mitsuba stand-in (left out)": int(beyond.sum()),
    }
    result = ImageCheck(
        variant=variant,
        width=scene.image.width,
        height=scene.image.height,
        device=ours.device,
        counts=counts,
        depth_absolute=Summary.of(difference[judged]),
        depth_relative=Summary.of(relative[judged]),
        depth_ratio=Summary.of(depth_ratio[judged]),
        silhouette_depth_ratio=Summary.of(depth_ratio[same & silhouette]),
        normal_angle=Summary.of(angle[judged]),
        normal_ratio=Summary.of((angle / normal_tolerance)[judged]),
        ids={"agree": int((~disagree & ~beyond).sum()), **disagreement_kinds(id_disagree, reasons)},
        misses={
            "pyclray hits, Mitsuba misses": disagreement_kinds(ours_only, reasons),
            "pyclray misses, Mitsuba hits": disagreement_kinds(theirs_only, reasons),
        },
        images={"ours": ours, "theirs": theirs, "relative": relative, "judged": judged, "outside": judged & (depth_ratio > 1)},
        truth=truth,
    )
    # the verdict: where they disagree, the oracle decides who is wrong (arbitrate.py); only
    # pyclray's faults fail the check
    ours_bounds = error_model.pyclray_tolerances(scene, truth, cos, origins, "fp32", scene.camera.eye)
    ours_wrong = wrong_hits(ours, truth, *ours_bounds)
    theirs_wrong = wrong_hits(theirs, truth, depth_tolerance, normal_tolerance)
    explained = silhouette | edge | adjacent | near_tie
    with np.errstate(invalid="ignore"):
        result.verdicts = {
            "depth": decide(judged & (depth_ratio > 1), ours_wrong["depth"], theirs_wrong["depth"]),
            "normal": decide(judged & (angle > normal_tolerance), ours_wrong["normal"], theirs_wrong["normal"]),
            "id (hits and misses)": decide(disagree, ours_wrong["id"], theirs_wrong["id"], explained),
        }
    for name, verdict in result.verdicts.items():
        if verdict.pyclray:
            result.failures.append(f"{name}: pyclray wrong by the float64 oracle at {verdict.pyclray} pixels "
                                   "where it disagrees with Mitsuba")
    if primitive_wrong.any():  # (the oracle has no primitive to arbitrate by)
        result.failures.append(f"{int(primitive_wrong.sum())} judged pixels where the primitive (prim_index) differs")
    if oracle_wrong.any():
        result.failures.append(f"{int(oracle_wrong.sum())} judged pixels where the primitive differs from the "
                               "float64 oracle's")
    return result


def format_image_check(result: ImageCheck) -> str:
    counts = [(name, str(value)) for name, value in result.counts.items()]
    depth = [
        ("absolute (scene units)", result.depth_absolute),
        ("relative", result.depth_relative),
        ("relative / 2^-24", result.depth_relative.scaled(1 / EPS32)),
        ("difference / tolerance", result.depth_ratio),
        ("silhouettes: difference / tolerance (not judged)", result.silhouette_depth_ratio),
    ]
    normal = [
        ("angle (radians)", result.normal_angle),
        ("angle / 2^-24", result.normal_angle.scaled(1 / EPS32)),
        ("angle / tolerance", result.normal_ratio),
    ]
    ids = [(name, str(value)) for name, value in result.ids.items()]
    misses = []
    for name, kinds in result.misses.items():
        explained = ", ".join(f"{k} {v}" for k, v in kinds.items() if k != "unexplained")
        misses.append((name, f"{sum(kinds.values())} ({explained}; unexplained {kinds['unexplained']})"))
    parts = [
        table(f"pixels ({result.width}x{result.height})", counts),
        table(f"depth: distance from the eye, over the {result.depth_ratio.count} judged pixels", depth),
        table(f"normal: angle between the geometric normals, over the {result.normal_angle.count} judged pixels", normal),
        table("id: pixels where neither is beyond a stand-in; disagreements by the first reason that explains them", ids),
        table("misses: one hits, the other does not", misses),
        table("arbitration: where pyclray and Mitsuba disagree beyond the tolerance, the float64 oracle decides "
              "(each against its own bound)", verdict_rows(result.verdicts)),
    ]
    return "\n\n".join(parts)
