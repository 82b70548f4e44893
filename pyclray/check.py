"""pyclray check: cross-check pyclray's float32 images against Mitsuba 3, pixel by pixel and ray by ray.

Two comparisons, both against the same scene built in Mitsuba by ``pyclray.mitsuba``:

1. Images (``cross_check``). Both render the scene (pyclray fp32, Mitsuba's aov integrator); the
   float64 oracle (``pyclray.oracle``) of the same pixel rays says, per pixel, which shape is hit,
   at what distance t and at what incidence. Depth and normals are compared where both hit the
   same shape; ids and misses everywhere, with the pixels whose disagreement the geometry
   explains counted apart.
2. Rays (``ray_level``). Mitsuba's own float32 primary rays (its sensor's ``sample_ray`` at pixel
   centres) are cast through ``pyclray.cast`` and through Mitsuba's ``ray_intersect``: first how
   far Mitsuba's camera rays are from pyclray's, then the intersections of the very same rays.

Error model (eps = 2^-24, float32's unit roundoff). A float32 intersection is the exact
intersection of a slightly moved ray: a position error of a few eps times the size of the
coordinates involved, which along the ray becomes a distance error divided by the cosine of the
incidence angle (at grazing incidence a small sideways move slides the hit far along the ray).
pyclray works in a frame centred on the eye (render) or on the rays' mean origin (cast), so its
coordinates are of size t; Mitsuba works in float32 world coordinates (the scalar variants solve
the sphere's quadratic in float64, but from float32 rays and centres), so its coordinates are of
size L = max(|eye|, |anchor|, |eye - anchor|), the anchor being the sphere's centre or the centre of
the disk standing in for a plane. On the very same rays (ray level), per ray,

    |depth difference| <= K eps (t + L) / cos              (relative: K eps (1 + L / t) / cos)
    normal angle       <= K eps (1 + (t + L) / (r cos))    (r: the sphere's radius; inf for a plane)

the normal's term being the depth error seen from the centre of a sphere of radius r. K = 6:
measured below 2.8 over 75 random scenes (random spheres and a tilted plane, moved 0, 100 and 1000
units off the world origin) in both variants; pyclray's own error against the float64 oracle is
below 3.7 eps t / cos, so 6 leaves room for Mitsuba's part too.

The images add the difference of the cameras. Mitsuba's sensor's to_world is a float32 look_at
matrix built from target - eye rounded in float32, so its ray directions differ from pyclray's
pixel rays by an angle up to

    alpha = 3 eps (1 + S),   S = max(|eye|, |target|) / |target - eye|

(the rounding of target - eye relative to its length, then the matrix product and the
normalization; measured 3.3 eps on tp02, where the bound is 6 eps; at most 2.1 eps (1 + S) over the
random scenes), and its origins, the eye rounded to float32 and moved to the near-clip plane, lie
within 2 eps max(|eye|, 1) of pyclray's rays (measured 1.6). A direction off by alpha moves the hit
sideways by t alpha, so per pixel

    |depth difference| <= eps (K (t + L) + 3 (1 + S) t + 2 max(|eye|, 1)) / cos = D
    normal angle       <= eps K + D / r

(measured: below 0.33 of these over the random scenes; without the camera term, scenes 1000 units
off the origin exceed K eps (t + L) / cos by a factor of 1.9).

Where the model ends: at silhouettes (|cos incidence| < 0.02 per the oracle) the 1/cos growth
turns into a square-root law at exact tangency and a ray may graze either shape; pixels next to
an id change may see a different shape through a few-ulp move of their ray; and where the
oracle's two nearest shapes are within the depth tolerance (near ties) either may win. These
pixels are counted apart, not judged; any other disagreement of ids or misses fails the check.
Pixels whose ray meets a plane beyond its stand-in disk's edge (``plane_beyond_disk``) are left
out of everything and counted.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

EPSILON = 2.0**-24  # float32 unit roundoff: half an ulp of 1
K = 6.0  # intersections of the same ray: the error model's K (see the module's docstring)
CAMERA_K = 3.0  # camera rays: angle <= CAMERA_K eps (1 + max(|eye|, |target|) / |target - eye|)
ORIGIN_K = 2.0  # camera rays: origin off our ray <= ORIGIN_K eps max(|eye|, 1)
SILHOUETTE_COS = 0.02  # |cos incidence| below this is a silhouette pixel
VARIANTS = ("scalar_rgb", "llvm_ad_rgb")
DEFAULT_RAYS = 1024


# -- the error model -----------------------------------------------------------------------------
def coordinate_scales(scene) -> np.ndarray:
    """L per shape id: the size of the float32 world coordinates Mitsuba intersects that shape in,
    max(|eye|, |anchor|, |eye - anchor|), the anchor being a sphere's centre or a plane's disk centre."""
    from .mitsuba import plane_disk

    eye = np.array(scene.camera.eye)
    scales = np.zeros(max(len(scene.shapes), 1))
    for index, shape in enumerate(scene.shapes):
        anchor = np.array(shape.center) if shape.type == "sphere" else plane_disk(shape, scene)[0]
        scales[index] = max(np.linalg.norm(eye), np.linalg.norm(anchor), np.linalg.norm(eye - anchor))
    return scales


def radii(scene) -> np.ndarray:
    """The radius of curvature per shape id (inf for a plane)."""
    return np.array([getattr(shape, "radius", np.inf) for shape in scene.shapes] or [np.inf])


def camera_angle_tolerance(scene) -> float:
    """alpha: how far (radians) Mitsuba's float32 look_at camera rays may be from pyclray's."""
    eye, target = np.array(scene.camera.eye), np.array(scene.camera.target)
    return CAMERA_K * EPSILON * (1 + max(np.linalg.norm(eye), np.linalg.norm(target)) / np.linalg.norm(target - eye))


def tolerances(scene, t, ids, cos, *, cameras: bool, origin_scale=None):
    """(depth tolerance, normal angle tolerance in radians) per ray, from the error model.

    t: the oracle's distance, ids: the oracle's shape ids (>= 0 where used), cos: |cos incidence|;
    cameras: add the difference of the two cameras' rays (images; not for the very same rays);
    origin_scale: the size of the rays' origins if they are not the eye (ray level)."""
    index = np.maximum(ids, 0)
    scale = coordinate_scales(scene)[index]
    if origin_scale is not None:
        scale = np.maximum(scale, origin_scale)
    t = np.where(np.isfinite(t), t, 0.0)
    reach = K * EPSILON * (t + scale)  # a position error, in scene units
    if cameras:
        eye = np.linalg.norm(scene.camera.eye)
        reach = reach + camera_angle_tolerance(scene) * t + ORIGIN_K * EPSILON * max(eye, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        depth = reach / cos
        normal = K * EPSILON + depth / radii(scene)[index]
    return depth, normal


def angle_between(a, b) -> np.ndarray:
    """Angle in radians between vectors (last axis), accurate for tiny angles (atan2 of the cross
    and dot products; arccos of the dot product loses half the digits near 0)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.einsum("...k,...k", a, b))


def near_ties(scene, origins, directions, nearest, tolerance) -> np.ndarray:
    """Rays whose second-nearest shape (float64 oracle) lies within the tolerance of the nearest."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(nearest) & (second_nearest(scene, origins, directions) - nearest <= tolerance)


def second_nearest(scene, origins, directions) -> np.ndarray:
    """The oracle's distance to the second-nearest shape along each ray (inf if none)."""
    shape = directions.shape[:-1]
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    distances = np.full((2, len(d)), np.inf)
    for item in scene.shapes:
        t = item.oracle_distance(o, d)
        distances = np.sort(np.vstack([distances, t[None]]), axis=0)[:2]
    return distances[1].reshape(shape)


def next_to_id_change(ids: np.ndarray) -> np.ndarray:
    """Pixels with a differently-identified pixel among their 8 neighbours."""
    padded = np.pad(ids, 1, mode="edge")
    height, width = ids.shape
    out = np.zeros(ids.shape, bool)
    for dj in (-1, 0, 1):
        for di in (-1, 0, 1):
            out |= padded[1 + dj : 1 + dj + height, 1 + di : 1 + di + width] != ids
    return out


# -- summaries -----------------------------------------------------------------------------------
@dataclass
class Summary:
    """max, 99th percentile and median of a set of values (nan when empty)."""

    count: int
    max: float
    p99: float
    median: float

    @classmethod
    def of(cls, values) -> "Summary":
        values = np.asarray(values, np.float64).ravel()
        if values.size == 0:
            return cls(0, math.nan, math.nan, math.nan)
        return cls(values.size, float(values.max()), float(np.percentile(values, 99)), float(np.median(values)))


def _number(value: float) -> str:
    if math.isnan(value):
        return "-"
    if value == 0:
        return "0"
    return f"{value:.3g}" if 1e-3 <= abs(value) < 1e4 else f"{value:.2e}"


def table(title: str, rows, header=("", "max", "p99", "median")) -> str:
    """A plain text table: rows of (label, Summary) or (label, text)."""
    lines = [title]
    cells = []
    for label, value in rows:
        if isinstance(value, Summary):
            cells.append((label, _number(value.max), _number(value.p99), _number(value.median)))
        else:
            cells.append((label, str(value)))
    widths = [max(len(header[0]), *(len(c[0]) for c in cells))] + [11, 11, 11]
    header_done = False
    for c in cells:
        if len(c) == 4 and not header_done:
            lines.append("  " + header[0].ljust(widths[0]) + "".join(h.rjust(w) for h, w in zip(header[1:], widths[1:])))
            header_done = True
        if len(c) == 4:
            lines.append("  " + c[0].ljust(widths[0]) + "".join(v.rjust(w) for v, w in zip(c[1:], widths[1:])))
        else:
            lines.append("  " + c[0].ljust(widths[0]) + "  " + c[1])
    return "\n".join(lines)


# -- images --------------------------------------------------------------------------------------
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

    @property
    def passed(self) -> bool:
        return not self.failures


def _disagreement_kinds(disagree, silhouette, adjacent, near_tie) -> dict:
    """Each disagreeing pixel counted once, under the first reason that explains it."""
    left = disagree.copy()
    out = {}
    for name, reason in (("silhouette", silhouette), ("next to an id change", adjacent), ("near tie", near_tie)):
        out[name] = int((left & reason).sum())
        left &= ~reason
    out["unexplained"] = int(left.sum())
    return out


def cross_check(scene, variant: str = "scalar_rgb", device=None, mitsuba_scene=None) -> ImageCheck:
    """Render the scene with pyclray (fp32) and Mitsuba and compare the images (see the docstring).

    mitsuba_scene: the scene Mitsuba renders, if not the same one (tests pass a slightly moved
    scene to see the check fail)."""
    from . import mitsuba, oracle
    from .progress import step
    from .render import render

    step("pyclray render")
    ours = render(scene, precision="fp32", device=device)
    step(f"Mitsuba {variant} render")
    theirs = mitsuba.render(scene if mitsuba_scene is None else mitsuba_scene, variant)
    step("float64 oracle")
    origins, directions = oracle.camera_rays(scene)
    truth = oracle.trace(scene, origins, directions)
    cos = oracle.incidence_cosine(scene, directions, truth["id"], truth["normal"])
    depth_tolerance, normal_tolerance = tolerances(scene, truth["depth"], truth["id"], cos, cameras=True)

    # the pixels each comparison covers
    beyond_disk = mitsuba.plane_beyond_disk(scene, origins, directions)
    silhouette = (truth["id"] >= 0) & (cos < SILHOUETTE_COS) & ~beyond_disk
    same = (ours["id"] == theirs["id"]) & (ours["id"] >= 0) & ~beyond_disk
    judged = same & ~silhouette
    both_miss = (ours["id"] < 0) & (theirs["id"] < 0) & ~beyond_disk

    # depth: distance from the eye
    with np.errstate(invalid="ignore", divide="ignore"):
        difference = np.abs(ours["depth"].astype(np.float64) - theirs["depth"])
        relative = np.where(same, difference / truth["depth"], np.nan)
        depth_ratio = difference / depth_tolerance
    # normals: angle between pyclray's and Mitsuba's geometric normals
    angle = angle_between(ours["normal"], theirs["normal"])

    # ids and misses: explained disagreements counted apart
    disagree = (ours["id"] != theirs["id"]) & ~beyond_disk
    near_tie = near_ties(scene, origins, directions, truth["depth"], depth_tolerance)
    adjacent = next_to_id_change(truth["id"]) | next_to_id_change(ours["id"])
    id_disagree = disagree & (ours["id"] >= 0) & (theirs["id"] >= 0)
    ours_only = disagree & (ours["id"] >= 0) & (theirs["id"] < 0)
    theirs_only = disagree & (ours["id"] < 0) & (theirs["id"] >= 0)

    counts = {
        "pixels": ours["id"].size,
        "both hit the same shape": int(same.sum()),
        "  of which judged": int(judged.sum()),
        "  of which silhouettes (apart)": int((same & silhouette).sum()),
        "both miss": int(both_miss.sum()),
        "plane beyond its disk (left out)": int(beyond_disk.sum()),
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
        ids={"agree": int((~disagree & ~beyond_disk).sum()), **_disagreement_kinds(id_disagree, silhouette, adjacent, near_tie)},
        misses={
            "pyclray hits, Mitsuba misses": _disagreement_kinds(ours_only, silhouette, adjacent, near_tie),
            "pyclray misses, Mitsuba hits": _disagreement_kinds(theirs_only, silhouette, adjacent, near_tie),
        },
        images={"ours": ours, "theirs": theirs, "relative": relative, "judged": judged, "outside": judged & (depth_ratio > 1)},
    )
    # the verdict
    if result.depth_ratio.count and result.depth_ratio.max > 1:
        result.failures.append(f"depth outside the tolerance at {int((judged & (depth_ratio > 1)).sum())} pixels")
    if result.normal_ratio.count and result.normal_ratio.max > 1:
        result.failures.append(f"normal outside the tolerance at {int((judged & (angle > normal_tolerance)).sum())} pixels")
    if result.ids["unexplained"]:
        result.failures.append(f"{result.ids['unexplained']} unexplained id disagreements")
    for name, kinds in result.misses.items():
        if kinds["unexplained"]:
            result.failures.append(f"{kinds['unexplained']} unexplained pixels where {name}")
    return result


def tolerance_text() -> list[str]:
    """The error model's tolerances, as printed by the command."""
    return [
        "tolerances (eps = 2^-24; t = distance, cos = |cos incidence| from the float64 oracle, r = sphere radius,",
        "  L = max(|eye|, |anchor|, |eye - anchor|): the size of the float32 world coordinates Mitsuba works in,",
        "  anchor = sphere centre or the plane's disk centre; S = max(|eye|, |target|) / |target - eye|):",
        f"  same rays: |depth difference| <= {K:g} eps (t + L) / cos, normal angle <= {K:g} eps (1 + (t + L) / (r cos))",
        f"  cameras:   direction angle <= alpha = {CAMERA_K:g} eps (1 + S), origin off our ray <= {ORIGIN_K:g} eps max(|eye|, 1)",
        f"  images:    |depth difference| <= D = eps ({K:g} (t + L) + {CAMERA_K:g} (1 + S) t + {ORIGIN_K:g} max(|eye|, 1)) / cos,"
        f" normal angle <= {K:g} eps + D / r",
        f"  not judged: silhouettes (|cos| < {SILHOUETTE_COS:g}), and for ids also pixels next to an id change and near ties",
    ]


def format_image_check(result: ImageCheck) -> str:
    counts = [(name, str(value)) for name, value in result.counts.items()]
    depth = [
        ("absolute (scene units)", result.depth_absolute),
        ("relative", result.depth_relative),
        ("relative / 2^-24", _scaled(result.depth_relative, 1 / EPSILON)),
        ("difference / tolerance", result.depth_ratio),
        ("silhouettes: difference / tolerance (not judged)", result.silhouette_depth_ratio),
    ]
    normal = [
        ("angle (radians)", result.normal_angle),
        ("angle / 2^-24", _scaled(result.normal_angle, 1 / EPSILON)),
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
        table("id: pixels where neither is beyond a disk; disagreements by the first reason that explains them", ids),
        table("misses: one hits, the other does not", misses),
    ]
    return "\n\n".join(parts)


def _scaled(summary: Summary, factor: float) -> Summary:
    return Summary(summary.count, summary.max * factor, summary.p99 * factor, summary.median * factor)


# -- rays ----------------------------------------------------------------------------------------
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

    @property
    def passed(self) -> bool:
        return not self.failures


def ray_level(
    scene, variant: str = "scalar_rgb", n_rays: int = DEFAULT_RAYS, seed: int = 0, device=None, mitsuba_scene=None
) -> RayCheck:
    """Cast Mitsuba's own primary rays of n_rays pixels (chosen with this seed) through pyclray.cast
    and through Mitsuba's ray_intersect; compare the cameras and the intersections of those rays.

    mitsuba_scene: the scene Mitsuba intersects, if not the same one (for tests)."""
    from . import mitsuba, oracle
    from .render import cast

    width, height = scene.image.width, scene.image.height
    rng = np.random.default_rng(seed)
    flat = np.sort(rng.choice(width * height, size=min(n_rays, width * height), replace=False))
    rows, columns = np.divmod(flat, width)

    mitsuba.import_mitsuba(variant)
    mi_scene, ids = mitsuba.load(scene if mitsuba_scene is None else mitsuba_scene, variant)
    origins, directions = mitsuba.primary_rays(mi_scene, scene, rows, columns)

    # the cameras: Mitsuba's rays against pyclray's pixel rays (float64 oracle)
    eye = np.array(scene.camera.eye)
    _, pixel_directions = oracle.camera_rays(scene)
    ours_directions = pixel_directions[rows, columns]
    offset = origins - eye
    sideways = offset - np.einsum("nk,nk->n", offset, ours_directions)[:, None] * ours_directions
    camera_angle = angle_between(directions, ours_directions)
    camera_origin = np.linalg.norm(sideways, axis=1) / (EPSILON * max(np.linalg.norm(eye), 1.0))
    camera_tolerance = camera_angle_tolerance(scene)

    # the same rays through both
    theirs = mitsuba.intersect(mi_scene, ids, origins, directions)
    ours = cast(scene, origins, directions, precision="fp32", device=device)
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    truth = oracle.trace(scene, origins, unit)
    cos = oracle.incidence_cosine(scene, unit, truth["id"], truth["normal"])
    depth_tolerance, normal_tolerance = tolerances(
        scene, truth["depth"], truth["id"], cos, cameras=False, origin_scale=np.linalg.norm(origins, axis=1)
    )
    beyond_disk = mitsuba.plane_beyond_disk(scene, origins, unit)
    silhouette = (truth["id"] >= 0) & (cos < SILHOUETTE_COS) & ~beyond_disk
    same = (ours["id"] == theirs["id"]) & (ours["id"] >= 0) & ~beyond_disk
    judged = same & ~silhouette
    with np.errstate(invalid="ignore", divide="ignore"):
        difference = np.abs(ours["depth"].astype(np.float64) - theirs["depth"])
        relative = difference / truth["depth"]
        depth_ratio = difference / depth_tolerance
    angle = angle_between(ours["normal"], theirs["normal"])
    disagree = (ours["id"] != theirs["id"]) & ~beyond_disk
    near_tie = near_ties(scene, origins, unit, truth["depth"], depth_tolerance)
    kinds = {"agree": int((~disagree & ~beyond_disk).sum())}
    left = disagree.copy()
    for name, reason in (("silhouette", silhouette), ("near tie", near_tie)):
        kinds[name] = int((left & reason).sum())
        left &= ~reason
    kinds["unexplained"] = int(left.sum())

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
            "both miss": int(((ours["id"] < 0) & (theirs["id"] < 0) & ~beyond_disk).sum()),
            "plane beyond its disk (left out)": int(beyond_disk.sum()),
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
    if result.depth_ratio.count and result.depth_ratio.max > 1:
        result.failures.append(f"ray level: depth outside the tolerance on {int((judged & (depth_ratio > 1)).sum())} rays")
    if result.normal_ratio.count and result.normal_ratio.max > 1:
        result.failures.append(f"ray level: normal outside the tolerance on {int((judged & (angle > normal_tolerance)).sum())} rays")
    if kinds["unexplained"]:
        result.failures.append(f"ray level: {kinds['unexplained']} unexplained id or miss disagreements")
    return result


def format_ray_check(result: RayCheck) -> str:
    camera = [
        ("direction angle (radians)", result.camera_angle),
        ("direction angle / 2^-24", _scaled(result.camera_angle, 1 / EPSILON)),
        ("direction angle / tolerance", _scaled(result.camera_angle, 1 / result.camera_tolerance)),
        ("origin off our ray / (2^-24 max(|eye|, 1))", result.camera_origin),
    ]
    hits = [
        *[(name, str(value)) for name, value in result.counts.items()],
        ("depth: relative difference / 2^-24", _scaled(result.depth_relative, 1 / EPSILON)),
        ("depth: difference / tolerance", result.depth_ratio),
        ("normal: angle (radians)", result.normal_angle),
        ("normal: angle / tolerance", result.normal_ratio),
        *[(f"id: {name}", str(value)) for name, value in result.ids.items()],
    ]
    return "\n\n".join(
        [
            table(f"ray level, cameras: Mitsuba's primary rays against pyclray's pixel rays ({result.rays} pixels)", camera),
            table("ray level, intersections of the very same rays: pyclray.cast against Mitsuba's ray_intersect", hits),
        ]
    )


# -- files ---------------------------------------------------------------------------------------
HEAT_LOW, HEAT_HIGH = -9.0, -4.0  # log10 of the relative depth difference at the two ends of the ramp
_RAMP = np.array(
    [[0, 0, 96], [0, 96, 255], [0, 208, 160], [160, 224, 0], [255, 160, 0], [224, 0, 0]], np.float64
)


def heat_map(relative: np.ndarray, judged: np.ndarray, outside: np.ndarray) -> np.ndarray:
    """RGB uint8: log10 of the relative depth difference from 1e-9 (dark blue) to 1e-4 (red), a zero
    difference dark blue; white where outside the tolerance; black where not compared."""
    with np.errstate(divide="ignore", invalid="ignore"):
        level = (np.log10(np.where(judged, relative, np.nan)) - HEAT_LOW) / (HEAT_HIGH - HEAT_LOW)
    level = np.clip(np.nan_to_num(level, nan=0.0, neginf=0.0), 0.0, 1.0) * (len(_RAMP) - 1)
    low = np.floor(level).astype(int).clip(0, len(_RAMP) - 2)
    weight = (level - low)[..., None]
    rgb = (1 - weight) * _RAMP[low] + weight * _RAMP[low + 1]
    rgb[~judged] = 0
    rgb[outside] = 255
    return np.round(rgb).astype(np.uint8)


def save(result: ImageCheck, folder: Path, stem: str) -> list[Path]:
    """Write both renders as EXR and the depth-difference heat map as PNG; return the paths."""
    from .output import write_exr, write_png, write_together

    ours, theirs = result.images["ours"], result.images["theirs"]
    paths = [
        folder / f"{stem}.pyclray.exr",
        folder / f"{stem}.mitsuba-{result.variant}.exr",
        folder / f"{stem}.depth-error.png",
    ]
    heat = heat_map(result.images["relative"], result.images["judged"], result.images["outside"])
    return write_together([  # the three files replaced together or not at all
        (paths[0], lambda tmp: write_exr(tmp, ours, comment="pyclray fp32 render (pyclray check)")),
        (paths[1], lambda tmp: write_exr(tmp, {k: theirs[k] for k in ("depth", "normal", "id")},
                                         comment=f"Mitsuba {result.variant} render in pyclray's conventions (pyclray check)")),
        (paths[2], lambda tmp: write_png(tmp, heat)),
    ])


# -- command line --------------------------------------------------------------------------------
def add_command(subparsers) -> None:
    from .cli import _size

    parser = subparsers.add_parser(
        "check",
        help="cross-check pyclray's images against Mitsuba 3 (exit 1 outside the tolerance)",
        description="Render SCENE with pyclray (fp32) and Mitsuba 3 and print one table per image "
        "(depth, normal, id, misses), the ray-level comparison (Mitsuba's own primary rays cast "
        "through both) and the shaded image against Mitsuba's direct integrator. Exit status 0 within the tolerance of the error model (printed), 1 outside it, "
        "2 on bad input.",
    )
    parser.add_argument("scene", metavar="SCENE", help="scene file (TOML)")
    parser.add_argument("--variant", choices=VARIANTS, default="scalar_rgb", help="Mitsuba variant (default scalar_rgb)")
    parser.add_argument("--size", type=_size, metavar="WxH", help="override the scene's image size")
    parser.add_argument("--rays", type=int, default=DEFAULT_RAYS, metavar="N",
                        help=f"pixels in the ray-level comparison (default {DEFAULT_RAYS})")
    parser.add_argument("--seed", type=int, default=0, help="seed choosing the ray-level pixels (default 0)")
    parser.add_argument("--save", metavar="DIR",
                        help="write DIR/NAME.pyclray.exr, DIR/NAME.mitsuba-VARIANT.exr and DIR/NAME.depth-error.png "
                        "(log10 relative depth difference, 1e-9 dark blue to 1e-4 red, white outside the "
                        "tolerance, black where not compared)")
    parser.add_argument("--device", metavar="DEV", help="OpenCL device (as for pyclray render)")
    parser.set_defaults(run=run)


def run(args) -> int:
    from .cli import BadInput, _load

    if args.rays < 1:
        raise BadInput(f"--rays: expected a whole number >= 1, got {args.rays}")
    folder = None
    if args.save is not None:
        folder = Path(args.save)
        if folder.exists() and not folder.is_dir():
            raise BadInput(f"--save {folder}: is not a folder")
        if not folder.parent.is_dir():
            raise BadInput(f"--save {folder}: the folder {folder.parent} does not exist")
    scene = _load(args.scene, args.size)
    try:
        from .mitsuba import import_mitsuba

        mi = import_mitsuba(args.variant)
    except (ImportError, ValueError) as error:
        raise BadInput(str(error)) from None

    from .progress import step, steps

    with steps(5, desc="pyclray check"):
        images = cross_check(scene, args.variant, device=args.device)
        step("ray level")
        rays = ray_level(scene, args.variant, args.rays, args.seed, device=args.device)
        step("shaded")
        from .shaded_check import cross_check_shaded, format_shaded_check

        shaded = cross_check_shaded(scene, args.variant, device=args.device) if scene.shading.shadows else None
    print(
        f"pyclray check {args.scene}: {images.width}x{images.height}, pyclray fp32 on {images.device} "
        f"against Mitsuba {mi.__version__} {args.variant}"
    )
    print("\n".join(tolerance_text()))
    print()
    print(format_image_check(images))
    print()
    print(format_ray_check(rays))
    print()
    print(format_shaded_check(shaded) if shaded else "shaded: not compared (shadows = false; Mitsuba's direct integrator always casts them)")
    if folder is not None:
        folder.mkdir(exist_ok=True)
        written = save(images, folder, Path(args.scene).stem)
        print()
        print("wrote " + ", ".join(map(str, written)))
    failures = images.failures + rays.failures + (shaded.failures if shaded else [])
    print()
    if failures:
        print("FAILED: " + "; ".join(failures))
        return 1
    print("passed: within the tolerance")
    return 0
