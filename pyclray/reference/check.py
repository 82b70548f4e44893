"""pyclray check: cross-check pyclray's float32 images against Mitsuba 3, pixel by pixel and ray by
ray (the command; the comparisons are in pyclray.validation, the error model in pyclray.accuracy).

The tolerances' derivation and measurements (pyclray.accuracy's docstring has the model):
- same rays: Mitsuba intersects in float32 world coordinates of size L = max(|eye|, |anchor|,
  |eye - anchor|) (the scalar variants solve a sphere's quadratic in float64, but from float32 rays
  and centres); measured below 2.8 eps (t + L) / cos over 75 random scenes (random spheres and a
  tilted plane, moved 0, 100 and 1000 units off the world origin) in both variants, and pyclray's
  own error against the float64 oracle is below 3.7 eps t / cos, so K = 6 leaves room for both;
- cameras: Mitsuba's sensor's to_world is a float32 look_at matrix built from target - eye
  rounded in float32, so its ray directions differ from pyclray's pixel rays by up to
  alpha = 3 eps (1 + S) (measured 3.3 eps on tp02, where the bound is 6 eps; at most 2.1 eps (1 + S)
  over the random scenes), and its origins, the eye rounded to float32 and moved to the near-clip
  plane, lie within 2 eps max(|eye|, 1) of pyclray's rays (measured 1.6). A direction off by alpha
  moves the hit sideways by t alpha: images measured below 0.33 of their bound over the random
  scenes; without the camera term, scenes 1000 units off the origin exceed K eps (t + L) / cos by 1.9.

Where the model ends (counted apart, not judged): silhouettes, edges, pixels next to an id change
and near ties; pixels whose ray meets a shape where its Mitsuba stand-in ends (the plane beyond its
disk) are left out of everything and counted.
"""
from __future__ import annotations

from pathlib import Path

from . import accuracy
from .accuracy import ORIGIN_K, SILHOUETTE_COS
from .shapes import REGISTRY
from .validation.files import heat_map, save
from .validation.images import ImageCheck, cross_check, format_image_check, next_to_id_change
from .validation.rays import DEFAULT_RAYS, RayCheck, format_ray_check, ray_level

VARIANTS = ("scalar_rgb", "llvm_ad_rgb")

__all__ = ["ImageCheck", "RayCheck", "cross_check", "format_image_check", "format_ray_check", "heat_map",
           "next_to_id_change", "ray_level", "save", "tolerance_text"]


def tolerance_text() -> list[str]:
    """The error model's tolerances, as printed by the command."""
    K, camera_k = accuracy.K_MITSUBA, accuracy.CAMERA_K
    return [
        "tolerances (eps = 2^-24; t = distance, cos = |cos incidence| from the float64 oracle, r = radius of curvature,",
        "  L = max(|eye|, |anchor|, |eye - anchor|): the size of the float32 world coordinates Mitsuba works in,",
        "  anchor = the point the shape is intersected from (a centre, an end, the plane's disk centre);",
        "  S = max(|eye|, |target|) / |target - eye|):",
        f"  same rays: |depth difference| <= {K:g} eps (t + L) / cos, normal angle <= {K:g} eps (1 + (t + L) / (r cos))",
        f"  cameras:   direction angle <= alpha = {camera_k:g} eps (1 + S), origin off our ray <= {ORIGIN_K:g} eps max(|eye|, 1)",
        f"  images:    |depth difference| <= D = eps ({K:g} (t + L) + {camera_k:g} (1 + S) t + {ORIGIN_K:g} max(|eye|, 1)) / cos,"
        f" normal angle <= {K:g} eps + D / r",
        f"  not judged: silhouettes (|cos| < {SILHOUETTE_COS:g}), hits within D of an edge, and for ids also pixels next",
        "  to an id change and near ties (the second-nearest surface within D)",
    ] + [f"  {kind}: K x {cls.mitsuba_error_scale:g} (its Mitsuba counterpart is less exact)"
         for kind, cls in REGISTRY.items() if cls.mitsuba_error_scale != 1.0]


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
        from .validation.shaded import cross_check_shaded, format_shaded_check

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
