"""Read the pytest-benchmark JSON and write the report (REPORT.md) and its plot (error_vs_time.png).

    python -m pytest bench                  # runs the benchmarks and writes REPORT.md under bench.OUT itself
    python -m bench.report                  # OUT/results.json -> OUT/REPORT.md (bench.OUT: outside the checkout)
    python -m bench.report --update         # bench/results.json -> the tracked bench/REPORT.md, plot and
                                            # the headline of docs/benchmarks.md
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from . import HERE, OUT  # OUT: untracked (.gitignore), a run's results and report
HEADLINE = HERE.parent / "docs" / "benchmarks.md"  # the page whose headline table --update rewrites
KIND_ORDER = ["pyclray", "pyclray-new-scene", "pyclray-cold", "mitsuba-llvm", "mitsuba-scalar", "oracle", "floor", "floor+copies", "floor-in-place", "breakdown", "targets-blocks"]
SCENE_ORDER = ["tp02", "grid64", "grid1024", "shapes", "floor"]
TARGETS = {"tp02_speedup": 8.0, "depth_share": 0.60, "grid64_speedup": 2.0}


BREAKDOWN_ORDER = [
    "render, all AOVs", "kernel only, all AOVs", "kernel only, depth", "kernel only, all AOVs, plane only",
    "render 16x16, all AOVs",
]
# What the profiling showed (see the breakdown table, and the commits on branch bench).
WHERE_THE_TIME_GOES = [
    "The render is almost all kernel time: Python, argument checks and one launch are the 16×16 render's",
    "row; on a CPU device the kernel writes the images straight into the returned numpy arrays. Each",
    "work-item casts a packet of 8 pixels in float8 lanes (`kernels/lanes.h`): before packets, PoCL ran",
    "the float3 shape code one pixel at a time (its work-item loop vectorizer rejects vector-typed",
    "code), and every pixel waited on the latency of its divisions and square roots. The depth-only",
    "render is now near the floor; all AOVs add each winner's normal (the sphere's terms again, two cross",
    "products, a normalization and the rotation to world space, once per distinct winner of a packet,",
    "found by a max-reduction over the lanes' winner keys), the interleaved 12-byte normal stores and the",
    "id and winner-key selects. On PoCL's CPU device the kernel calls nothing in PoCL's built-in library,",
    "which LLVM does not inline there (square root, any(), vector stores were calls): that took tp02's",
    "all-AOV render from 1.12 to 0.88 ms (min).",
]


def load(path: Path) -> list[dict]:
    data = json.loads(path.read_text())
    rows = []
    for bench in data["benchmarks"]:
        if "scene" not in bench["extra_info"]:
            continue  # not a case of the matrix (see exact_cost)
        row = dict(bench["extra_info"])
        stats = bench["stats"]
        row.update(
            name=bench["name"], median=stats["median"], q1=stats["q1"], q3=stats["q3"],
            min=stats["min"], max=stats["max"], rounds=stats["rounds"],
        )
        rows.append(row)
    rows = [r for r in rows if r["kind"] in KIND_ORDER]  # cases of earlier versions of the matrix are left out
    scene_rank = lambda name: SCENE_ORDER.index(name) if name in SCENE_ORDER else len(SCENE_ORDER)  # noqa: E731
    rows.sort(key=lambda r: (scene_rank(r["scene"]), r["scene"], r["size"], KIND_ORDER.index(r["kind"]), r["aovs"], r["precision"], r.get("part", "")))
    return rows, data.get("machine_info", {}), data.get("datetime", "")


def exact_cost(path: Path) -> list[str]:
    """The table of bench/test_exact_cost.py: kernels/sphere.cl against the textbook sphere."""
    data = json.loads(path.read_text())
    cases = [b for b in data["benchmarks"] if b["name"].startswith("test_tp02_sphere_formulation")]
    if not cases:
        return ["(not in this run: `pytest bench/test_exact_cost.py --benchmark-only`)"]
    lines = ["| formulation, images (tp02 512×512 fp32, warm) | median ms | min ms |", "|---|---|---|"]
    for b in sorted(cases, key=lambda b: b["name"]):
        lines.append(f"| {b['param']} | {ms(b['stats']['median'])} | {ms(b['stats']['min'])} |")
    by = {b["param"]: b["stats"]["median"] for b in cases}
    for aovs in ("depth", "all"):
        if f"exact-{aovs}" in by and f"simple-{aovs}" in by:
            lines.append("")
            lines.append(f"exact / simple, {aovs}: {by[f'exact-{aovs}'] / by[f'simple-{aovs}']:.2f}x (medians)")
    return lines


def find(rows, **keys):
    for row in rows:
        if all(row.get(k) == v for k, v in keys.items()):
            return row
    return None


def ms(seconds: float) -> str:
    value = seconds * 1e3
    return f"{value:.3g}" if value < 100 else f"{value:.0f}"


def fmt(value, digits=3) -> str:
    if value is None:
        return ""
    if isinstance(value, int):
        return str(value)
    if value == 0:
        return "0"
    return f"{value:.{digits}g}"


def llvm_of(rows, row):
    return find(rows, kind="mitsuba-llvm", scene=row["scene"], size=row["size"])


def table(rows) -> list[str]:
    out = [
        r"| kind | scene | size | AOVs | precision | median ms | IQR ms (q1–q3) | min–max ms | rounds | vs llvm | Mrays/s | depth ulps×\|cos\| max / p99 | normal err×\|cos\| max / p99 | id mismatches |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r["kind"] == "targets-blocks":
            continue
        llvm = llvm_of(rows, r) if r["kind"] != "breakdown" else None
        ratio = f"{llvm['median'] / r['median']:.2f}x" if llvm and r["kind"] != "mitsuba-llvm" else ("1" if llvm else "")
        kind = f"breakdown: {r['part']}" if r["kind"] == "breakdown" else r["kind"]
        depth = f"{fmt(r['depth_ulps_max'])} / {fmt(r['depth_ulps_p99'])}" if "depth_ulps_max" in r else ""
        normal = f"{fmt(r['normal_err_max'])} / {fmt(r['normal_err_p99'])}" if "normal_err_max" in r else ""
        out.append(
            f"| {kind} | {r['scene']} | {r['size']} | {r['aovs']} | {r['precision']} | {ms(r['median'])} | "
            f"{ms(r['q1'])}–{ms(r['q3'])} | {ms(r['min'])}–{ms(r['max'])} | {r['rounds']} | {ratio} | "
            f"{r['rays'] / r['median'] / 1e6:.1f} | {depth} | {normal} | {fmt(r.get('id_mismatches'))} |"
        )
    return out


def block_cases(rows) -> dict:
    """The cases of every test_targets_blocks group: label -> statistics."""
    cases = {}
    for row in rows:
        if row["kind"] == "targets-blocks":
            cases.update(row.get("cases", {}))
    return cases


def block_targets(rows) -> list[str]:
    """The speed targets from test_targets_blocks (bench/blocks.py: each case in blocks of calls)."""
    from .blocks import PAUSE, ROUNDS, tables

    cases = block_cases(rows)
    if not cases:
        return []
    return [
        f"Each case timed in blocks of calls ({ROUNDS} blocks of about 1 s each, 3 untimed calls first, a "
        f"{PAUSE:g} s pause at each switch, the order rotating; `bench/blocks.py`, also `python -m bench.blocks`), "
        "so that one runtime's threads winding down do not weigh on the next; ratios of medians measured in the "
        "same process. The floor writes the three images into new numpy arrays as pyclray does on a CPU:",
        "",
        *tables(cases),
    ]


def targets(rows) -> tuple[list[str], dict]:
    found = {}
    lines = ["| target | measured (separate cases of the matrix) | goal | met |", "|---|---|---|---|"]

    def add(label, value, goal, ok, text):
        found[label] = value
        lines.append(f"| {label} | {text} | {goal} | {'yes' if ok else '**no**'} |")

    tp_all = find(rows, kind="pyclray", scene="tp02", size=512, aovs="all", precision="fp32")
    tp_depth = find(rows, kind="pyclray", scene="tp02", size=512, aovs="depth", precision="fp32")
    tp_llvm = find(rows, kind="mitsuba-llvm", scene="tp02", size=512)
    g_all = find(rows, kind="pyclray", scene="grid64", size=512, aovs="all", precision="fp32")
    g_llvm = find(rows, kind="mitsuba-llvm", scene="grid64", size=512)
    floor = find(rows, kind="floor-in-place", size=512) or find(rows, kind="floor+copies", size=512)
    floor_copies = find(rows, kind="floor+copies", size=512)
    floor_kernel = find(rows, kind="floor", size=512)
    if tp_all and tp_llvm:
        s = tp_llvm["median"] / tp_all["median"]
        add("tp02 512² all AOVs: llvm / pyclray", s, f">= {TARGETS['tp02_speedup']:g}x", s >= TARGETS["tp02_speedup"],
            f"{s:.2f}x ({ms(tp_llvm['median'])} ms / {ms(tp_all['median'])} ms)")
    if tp_all and tp_depth:
        s = tp_depth["median"] / tp_all["median"]
        add("tp02 512² depth only / all AOVs", s, f"<= {TARGETS['depth_share']:.0%}", s <= TARGETS["depth_share"],
            f"{s:.0%} ({ms(tp_depth['median'])} ms / {ms(tp_all['median'])} ms)")
    if g_all and g_llvm:
        s = g_llvm["median"] / g_all["median"]
        add("grid64 512² all AOVs: llvm / pyclray", s, f">= {TARGETS['grid64_speedup']:g}x", s >= TARGETS["grid64_speedup"],
            f"{s:.2f}x ({ms(g_llvm['median'])} ms / {ms(g_all['median'])} ms)")
    if tp_all and floor:
        found["floor"] = floor["median"]
        lines.append(
            f"| floor at 512²: a trivial kernel writing the 3 images into new numpy arrays as pyclray does "
            f"| {ms(floor['median'])} ms (kernel alone {ms(floor_kernel['median']) if floor_kernel else '?'} ms, "
            f"with copies instead {ms(floor_copies['median']) if floor_copies else '?'} ms); tp02 all AOVs is "
            f"{ms(tp_all['median'] - floor['median'])} ms above it ({tp_all['median'] / floor['median']:.1f}x) | | |"
        )
    return lines, found


def breakdown(rows) -> list[str]:
    """The tp02 512x512 fp32 render taken apart (test_breakdown), beside the floor."""
    out = ["| part (tp02, 512×512, fp32) | median ms | min ms |", "|---|---|---|"]
    parts = [r for r in rows if r["kind"] == "breakdown"]
    parts.sort(key=lambda r: BREAKDOWN_ORDER.index(r["part"]) if r["part"] in BREAKDOWN_ORDER else 99)
    for r in parts:
        out.append(f"| {r['part']} | {ms(r['median'])} | {ms(r['min'])} |")
    for kind, label in (
        ("floor", "floor: trivial kernel writing the 3 images (device buffers)"),
        ("floor-in-place", "floor, writing into new numpy arrays (as pyclray on a CPU)"),
        ("floor+copies", "floor + copies into new numpy arrays"),
    ):
        r = find(rows, kind=kind, size=512)
        if r:
            out.append(f"| {label} | {ms(r['median'])} | {ms(r['min'])} |")
    return out


def headline(rows) -> list[str]:
    """Medians of the block measurement when it has the scene, else of the matrix's cases."""
    out = [
        "| scene (512×512) | pyclray, all AOVs | pyclray, depth only | Mitsuba 3 llvm_ad_rgb | llvm / pyclray (all AOVs) |",
        "|---|---|---|---|---|",
    ]
    cases = block_cases(rows)
    for name in ("tp02", "grid64", "grid1024", "shapes"):
        keys = [f"{name} 512 all", f"{name} 512 depth", f"{name} 512 llvm"]
        if all(k in cases for k in keys):
            a, d, m = (cases[k]["median"] for k in keys)
            out.append(f"| {name} | {ms(a)} ms | {ms(d)} ms | {ms(m)} ms | {m / a:.1f}x |")
            continue
        a = find(rows, kind="pyclray", scene=name, size=512, aovs="all", precision="fp32")
        d = find(rows, kind="pyclray", scene=name, size=512, aovs="depth", precision="fp32")
        m = find(rows, kind="mitsuba-llvm", scene=name, size=512)
        if a and d and m:
            out.append(f"| {name} | {ms(a['median'])} ms | {ms(d['median'])} ms | {ms(m['median'])} ms | {m['median'] / a['median']:.1f}x |")
    return out


def plot(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    markers = {"tp02": "o", "grid64": "s", "grid1024": "^", "shapes": "D"}
    colours = {("pyclray", "fp32"): "tab:blue", ("pyclray", "fp64"): "tab:cyan", ("mitsuba-llvm", "fp32"): "tab:red",
               ("mitsuba-scalar", "fp32"): "tab:orange"}
    floor_value = 1e-9  # errors of exactly 0 (or below) are drawn here
    fig, ax = plt.subplots(figsize=(8, 6))
    seen = set()
    for r in rows:
        if "depth_ulps_max" not in r:
            continue
        key = (r["kind"], r["precision"])
        label = f"{r['kind']} {r['precision']}" if key not in seen else None
        seen.add(key)
        y = max(r["depth_ulps_max"], floor_value)
        ax.scatter(r["median"], y, marker=markers[r["scene"]], color=colours.get(key, "grey"), label=label,
                   facecolors="none" if r["aovs"] == "depth" else None, s=60)
        ax.annotate(f"{r['scene']}{' d' if r['aovs'] == 'depth' else ''}", (r["median"], y), fontsize=7,
                    xytext=(4, 3), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("median render time at 512×512 [s] (warm)")
    ax.set_ylabel("max depth error vs float64 oracle [float32 ulps x |cos incidence|]")
    ax.set_title("Error against run time (one point per configuration;\nmarkers: o tp02, □ grid64, △ grid1024, ◇ shapes; hollow: depth only)")
    ax.grid(True, which="both", alpha=0.3)
    if seen:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.report", description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="?", default=None, type=Path,
                        help=f"the pytest-benchmark JSON (default {OUT / 'results.json'}; with --update {HERE / 'results.json'})")
    parser.add_argument("-o", "--output", default=None, type=Path, help=f"the report (default {OUT / 'REPORT.md'})")
    parser.add_argument("--plot", default=None, type=Path, help=f"the plot (default {OUT / 'error_vs_time.png'})")
    parser.add_argument("--readme", type=Path, nargs="?", const=HEADLINE, default=None,
                        help=f"also replace the headline table between the bench-headline markers of this file "
                        f"(default {HEADLINE})")
    parser.add_argument("--update", action="store_true",
                        help="the tracked files: bench/results.json -> bench/REPORT.md, bench/error_vs_time.png and the "
                        "headline of docs/benchmarks.md (a checkout stays clean without it)")
    args = parser.parse_args(argv)
    folder = HERE if args.update else OUT
    args.results = args.results or folder / "results.json"
    args.output = args.output or folder / "REPORT.md"
    args.plot = args.plot or folder / "error_vs_time.png"
    if args.update and args.readme is None:
        args.readme = HEADLINE
    if not args.results.is_file():
        raise SystemExit(f"python -m bench.report: no {args.results}: run `python -m pytest bench` first")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    rows, machine, when = load(args.results)
    plotted = True
    try:
        plot(rows, args.plot)
    except ModuleNotFoundError as error:  # matplotlib is in the bench extra
        plotted = False
        print(f"no plot ({error}: pip install -e '.[bench]')")
    target_lines, _ = targets(rows)
    cpu = machine.get("cpu", {})
    lines = [
        "# pyclray benchmarks",
        "",
        f"Generated by `python -m bench.report` from `{args.results.name}` ({when}); machine: "
        f"{cpu.get('brand_raw', machine.get('processor', '?'))}, {cpu.get('count', '?')} logical CPUs, "
        f"Python {machine.get('python_version', '?')}. PoCL (CPU) is pyclray's device.",
        "",
        "Run: `python -m pytest bench --bench-full --update-report` (the whole matrix; `python -m pytest bench` alone "
        "runs the quick subset and writes its report outside the checkout (bench.OUT)).",
        "",
        "## Speed targets (ratios to Mitsuba 3 llvm_ad_rgb measured in the same run)",
        "",
        *block_targets(rows),
        "",
        "The same ratios from the separate cases of the matrix below (each case timed on its own, so",
        "another process's load during one case and not the other shows in the ratio):",
        "",
        *target_lines,
        "",
        "## Where the time goes",
        "",
        *breakdown(rows),
        "",
        *WHERE_THE_TIME_GOES,
        "",
        "## Headline (512×512, warm, fp32; medians of the block measurement)",
        "",
        *headline(rows),
        "",
        f"![error against run time]({args.plot.name})",
        "",
        "The plot has the 512×512 configurations, where the errors are computed (warm times).",
        "",
        "## All configurations",
        "",
        *table(rows),
        "",
        "## Cost of the exact sphere formulation",
        "",
        "The exact sphere (`kernels/sphere.cl`: the better-conditioned of two discriminants, stable roots,",
        "the normal from the perpendicular) against the textbook one (b^2 - a c, (b -+ sqrt) / a, p - C),",
        "both with the host's camera-relative packing (`bench/test_exact_cost.py`):",
        "",
        *exact_cost(args.results),
        "",
        "## How it is measured",
        "",
        "- **Times**: pytest-benchmark, `benchmark.pedantic` with one call per round; the median and the",
        "  interquartile range (q1–q3) and min–max of the rounds. Rounds are chosen from a first timed",
        "  call to spend about 2 s per case (3 to 100 rounds; 3 for scalar_rgb, 1 for the oracle).",
        "- **pyclray (warm)**: `pyclray.render(scene, aovs, precision)` after a first render that built the",
        "  program; everything per call is included (checks, kernel, images in new numpy arrays).",
        "  Renders of the same `Scene` object share their packed inputs and tile lists (or BVH)",
        "  (kept by pyclray, see `pyclray/engine/scene/prepared.py`), as repeated renders of one view do.",
        "- **pyclray-new-scene**: the same, but a new (equal) `Scene` object each call, as a moved camera",
        "  would be: the per-scene inputs and tile lists are rebuilt every time (program warm).",
        "- **pyclray-cold**: the first render with a build: `pyclray.engine.launch.programs.clear()` called and",
        "  `PYCLRAY_CACHE_DIR` an empty temporary directory before each round, and PoCL's own kernel cache",
        "  off (`POCL_KERNEL_CACHE=0`, set by `bench/conftest.py`), so each round compiles from source",
        "  (in the same process: the OpenCL platform and context are already up).",
        "- **Mitsuba 3** (`mitsuba-llvm`: llvm_ad_rgb, `mitsuba-scalar`: scalar_rgb): the aov integrator",
        "  (depth, geo_normal, sh_normal, shape_index) on the scene from `pyclray.reference.mitsuba.load`; only",
        "  `integrator.render(scene, sensor)` plus the conversion of its result to numpy (which forces the JIT's",
        "  evaluation) is timed, after one untimed render. **scalar_rgb is capped**: it takes ~1 s a render",
        "  on tp02, ~15 s on grid64 and ~3 min on grid1024, so it runs at 512×512 on tp02 and grid64 only",
        "  (3 rounds), not on grid1024 nor at 2048×2048.",
        "- **oracle**: `pyclray.reference.oracle.render` (float64 numpy), 512×512, one round; it is also the reference",
        "  of every error.",
        "- **floor**: a trivial OpenCL kernel that writes depth = inf, normal = 0, id = -1 for every pixel",
        "  (`floor`: enqueue and wait; `floor+copies`: plus the copies into new numpy arrays;",
        "  `floor-in-place`: writing into new numpy arrays through USE_HOST_PTR buffers and a map, as",
        "  pyclray does on a CPU device).",
        "- **Errors** (512×512 only), by pyclray's error model (`pyclray.accuracy`, the same as the tests):",
        "  depth in float32 ulps of the oracle's t times |cos incidence| (|d - d_ref| / spacing(float32(d_ref)) x |cos|:",
        "  a direction error moves the hit by 1/|cos| more at grazing incidence), max and 99th percentile, over",
        "  the pixels where both hit the same shape (`depth_ulps_raw_max` in the JSON is the max without the",
        "  |cos| factor); normal error |n - n_ref| x |cos|; id mismatches (depth only: hit/miss disagreements).",
        "  Silhouettes, near-ties and edges, by each engine's own tolerance (`pyclray.reference.error_model.judged_pixels`),",
        "  are left out (column `excluded` in the JSON). For Mitsuba, the pixels where the plane lies beyond",
        "  its stand-in disk (`pyclray.reference.mitsuba.beyond_counterparts`) are left out too.",
        "- Before each case's timing the benchmark sleeps 0.3 s, and OpenBLAS runs one thread",
        "  (`bench/conftest.py`), so that threads left busy by the previous case (numpy's BLAS, Dr.Jit's",
        "  pool) do not run into the timing. The machine has 2 cores, and other people's test runs shared",
        "  them during these runs: spreads are wide, hence also the block measurement of the targets.",
        "- Mrays/s = width × height / median time.",
        "",
    ]
    args.output.write_text("\n".join(lines))
    scale = scale_section(args.results.parent)
    if scale:  # the "Scale" section of bench.open3d_compare, kept from its own results
        from .open3d_compare import write_report

        write_report(scale, args.output)
    print(f"wrote {args.output}" + (f" and {args.plot}" if plotted else ""))
    if args.readme:
        update_readme(args.readme, rows, target_summary(rows))
        print(f"updated the headline in {args.readme}")


def scale_section(folder: Path) -> dict | None:
    """The results of bench.open3d_compare beside these results (else the tracked ones), if any."""
    for path in (folder / "open3d_results.json", HERE / "open3d_results.json"):
        if path.is_file():
            return json.loads(path.read_text())
    return None


START, END = "<!-- bench-headline: written by python -m bench.report --readme -->", "<!-- /bench-headline -->"


def target_summary(rows) -> list[str]:
    from .blocks import TARGETS

    c = block_cases(rows)
    parts = []
    for name, (top, bottom, goal, sense) in TARGETS.items():
        if goal is None or top not in c or bottom not in c:
            continue
        ratio = c[top]["median"] / c[bottom]["median"]
        met = ratio <= goal if sense == "<=" else ratio >= goal
        parts.append(f"{name} {ratio:.2f} (goal {sense} {goal:g}{'' if met else ': **not met**'})")
    if not parts:
        return []
    return ["Speed targets, each system timed in blocks in the same run (`bench/blocks.py`): " + "; ".join(parts) + "."]


def update_readme(path: Path, rows, summary) -> None:
    text = path.read_text()
    if START not in text or END not in text:
        raise SystemExit(f"{path}: no {START} ... {END} markers")
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    block = [START, "", *headline(rows), "", *summary, "", END]
    path.write_text(head + "\n".join(block) + tail)


if __name__ == "__main__":
    main()
