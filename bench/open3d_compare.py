"""pyclray against Open3D's RaycastingScene (Embree over triangle meshes) in one process, and the
BVH's scaling, build times and memory (issue 11).

    python -m bench.open3d_compare [--quick]      # writes OUT/open3d_results.json and the
                                                   # "Scale" section of OUT/REPORT.md (bench.OUT)
    python -m bench.open3d_compare --update       # the tracked bench/open3d_results.json and
                                                   # bench/REPORT.md instead

Open3D is in the `bench` extra; its wheel needs the Debian library libusb-1.0-0
(`apt-get update && apt-get install -y libusb-1.0-0`). Spheres are tessellated as Open3D's users
must (create_sphere(resolution=6): 120 triangles each). Open3D's create_rays_pinhole leaves its
camera rays unnormalized, so its t_hit is z-depth (pyclray's depth is along the unit ray); both
compute hit distance, normal and id for every pixel.

Timing: every system is timed in blocks: at each switch a 50 ms pause and one untimed call, then
BLOCK timed calls; ROUNDS rounds, the order of the systems rotating; the medians are reported.
So the machine's load over the run weighs on every system alike (this machine's two cores are
shared with other work: compare ratios, not absolute times).
"""
from __future__ import annotations

import argparse
import json
import platform
import re
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import pyclray
from pyclray.engine.bvh import tree as bvh
from pyclray.model.shapes import REGISTRY
from pyclray.engine.bvh import wide as bvh_wide
from pyclray.engine import api
from pyclray.engine.opencl.device import context_for
from pyclray.engine.scene.views import ViewState
from pyclray.engine.bvh.scene import scene_bvh as build_scene_bvh

from . import scale

from . import HERE, OUT  # OUT: outside the checkout; --update writes the tracked files in HERE instead
RESULTS_NAME, REPORT_NAME = "open3d_results.json", "REPORT.md"
BEGIN, END = "<!-- scale:begin -->", "<!-- scale:end -->"


def blocks(systems: dict, rounds: int, block: int, pause: float = 0.05) -> dict:
    """Median and quartiles (ms) of each system's calls, timed in rotating blocks; "cpu": the median
    process CPU time of its calls (ms, every thread's: what the machine's other load leaves alone)."""
    times = {name: [] for name in systems}
    cpus = {name: [] for name in systems}
    names = list(systems)
    for r in range(rounds):
        for name in names[r % len(names):] + names[: r % len(names)]:
            time.sleep(pause)
            systems[name]()
            for _ in range(block):
                start, start_cpu = time.perf_counter(), time.process_time()
                systems[name]()
                times[name].append(time.perf_counter() - start)
                cpus[name].append(time.process_time() - start_cpu)
    out = {}
    for name, values in times.items():
        ms = np.array(values) * 1e3
        out[name] = {"median": float(np.median(ms)), "q1": float(np.percentile(ms, 25)), "q3": float(np.percentile(ms, 75)),
                     "n": len(ms), "cpu": float(np.median(cpus[name])) * 1e3}
    return out


def once(function) -> float:
    start = time.perf_counter()
    function()
    return (time.perf_counter() - start) * 1e3


def cpu_once(function) -> float:
    """CPU time of the process (numpy's build is single-threaded: this is its work, whatever other
    load the machine carries)."""
    start = time.process_time()
    function()
    return (time.process_time() - start) * 1e3


def versus_open3d(rounds: int, block: int) -> dict:
    import open3d as o3d

    out = {}
    # render: ground + 100,000 spheres, 512x512, depth + normal + id
    scene = scale.scene(100_000)
    o3d_scene, triangles = scale.open3d_scene(100_000)
    rays = scale.open3d_camera_rays(512)
    out["render 512x512, ground + 100,000 spheres, depth+normal+id"] = {
        "triangles": triangles,
        **blocks({"pyclray": lambda: pyclray.render(scene), "open3d": lambda: o3d_scene.cast_rays(rays)}, rounds, block),
    }
    del o3d_scene
    origins, directions = scale.random_rays(100_000)
    o3d_rays = o3d.core.Tensor(np.hstack([origins, directions]).astype(np.float32))
    for count in (16_384, 100_000):
        scene = scale.scene(count, ground=False)
        o3d_scene, triangles = scale.open3d_scene(count, ground=False)
        out[f"cast 100,000 random rays into {count:,} spheres"] = {
            "triangles": triangles,
            **blocks(
                {"pyclray": lambda: pyclray.cast(scene, origins, directions), "open3d": lambda: o3d_scene.cast_rays(o3d_rays)},
                rounds, block,
            ),
        }
        del o3d_scene
    return out


def scaling(counts, rounds: int, block: int) -> dict:
    """Render time of ground + N spheres (512x512, all AOVs), and what the BVH costs to build."""
    out = {}
    for count in counts:
        scene = scale.scene(count)
        centres, radii = scale.sphere_field(count)
        bounds = np.stack([centres - radii[:, None], centres + radii[:, None]], axis=1)
        widened = bvh.widened(bounds)
        build = min(once(lambda: bvh.build(widened)) for _ in range(3))
        build_cpu = min(cpu_once(lambda: bvh.build(widened)) for _ in range(3))
        tree = bvh.build(widened)
        collapse = min(once(lambda: bvh_wide.collapse(tree)) for _ in range(3))
        collapse_cpu = min(cpu_once(lambda: bvh_wide.collapse(tree)) for _ in range(3))
        prepare = once(lambda: build_scene_bvh(scene.shapes, REGISTRY))
        first = once(lambda: pyclray.render(scene))
        timing = blocks(
            {"render": lambda: pyclray.render(scene, acceleration="bvh"), "auto": lambda: pyclray.render(scene)}, rounds, block
        )
        # a moved camera: the same shapes tuple, so the tree is reused; the shapes are packed again
        moved = replace(scene, camera=pyclray.Camera((4.0, 10.0, 24.0), scale.TARGET, fov=scale.FOV))
        camera_move = once(lambda: pyclray.render(moved))
        scene_bvh = api.tracer_for(scene, context_for(None), "fp32").prepared.bvh
        memory = {
            "binary nodes": scene_bvh.binary_nodes(np.zeros(3)).nbytes,
            "wide nodes": scene_bvh.nodes(np.zeros(3)).nbytes,
            "refs": scene_bvh.refs(scene.shape_types()).nbytes,
            "cast anchors": scene_bvh.anchors().nbytes,
        }
        out[str(count)] = {
            "tree from bounds ms": build,
            "tree from bounds cpu ms": build_cpu,
            "wide tree ms": collapse,
            "wide tree cpu ms": collapse_cpu,
            "auto": ViewState().acceleration(scene, "auto", api.tracer_for(scene, context_for(None), "fp32").prepared),
            "render auto ms": timing["auto"],
            "scene BVH ms (bounds from the shapes, tree, wide tree)": prepare,
            "first render ms (BVH, packing, upload, render)": first,
            "render after a camera move ms (tree reused)": camera_move,
            "render ms": timing["render"],
            "bytes per shape": {k: v / count for k, v in memory.items()},
            "depth": tree.depth(),
        }
        print(f"  {count:>9,} spheres: render {timing['render']['median']:.1f} ms, tree {build:.0f} ms", file=sys.stderr)
    return out


def acceleration_choice(rounds: int, block: int) -> dict:
    """Tiles against the BVH for render, on scenes of a few to a thousand spheres."""
    out = {}
    for name, scene in (
        ("tp02 (3 spheres)", pyclray.load_scene(HERE.parent / "scenes" / "tp02.toml")),
        ("grid64 (64 spheres)", pyclray.load_scene(HERE.parent / "scenes" / "grid64.toml")),
        ("grid1024 (1,024 spheres)", pyclray.load_scene(HERE.parent / "scenes" / "grid1024.toml")),
        ("field 1,000 spheres", scale.scene(1000)),
    ):
        out[name] = blocks(
            {"tiles": lambda: pyclray.render(scene, acceleration="tiles"), "bvh": lambda: pyclray.render(scene, acceleration="bvh")},
            rounds, block,
        )
    return out


def report(results: dict) -> str:
    lines = [BEGIN, "## Scale: the BVH against Open3D (issue 11)", ""]
    lines.append(
        f"Generated by `python -m bench.open3d_compare` ({results['when']}; {results['machine']}); "
        "each system timed in rotating blocks in one process (see the script's docstring), medians "
        "with quartiles. Open3D's RaycastingScene (Embree) gets the spheres as triangle meshes "
        "(120 triangles each); its t_hit is z-depth (create_rays_pinhole leaves rays unnormalized)."
    )
    lines += ["", "| work | pyclray ms | Open3D ms | Open3D / pyclray | target |", "|---|---|---|---|---|"]
    targets = {"render": ">= 2x", "cast": ">= 1x"}
    for work, row in results["open3d"].items():
        p, o = row["pyclray"], row["open3d"]
        ratio = o["median"] / p["median"]
        target = targets["render" if work.startswith("render") else "cast"]
        lines.append(
            f"| {work} ({row['triangles']:,} triangles for Open3D) | {p['median']:.1f} ({p['q1']:.1f}–{p['q3']:.1f}) "
            f"| {o['median']:.1f} ({o['q1']:.1f}–{o['q3']:.1f}) | {ratio:.2f}x | {target} |"
        )
    lines += ["", "### Render time against the number of spheres (512x512, ground + N spheres, all AOVs)", ""]
    lines += ["Build times: wall (min of 3) and, in brackets, the process's CPU time (numpy builds on one core: "
              "its work, whatever else loads the machine).", ""]
    lines += ["| spheres | render through the BVH ms (median, q1–q3) | render, auto ms (its choice) | tree depth | tree from bounds ms | wide tree ms | scene BVH ms | first render ms | after a camera move ms | bytes per shape (binary + wide nodes + refs; cast's anchors) |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for count, row in results["scaling"].items():
        r = row["render ms"]
        a = row["render auto ms"]
        b = row["bytes per shape"]
        render_bytes = b["binary nodes"] + b["wide nodes"] + b["refs"]
        lines.append(
            f"| {int(count):,} | {r['median']:.1f} ({r['q1']:.1f}–{r['q3']:.1f}) | {a['median']:.1f} ({row['auto']}) | {row['depth']} "
            f"| {row['tree from bounds ms']:.0f} ({row['tree from bounds cpu ms']:.0f}) "
            f"| {row['wide tree ms']:.0f} ({row['wide tree cpu ms']:.0f}) | {row['scene BVH ms (bounds from the shapes, tree, wide tree)']:.0f} "
            f"| {row['first render ms (BVH, packing, upload, render)']:.0f} | {row['render after a camera move ms (tree reused)']:.0f} "
            f"| {render_bytes:.0f} ({b['binary nodes']:.0f} + {b['wide nodes']:.0f} + {b['refs']:.0f}); {b['cast anchors']:.0f} |"
        )
    lines += ["", "### Tiles or BVH for render (pyclray.render(..., acceleration=...))", "",
              "| scene | tiles ms | BVH ms | tiles / BVH |", "|---|---|---|---|"]
    for name, row in results["acceleration"].items():
        lines.append(
            f"| {name} | {row['tiles']['median']:.2f} | {row['bvh']['median']:.2f} | {row['tiles']['median'] / row['bvh']['median']:.2f} |"
        )
    lines += ["", results.get("notes", ""), END]
    return "\n".join(lines)


def write_report(results: dict, path: Path) -> None:
    """Put the "Scale" section into the report at path (replacing an earlier one)."""
    text = path.read_text(encoding="utf-8") if path.exists() else ""
    section = report(results)
    if BEGIN in text:
        text = re.sub(re.escape(BEGIN) + ".*?" + re.escape(END), lambda _: section, text, flags=re.S)
    else:
        text = text.rstrip("\n") + "\n\n" + section + "\n"
    path.write_text(text, encoding="utf-8")


NOTES = """What the BVH does when things move: a render of a scene whose camera moved (a new Scene with the
same shapes tuple, e.g. `dataclasses.replace(scene, camera=...)`) reuses the tree: only the nodes'
boxes are re-expressed around the new eye (one vectorized pass) and the shapes packed again in the
camera's frame, as before the BVH; no program is rebuilt. Shapes that move make a new shapes tuple,
hence a new tree: its cost is the "scene BVH" column (bounds from the shapes' modules, the LBVH, the
wide tree), which grows about linearly; cast's inputs (the wide tree around the scene's anchor, the
shapes at their own anchors) are kept per shapes tuple and never depend on the rays."""


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer rounds and no 1,000,000-sphere scene")
    parser.add_argument("--no-open3d", action="store_true", help="skip the comparison with Open3D")
    parser.add_argument("--update", action="store_true",
                        help="write the tracked bench/open3d_results.json and bench/REPORT.md (default: bench.OUT, outside the checkout)")
    args = parser.parse_args(argv)
    folder = HERE if args.update else OUT
    folder.mkdir(parents=True, exist_ok=True)
    rounds, block = (3, 2) if args.quick else (9, 3)
    results = {
        "when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, pyclray on {pyclray.list_devices()[0]['device'] if pyclray.list_devices() else '?'}",
    }
    print("Open3D...", file=sys.stderr)
    results["open3d"] = {} if args.no_open3d else versus_open3d(rounds, block)
    print("scaling...", file=sys.stderr)
    counts = (1_000, 10_000, 100_000) if args.quick else (1_000, 10_000, 100_000, 1_000_000)
    results["scaling"] = scaling(counts, rounds, block)
    print("tiles or BVH...", file=sys.stderr)
    results["acceleration"] = acceleration_choice(rounds, block)
    results["notes"] = NOTES
    (folder / RESULTS_NAME).write_text(json.dumps(results, indent=1), encoding="utf-8")
    write_report(results, folder / REPORT_NAME)
    print(report(results))


if __name__ == "__main__":
    main()
