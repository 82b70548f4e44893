"""The engine's workloads, timed against another checkout of pyclray in alternating processes: a
restructuring of the engine (issue 37) must leave none more than 5% slower.

    .venv/bin/python bench/engine_ab.py --against /path/to/other/checkout [--rounds 4] [--block 5]

Each round runs one process per checkout, in turn (this checkout's pyclray, then the other's, put
first on the import path): each process prepares every workload's scene and program once (not
timed), then times each workload in a block of calls (median, wall and process CPU time) with a
short pause between workloads. The report is, per workload, the median over the rounds of each side
and the ratio (this / other; above 1: this checkout is slower). Only pyclray's public functions are
called, so that both sides run the same script. The workloads (512x512 unless said):

- tp02: depth, normal, id of scenes/tp02.toml;
- 100k spheres: render, and render_views of 8 cameras (bench/scale.py's field, depth, normal, id);
- bunny (80,000 triangles, subdivided) and 1M (the 998,000-triangle perturbed sphere): primary rays
  (depth, normal, id, primitive) and 100,000 incoherent rays' cast;
- 100k spheres: cast and occluded of 100,000 rays from the field's box;
- shaded with shadows: the 100k-sphere field lit by a point light (shaded);
- bunny and 1M: closest_points and signed_distance of 100,000 points uniform in the mesh's box.
`--only name,...` times the workloads whose names contain one of those words (all by default).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent


def _workloads():
    """name -> callable, each ready (scenes built, programs compiled by one call)."""
    import pyclray
    from pyclray.model.shapes.mesh_shapes import perturbed_sphere

    size = 512
    tp02 = pyclray.load_scene(REPO / "scenes" / "tp02.toml").with_size(size, size)
    rng = np.random.default_rng(0)
    count = 100_000
    centers = rng.uniform((-50.0, 0.0, -50.0), (50.0, 4.0, 50.0), (count, 3))
    radii = rng.uniform(0.05, 0.3, count)
    field_shapes = (pyclray.Plane((0.0, 1.0, 0.0), 0.0), pyclray.Spheres(centers, radii))
    field = pyclray.Scene(pyclray.Camera((0.0, 30.0, 80.0), (0.0, 0.0, 0.0), fov=50.0), pyclray.Image(size, size),
                          field_shapes)
    cameras = [pyclray.Camera((80.0 * np.sin(a), 30.0, 80.0 * np.cos(a)), (0.0, 0.0, 0.0), fov=50.0)
               for a in np.linspace(0.0, 1.0, 8)]
    lit = pyclray.Scene(field.camera, field.image, field_shapes,
                        lights=(pyclray.PointLight((20.0, 60.0, 40.0), 5000.0),), shading=pyclray.Shading(shadows=True))
    box_origins = rng.uniform((-50.0, 0.0, -50.0), (50.0, 4.0, 50.0), (100_000, 3))
    box_directions = rng.normal(size=(100_000, 3))

    base = pyclray.Mesh.load(REPO / "scenes" / "meshes" / "bunny.ply")
    bunny = pyclray.Mesh(*subdivided(base.vertices, base.faces, 2))  # bench.meshes' 80,000 triangles
    million = pyclray.Mesh(*perturbed_sphere(500, 1000, 0.5, 0.02, np.random.default_rng(0)))
    work = {
        "tp02 512x512": lambda: pyclray.render(tp02, ("depth", "normal", "id")),
        "100k spheres render": lambda: pyclray.render(field, ("depth", "normal", "id")),
        "100k spheres render_views x8": lambda: list(pyclray.render_views(field, cameras, ("depth", "normal", "id"))),
        "100k spheres cast 100k": lambda: pyclray.cast(field, box_origins, box_directions),
        "100k spheres occluded 100k": lambda: pyclray.occluded(field, box_origins, box_directions),
        "100k spheres shaded, shadows": lambda: pyclray.render(lit, ("shaded",)),
    }
    for label, mesh in (("bunny", bunny), ("1M", million)):
        lo, hi = mesh.box()
        centre, radius = 0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo)  # bench.meshes' camera_for
        eye = centre + np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0]) * radius * 2.6
        scene = pyclray.Scene(pyclray.Camera(tuple(eye), tuple(centre), fov=45.0), pyclray.Image(size, size), (mesh,))
        origins = rng.uniform(lo, hi, (100_000, 3))
        directions = rng.normal(size=(100_000, 3))
        work[f"{label} primary"] = lambda scene=scene: pyclray.render(scene, ("depth", "normal", "id", "primitive"))
        work[f"{label} incoherent cast 100k"] = lambda scene=scene, o=origins, d=directions: pyclray.cast(scene, o, d)
        points = rng.uniform(lo, hi, (100_000, 3))
        work[f"{label} closest_points 100k"] = lambda scene=scene, p=points: pyclray.closest_points(scene, p)
        work[f"{label} signed_distance 100k"] = lambda scene=scene, p=points: pyclray.signed_distance(scene, p)
    return work


def subdivided(vertices, faces, times: int):
    """Each triangle split into four (midpoints), times over (bench.meshes' bunny: here, because this
    script imports none of bench/, whose other checkout may differ)."""
    for _ in range(times):
        edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = len(vertices) + inverse.reshape(3, -1).T  # (F, 3): midpoints of ab, bc, ca
        vertices = np.concatenate([vertices, 0.5 * (vertices[unique[:, 0]] + vertices[unique[:, 1]])])
        a, b, c = faces.T
        ab, bc, ca = mid.T
        faces = np.concatenate([np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return vertices, faces


def worker(block: int, only: str = "") -> None:
    """Time every workload (a block of calls each; only: those whose names contain one of its
    comma-separated words, where given) and print one JSON line: name -> [wall ms, CPU ms]."""
    import pyclray

    words = [w for w in only.split(",") if w]
    work = {k: v for k, v in _workloads().items() if not words or any(w in k for w in words)}
    for run in work.values():  # programs compiled, scenes prepared
        run()
    out = {"pyclray": str(Path(pyclray.__file__).parent)}
    for name, run in work.items():
        time.sleep(0.3)  # runtimes' threads wind down before the next workload
        run()
        walls, cpus = [], []
        for _ in range(block):
            wall, cpu = time.perf_counter(), time.process_time()
            run()
            walls.append(1e3 * (time.perf_counter() - wall))
            cpus.append(1e3 * (time.process_time() - cpu))
        out[name] = [statistics.median(walls), statistics.median(cpus)]
    print(json.dumps(out))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, help="the other checkout's root (its pyclray/ is imported)")
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--block", type=int, default=5)
    parser.add_argument("--only", default="", help="comma-separated words: the workloads whose names contain one")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        worker(args.block, args.only)
        return
    sides = {"this": str(REPO), "other": str(Path(args.against).resolve())}
    results = {side: [] for side in sides}
    for round_ in range(args.rounds):
        for side, root in sides.items():
            env = dict(os.environ, PYTHONPATH=root)
            done = subprocess.run([sys.executable, __file__, "--worker", "--against", root, "--block", str(args.block),
                                   "--only", args.only],
                                  env=env, capture_output=True, text=True, check=True)
            line = json.loads(done.stdout.strip().splitlines()[-1])
            assert line.pop("pyclray") == str(Path(root) / "pyclray"), "the other checkout's pyclray was not imported"
            results[side].append(line)
            print(f"round {round_ + 1} {side}: " + ", ".join(f"{k} {v[0]:.1f}" for k, v in line.items()), file=sys.stderr)
            time.sleep(1.0)
    print(f"| workload | this: wall ms (CPU) | other: wall ms (CPU) | this / other |\n|---|---|---|---|")
    for name in results["this"][0]:
        mine = [statistics.median(r[name][k] for r in results["this"]) for k in (0, 1)]
        theirs = [statistics.median(r[name][k] for r in results["other"]) for k in (0, 1)]
        print(f"| {name} | {mine[0]:.2f} ({mine[1]:.2f}) | {theirs[0]:.2f} ({theirs[1]:.2f}) | {mine[0] / theirs[0]:.3f} |")


if __name__ == "__main__":
    main()
