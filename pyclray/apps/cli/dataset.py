"""`pyclray dataset`: many views of one scene written as a data set (BOP with COCO annotations, or
an .npz/.exr per view), resumable, here or on a Dask cluster (pyclray.io.dataset)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from .options import (BadInput, add_cluster_options, aov_list, cluster_module, count, image_size, load, positive, seed,
                      time_value)
from .texts import EXIT_STATUS_HELP


def _range(text: str, what: str, low=None, high=None) -> tuple[float, float]:
    """A number R (the range R:R) or MIN:MAX, MIN <= MAX, within [low, high]."""
    try:
        parts = [float(p) for p in text.split(":")] if ":" in text else [float(text)] * 2
        if len(parts) != 2 or not all(p == p and abs(p) != float("inf") for p in parts) or parts[0] > parts[1]:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what} as a number or MIN:MAX (MIN <= MAX), got {text!r}") from None
    if (low is not None and parts[0] < low) or (high is not None and parts[1] > high):
        raise argparse.ArgumentTypeError(f"expected {what} within {low:g}..{high:g}, got {text!r}")
    return parts[0], parts[1]


def radius_range(text: str) -> tuple[float, float]:
    value = _range(text, "a radius (scene units)")
    if value[0] <= 0:
        raise argparse.ArgumentTypeError(f"expected a radius > 0, got {text!r}")
    return value


def elevation_range(text: str) -> tuple[float, float]:
    return _range(text, "an elevation in degrees", -90.0, 90.0)


def add_command(commands) -> None:
    parser = commands.add_parser(
        "dataset",
        help="render many views of a scene as a data set (BOP + COCO, or .npz/.exr per view), resumable",
        description="Render N views of SCENE looking at its labelled shapes (or at the cameras of --poses) and write "
        "them into the folder OUT/: --format bop (BOP's layout: OUT/models/, OUT/camera.json and the scene "
        "OUT/train/000000/ with rgb/, depth/, mask/, mask_visib/, scene_camera.json, scene_gt.json, "
        "scene_gt_info.json and the COCO annotations scene_gt_coco.json; objects are the shapes with a label, "
        "obj_id = label), or --format npz|exr (OUT/NNNNNN.npz or .exr per view with every --aov image, K, pose and "
        "extrinsic, and OUT/views.json). Resumable: a rerun with the same options renders only the views not yet "
        "complete and never rewrites a complete one; a killed run leaves no half-written view.",
        epilog=EXIT_STATUS_HELP,
    )
    parser.add_argument("scene", metavar="SCENE", help="scene file (TOML, or Mitsuba 3 XML)")
    parser.add_argument("-o", "--output", required=True, metavar="OUT/", help="the data set's folder (new, empty, or a run to resume)")
    parser.add_argument("--views", type=count, metavar="N", help="how many views (default: every pose of --poses)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--poses", metavar="FILE.json", help="a JSON list of 4x4 camera-to-world poses (OpenCV axes: x right, "
                       "y down, z forward) or of objects {\"K\": 3x3, \"pose\": 4x4}")
    where.add_argument("--orbit", action="store_true", help="N views evenly around the labelled shapes' centre, at the "
                       "middle of --elevation")
    where.add_argument("--hemisphere", action="store_true", help="N random views (--seed) over the zone of --elevation "
                       "around the labelled shapes' centre (the default)")
    parser.add_argument("--radius", type=radius_range, metavar="R|MIN:MAX",
                        help="distance from the centre, scene units (default: the scene camera's)")
    parser.add_argument("--elevation", type=elevation_range, metavar="MIN:MAX",
                        help="degrees above the horizon (orthogonal to the scene camera's up), default 10:80")
    parser.add_argument("--seed", type=seed, default=0, metavar="S", help="the hemisphere's random seed (default 0)")
    parser.add_argument("--format", choices=("bop", "npz", "exr"), default="bop", help="default bop")
    parser.add_argument("--aov", type=aov_list, metavar="LIST", help="npz/exr: the images of each view (default depth,normal,id)")
    parser.add_argument("--unit", type=positive, default=1.0, metavar="M", help="bop: metres per scene unit (default 1)")
    parser.add_argument("--depth-scale", type=positive, default=1.0, metavar="S",
                        help="bop: mm per level of the depth PNGs (default 1: depths up to 65.535 m)")
    parser.add_argument("--time", type=time_value, metavar="T", help="render the scene at time T (seconds) of its "
                        "[animation] (default 0 for an animated scene); flow goes to T + 1/fps")
    parser.add_argument("--size", type=image_size, metavar="WxH", help="override the scene's image size")
    parser.add_argument("--precision", choices=("fp32", "fp64"), default="fp32", help="kernel precision (default fp32)")
    parser.add_argument("--device", metavar="DEV", help="OpenCL device (as for pyclray render)")
    parser.add_argument("--writers", type=count, metavar="N", help="threads encoding and writing files (default: cores, 2 to 8)")
    add_cluster_options(parser, "the views")
    parser.set_defaults(run=run)


def _digest(path) -> str:
    """The scene file's SHA-256: a resumed run must render the same scene."""
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _placement(args):
    from ...io.dataset import Placement
    from ...io.dataset.placement import DEFAULT_ELEVATION

    kind = "poses" if args.poses else "orbit" if args.orbit else "hemisphere"
    if args.poses and (args.radius or args.elevation):
        raise BadInput(f"--{'radius' if args.radius else 'elevation'}: the cameras of --poses are placed by the file")
    return Placement(kind, args.radius, args.elevation or DEFAULT_ELEVATION, args.seed,
                     str(Path(args.poses).resolve()) if args.poses else None)


def run(args) -> int:
    from ...engine.queries.motion import Motion
    from ...io.dataset import make_format, read_poses, view_cameras, write_dataset
    from ...io.progress import progress, seconds
    from ...model.errors import RequestError

    # every option first: a mistake costs no scene read, no device and writes nothing
    if args.views is None and not args.poses:
        raise BadInput("--views: how many views? (--views N; only --poses may leave it out: then every pose)")
    if args.aov and args.format == "bop":
        raise BadInput("--aov: --format bop writes its own images (rgb, depth, masks); --aov is for npz and exr")
    if args.format != "bop" and (args.unit != 1.0 or args.depth_scale != 1.0):
        raise BadInput(f"--{'unit' if args.unit != 1.0 else 'depth-scale'}: only --format bop has it")
    placement = _placement(args)
    out = Path(args.output)
    on_cluster = args.workers is not None or args.scheduler is not None
    cluster = cluster_module() if on_cluster else None
    try:
        fmt = make_format(args.format, args.aov, args.unit, args.depth_scale)
        views = args.views
        if views is None:
            views = len(read_poses(placement.poses))
        moving = load(args.scene, args.size)
        t = args.time if args.time is not None or moving.animation is None else 0.0
        if t is not None and moving.animation is None:
            raise BadInput(f"--time: {args.scene} has no [animation] table; --time renders a time of an animated scene")
        scene = moving if t is None else moving.at(t)
        motion = None
        if t is not None and "flow" in (args.aov or ()):  # the next frame's shapes; each view keeps its camera
            motion = Motion(moving.at(t + 1.0 / moving.animation.fps).shapes, None)
        cameras = view_cameras(scene, placement, views)
    except RequestError as error:
        raise BadInput(str(error)) from None
    settings = {"scene": str(Path(args.scene).resolve()), "scene_sha256": _digest(args.scene),
                "placement": placement.describe(), "time": t,
                "size": list(args.size) if args.size else None}
    start = time.perf_counter()
    where = "here"
    try:
        with progress(views, desc="pyclray dataset", unit="view") as bar:
            if on_cluster:
                with cluster.connect(args.workers, args.scheduler) as client:
                    where = cluster.describe(client)
                    written = write_dataset(scene, out, cameras, fmt, settings=settings, precision=args.precision,
                                            device=args.device, writers=args.writers, progress=bar, motion=motion,
                                            remote=lambda work, todo: cluster.map_work(client, work, todo, what="view"))
            else:
                written = write_dataset(scene, out, cameras, fmt, settings=settings, precision=args.precision,
                                        device=args.device, writers=args.writers, progress=bar, motion=motion)
    except RequestError as error:
        raise BadInput(str(error)) from None
    except Exception as error:
        if on_cluster and isinstance(error, cluster.ClusterError):
            raise BadInput(str(error)) from None
        raise
    total = time.perf_counter() - start
    rate = f"{written.rendered / total:.1f} views/s" if written.rendered else "nothing to render"
    print(
        f"dataset {args.scene}: {written.rendered} view{'s' if written.rendered != 1 else ''} of "
        f"{scene.image.width}x{scene.image.height} rendered ({where}), {written.skipped} already complete, "
        f"in {seconds(total)} ({rate}; render {seconds(written.render_seconds)}, writers busy "
        f"{seconds(written.writer_seconds)}); wrote {out} ({args.format})"
    )
    return 0
