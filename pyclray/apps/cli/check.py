"""`pyclray check`: pyclray's images and rays against Mitsuba 3 (pyclray.reference.check)."""
from __future__ import annotations

from pathlib import Path

from .options import BadInput, image_size, load


# the rays of the all-hits comparison (at most --rays): Mitsuba's re-casts go one hit at a time
ALL_HITS_RAYS = 256


def add_command(subparsers) -> None:
    from ...reference.check import DEFAULT_RAYS, VARIANTS

    parser = subparsers.add_parser(
        "check",
        help="cross-check pyclray's images against Mitsuba 3 (exit 1 outside the tolerance)",
        description="Render SCENE with pyclray (fp32) and Mitsuba 3 and print one table per image "
        "(depth, normal, id, misses), the ray-level comparison (Mitsuba's own primary rays cast "
        "through both), every hit along some of those rays (pyclray.all_hits against the float64 oracle, Mitsuba's "
        "ray_intersect repeated past each hit beside), the shaded image against Mitsuba's direct integrator, and closest points of points in and "
        "around the scene against the float64 oracle (Mitsuba has no closest-point query). Exit status 0 within the tolerance of the error model (printed), 1 outside it, "
        "2 on bad input.",
    )
    parser.add_argument("scene", metavar="SCENE", help="scene file (TOML, or Mitsuba 3 XML)")
    parser.add_argument("--variant", choices=VARIANTS, default="scalar_rgb", help="Mitsuba variant (default scalar_rgb)")
    parser.add_argument("--size", type=image_size, metavar="WxH", help="override the scene's image size")
    parser.add_argument("--rays", type=int, default=DEFAULT_RAYS, metavar="N",
                        help=f"pixels in the ray-level comparison (default {DEFAULT_RAYS})")
    parser.add_argument("--seed", type=int, default=0, help="seed choosing the ray-level pixels (default 0)")
    parser.add_argument("--save", metavar="DIR",
                        help="write DIR/NAME.pyclray.exr, DIR/NAME.mitsuba-VARIANT.exr and DIR/NAME.depth-error.png "
                        "(log10 relative depth difference, 1e-9 dark blue to 1e-4 red, white outside the "
                        "tolerance, black where not compared)")
    parser.add_argument("--points", type=int, default=2000, metavar="N",
                        help="points in the closest-point comparison against the float64 oracle (default 2000)")
    parser.add_argument("--device", metavar="DEV", help="OpenCL device (as for pyclray render)")
    parser.set_defaults(run=run)


def run(args) -> int:
    if args.rays < 1:
        raise BadInput(f"--rays: expected a whole number >= 1, got {args.rays}")
    if args.points < 1:
        raise BadInput(f"--points: expected a whole number >= 1, got {args.points}")
    folder = None
    if args.save is not None:
        folder = Path(args.save)
        if folder.exists() and not folder.is_dir():
            raise BadInput(f"--save {folder}: is not a folder")
        if not folder.parent.is_dir():
            raise BadInput(f"--save {folder}: the folder {folder.parent} does not exist")
    scene = load(args.scene, args.size)
    from ...reference.mitsuba import sensor_of

    sensor_of(scene)  # a camera Mitsuba has no sensor for (fx != fy) is bad input, said before any work
    try:
        from ...reference.mitsuba import import_mitsuba

        mi = import_mitsuba(args.variant)
    except (ImportError, ValueError) as error:
        raise BadInput(str(error)) from None

    from ...io.progress import seconds, step, steps
    from ...reference.check import (cross_check, format_image_check, format_ray_check, ray_level, save,
                                    tolerance_text)
    from ...reference.validation.arbitrate import mitsuba_faults
    from ...reference.validation.closest import closest_check, format_closest_check
    from ...reference.validation.hits import all_hits_check, format_hits_check
    from ...reference.validation.shaded import cross_check_shaded, format_shaded_check

    with steps(12, desc="pyclray check") as timing:
        images = cross_check(scene, args.variant, device=args.device)
        rays = ray_level(scene, args.variant, args.rays, args.seed, device=args.device)
        hits = all_hits_check(scene, args.variant, min(args.rays, ALL_HITS_RAYS), args.seed, device=args.device)
        shaded = None
        if scene.shading.shadows:
            shaded = cross_check_shaded(scene, args.variant, device=args.device, truth=images.truth)
        closest = closest_check(scene, args.points, args.seed, device=args.device)
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
    print(format_hits_check(hits))
    print()
    print(format_shaded_check(shaded) if shaded else "shaded: not compared (shadows = false; Mitsuba's direct integrator always casts them)")
    print()
    print(format_closest_check(closest))
    print()
    print(time_table(timing.times, seconds))
    if folder is not None:
        folder.mkdir(exist_ok=True)
        written = save(images, folder, Path(args.scene).stem)
        print()
        print("wrote " + ", ".join(map(str, written)))
    failures = images.failures + rays.failures + hits.failures + (shaded.failures if shaded else []) + closest.failures
    verdicts = {f"image {name}": v for name, v in images.verdicts.items()}
    verdicts.update({f"ray-level {name}": v for name, v in rays.verdicts.items()})
    if shaded:
        verdicts["shaded"] = shaded.verdict
    theirs = mitsuba_faults(verdicts)
    print()
    if failures:
        print("FAILED: " + "; ".join(failures) + (f" ({theirs})" if theirs else ""))
        return 1
    print("passed: within the tolerance" + (f"; {theirs}" if theirs else ""))
    return 0


def time_table(times: dict, seconds) -> str:
    """Where the time went: each step, and Mitsuba's steps against the rest."""
    from ...reference.validation.summary import table

    theirs = sum(t for name, t in times.items() if "Mitsuba" in name)
    rows = [(name, seconds(t)) for name, t in times.items()]
    rows += [("Mitsuba's steps, in all", seconds(theirs)), ("the others (pyclray, oracle, comparison)",
                                                            seconds(sum(times.values()) - theirs))]
    return table("time by step (wall clock)", rows)
