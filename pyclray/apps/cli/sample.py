"""`pyclray sample`: training data for signed distance functions and occupancy networks (DeepSDF,
Occupancy Networks): points in the scene's bounds and near its surfaces with their signed distance,
occupancy, nearest surface point, normal and shape id, in one .npz file."""
from __future__ import annotations

import argparse
from pathlib import Path

from .options import BadInput, count, positive, seed

# the bounds' margin on each side, a share of their largest side (DeepSDF samples a box a little
# larger than the shape)
MARGIN = 0.05
# points per query (the progress bar's step)
CHUNK = 1 << 16


def _sigma(text: str) -> float:
    return positive(text, "a distance > 0 (scene units)")


def add_command(subparsers) -> None:
    parser = subparsers.add_parser(
        "sample",
        help="write points with their signed distance, occupancy, nearest point and normal (SDF training data)",
        description="Write N points of SCENE to an .npz file with, for each, its signed distance (negative inside "
        "a solid), occupancy (1 inside or on a surface), nearest surface point, that surface's normal and shape id: "
        "training data for signed distance functions and occupancy networks. The points are uniform in the "
        "bounded shapes' box (5%% larger on each side); with --near-surface SIGMA, half of them are instead "
        "points of the surfaces (the nearest surface points of uniform points) moved by a normal random offset "
        "of standard deviation SIGMA along each axis, as DeepSDF samples.",
    )
    parser.add_argument("scene", metavar="SCENE", help="scene file (TOML or Mitsuba XML)")
    parser.add_argument("-o", "--output", required=True, metavar="OUT.npz", help="the .npz file to write")
    parser.add_argument("--points", type=count, required=True, metavar="N", help="how many points")
    parser.add_argument("--near-surface", type=_sigma, metavar="SIGMA",
                        help="half the points jittered about the surfaces by this standard deviation (scene units)")
    parser.add_argument("--seed", type=seed, default=0, metavar="S", help="the random generator's seed (default 0)")
    parser.add_argument("--sign", choices=("parity", "winding"), default="parity",
                        help="how a mesh's inside is decided: parity (closed meshes) or winding (any mesh)")
    parser.add_argument("--precision", choices=("fp32", "fp64"), default="fp32",
                        help="the nearest points' precision (distances are float64 either way)")
    parser.add_argument("--device", metavar="DEV", help="the OpenCL device (see pyclray devices)")
    parser.set_defaults(run=run)


def bounds(scene):
    """(lo, hi): the bounded shapes' box, MARGIN larger on each side; a BadInput without any."""
    import numpy as np

    boxes = [np.asarray(shape.box(), np.float64) for shape in scene.shapes if type(shape).bounded]
    if not boxes:
        raise BadInput(f"{scene.source or 'the scene'}: no bounded shape (only planes): no box to sample points in")
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    margin = MARGIN * float(np.max(hi - lo))
    if margin == 0:  # a single point or a flat box: a margin of the box's own scale
        margin = MARGIN * max(float(np.max(np.abs(lo))), 1.0)
    return lo - margin, hi + margin


def sample_points(tracer, lo, hi, count_: int, sigma, rng):
    """count_ points: uniform in [lo, hi], or (with sigma) half of them the nearest surface points of
    uniform points, moved by a normal offset of sigma per axis."""
    import numpy as np

    near = count_ // 2 if sigma is not None else 0
    uniform = rng.uniform(lo, hi, (count_ - near, 3))
    if not near:
        return uniform
    seeds = rng.uniform(lo, hi, (near, 3))
    on = np.empty_like(seeds)
    for start in range(0, near, CHUNK):
        on[start:start + CHUNK] = tracer.closest_points(seeds[start:start + CHUNK])["position"]
    return np.concatenate([uniform, on + rng.normal(scale=sigma, size=on.shape)])


def run(args) -> int:
    out = Path(args.output)
    if out.suffix.lower() != ".npz":
        raise BadInput(f"-o {args.output}: expected OUT.npz")
    import numpy as np

    from ...engine.tracer import prepare
    from ...io.files import check_target, replace_together
    from ...io.progress import progress
    from .options import load

    check_target(out)
    scene = load(args.scene)
    lo, hi = bounds(scene)
    rng = np.random.default_rng(args.seed)
    with prepare(scene, device=args.device, precision=args.precision) as tracer:
        points = sample_points(tracer, lo, hi, args.points, args.near_surface, rng)
        n = len(points)
        real = np.float64 if args.precision == "fp64" else np.float32
        arrays = {"points": points, "sdf": np.empty(n), "occupancy": np.empty(n, np.uint8),
                  "closest": np.empty((n, 3), real), "normal": np.empty((n, 3), real), "id": np.empty(n, np.int32)}
        with progress(n, desc="sample", unit="point") as bar:
            for start in range(0, n, CHUNK):
                part = points[start:start + CHUNK]
                nearest = tracer.closest_points(part)
                sd = tracer.signed_distance(part, sign=args.sign)
                rows = slice(start, start + len(part))
                arrays["sdf"][rows] = sd
                arrays["occupancy"][rows] = sd <= 0  # inside, or on a surface (distance 0)
                arrays["closest"][rows] = nearest["position"]
                arrays["normal"][rows] = nearest["normal"]
                arrays["id"][rows] = nearest["id"]
                bar.update(len(part))
    arrays["bounds"] = np.stack([lo, hi])
    with replace_together([out]) as (temporary,):
        with open(temporary, "wb") as file:
            np.savez(file, **arrays)
    inside = int(arrays["occupancy"].sum())
    print(f"wrote {out}: {n} points ({inside} inside), sign={args.sign}")
    return 0
