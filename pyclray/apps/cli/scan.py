"""`pyclray scan`: a LiDAR scan of a scene (its [lidar] or one of its [[lidars]]) to an .npz of the
range image and the point cloud, or to a PLY point cloud."""
from __future__ import annotations

import time
from pathlib import Path

from .options import BadInput, load, time_value
from .texts import EXIT_STATUS_HELP

FORMATS = (".npz", ".ply")


def run(args) -> int:
    from ...io.files import check_target
    from ...io.progress import seconds

    out, scene_path = Path(args.output), Path(args.scene)
    if out.suffix.lower() not in FORMATS:
        raise BadInput(f"-o {args.output}: expected OUT.npz (the range image and the point cloud as numpy arrays) or "
                       "OUT.ply (the point cloud); the format follows the extension")
    if out.resolve() == scene_path.resolve() or (out.exists() and scene_path.exists() and out.samefile(scene_path)):
        raise BadInput(f"-o {args.output}: is the scene file itself; give another output path")
    check_target(out)
    scene = load(args.scene)  # the scan's time is its own (a sweep starts there)
    if args.time is not None and scene.animation is None:
        raise BadInput(f"--time: {args.scene} has no [animation] table; --time scans a time of an animated scene")
    if not scene.lidars:
        raise BadInput(f"{args.scene}: the scene has no [lidar] table or [[lidars]] to scan with")
    if args.lidar is not None and args.lidar not in [lidar.name for lidar in scene.lidars]:
        names = ", ".join(lidar.name for lidar in scene.lidars)
        raise BadInput(f"--lidar {args.lidar}: no such sensor in {args.scene} (its lidars: {names})")
    from ...engine.api import scan
    from ...io.ply import write_ply, write_scan_npz

    start = time.perf_counter()
    result = scan(scene, args.lidar, args.time, precision=args.precision, device=args.device)
    spent = time.perf_counter() - start
    if out.suffix.lower() == ".ply":
        write_ply(out, result, comment=f"pyclray scan of {args.scene} ({result.lidar.describe()})")
    else:
        write_scan_npz(out, result)
    lidar = result.lidar
    print(f"scanned {args.scene} with {lidar.describe()} ({lidar.beams} x {lidar.columns}, {args.precision}, "
          f"{result.device}) in {seconds(spent)}: {len(result['ring'])} hits; wrote {out}")
    return 0


def add_command(commands) -> None:
    parser = commands.add_parser(
        "scan",
        help="scan a scene with its LiDAR to an .npz (range image and points) or a PLY point cloud",
        description="Scan SCENE with its [lidar] (or the [[lidars]] named by --lidar): every beam of every column "
        "cast from the sensor's origin (x forward, y left, z up; column 0 looks back, the columns turn clockwise "
        "seen from above). -o decides the format from its extension: OUT.npz (the range image (beams, columns): "
        "range (inf on a miss), id, label, normal, position; the points: points (sensor frame), points_world, "
        "ring, column, point_range; elevation, azimuth, time; the sensor's pose) or OUT.ply (binary PLY: x y z "
        "(world), nx ny nz, id, label, ring, column, range). With sweep = true in an animated scene each column "
        "fires at its own time across one revolution (rate, Hz).",
        epilog=EXIT_STATUS_HELP,
    )
    parser.add_argument("scene", metavar="SCENE", help="scene file (TOML) with a [lidar] table or [[lidars]]")
    parser.add_argument("-o", "--output", required=True, metavar="OUT.npz|OUT.ply",
                        help="the file to write; its extension decides the format (.npz or .ply)")
    parser.add_argument("--lidar", metavar="NAME", help="the [[lidars]] entry to scan with (default: the first)")
    parser.add_argument("--time", type=time_value, metavar="T",
                        help="the time (seconds) of the scene's [animation] the revolution starts at (default 0)")
    parser.add_argument("--precision", choices=("fp32", "fp64"), default="fp32", help="cast precision (default fp32)")
    parser.add_argument("--device", metavar="DEV",
                        help="OpenCL device: P:D indices (see `pyclray devices`) or part of its name")
    parser.set_defaults(run=run)
