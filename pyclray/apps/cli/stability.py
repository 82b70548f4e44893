"""`pyclray stability`: the stiff and extreme cases against the float64 oracle
(pyclray.reference.stability)."""
from __future__ import annotations


def add_command(commands) -> None:
    from ...reference.stability import CASES

    parser = commands.add_parser(
        "stability",
        help="print the stability report: stiff and extreme cases against the float64 oracle",
        description="Render each stiff case with pyclray fp32 and fp64 and with Mitsuba 3 (scalar_rgb, "
        "llvm_ad_rgb) and print, per case and engine, the errors against the float64 oracle on pixels "
        "that are neither silhouettes (|cos| < 0.02) nor near-ties. Exit status 1 if pyclray misses a target.",
    )
    parser.add_argument("--case", action="append", metavar="NAME", choices=[c.name for c in CASES],
                        help="only this case (repeatable); default all")
    parser.add_argument("--no-mitsuba", action="store_true", help="pyclray only")
    parser.set_defaults(run=_cmd)


def _cmd(args) -> int:
    from ...reference.error_model import FP32_DEPTH_ULPS, FP32_NORMAL, FP64_DEPTH_RELATIVE, meets_targets
    from ...reference.stability import run, table

    engines = ("fp32", "fp64") if args.no_mitsuba else ("fp32", "fp64", "scalar_rgb", "llvm_ad_rgb")
    results = run(args.case, engines)
    print(table(results))
    print(
        f"\ntargets: fp32 depth <= {FP32_DEPTH_ULPS:g} ulps x 1/|cos|, normal <= {FP32_NORMAL:g} / |cos|, ids right; "
        f"fp64 depth <= {FP64_DEPTH_RELATIVE:g} relative x 1/|cos|"
    )
    failed = [(c, e) for c, r in results.items() for e in ("fp32", "fp64") if e in r and ("error" in r[e] or not meets_targets(r[e], e))]
    for case, engine in failed:
        print(f"MISSED: {case} {engine}")
    return 1 if failed else 0
