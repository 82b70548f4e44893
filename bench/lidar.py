"""LiDAR scans (issue 39's targets): a VLP-16 scan of a 1,000,000-triangle scene, and sweeping scans
of an animated scene.

    python -m bench.lidar [--rounds 3] [--block 5] [--sweeps 100]

Cases, each timed in rotating blocks with a pause at each switch (bench.open3d_compare.blocks):
- "scan": pyclray.scan of a VLP-16 (16 x 1800 beams) at the centre of a closed 998,000-triangle
  mesh (a perturbed UV sphere of radius 20: every beam returns), against its baselines in the same
  process: pyclray.cast of the same 28,800 float64 rays (depth, normal, id: what a scan adds beyond
  the cast is the rays, the range limits, the labels and the point cloud) and Open3D's
  RaycastingScene.cast_rays of the same rays (float32, Embree) where Open3D is installed;
  the scan's PLY file is read back with Open3D's read_point_cloud (points and normals);
- "sweeps": scans/s of `--sweeps` sweeping VLP-16 scans (sweep = true, 10 Hz) of an animated scene
  (a ground plane, 20 still boxes and a car driving past: one moving shape), each starting at
  the next 1/10 s, with the revolution cut into steps time slices: every column at its own time
  (steps = 1800, the default) and coarser (360, 36); and with the car still and the sensor
  moving (one cast per scan: the rays move, not the shapes); and a car driving past inside the
  1,000,000-triangle scene (its still shapes prepared once, the car alone updated per time slice).
Prints medians (ms), the ratios, scans/s and the machine's load (uptime): the machine is shared.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import time

import numpy as np

import pyclray
from pyclray.model.shapes.mesh_shapes import perturbed_sphere

from .meshes import with_cpu
from .open3d_compare import blocks


def million_triangle_scene():
    vertices, faces = perturbed_sphere(500, 1000, 20.0, 0.02, np.random.default_rng(0))
    mesh = pyclray.Mesh(vertices, faces, name="sphere")
    lidar = pyclray.Lidar(preset="VLP-16", name="vlp16")
    return pyclray.Scene(pyclray.Camera((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)), pyclray.Image(8, 8),
                         (mesh,), lidars=(lidar,)), mesh, lidar


def scan_case(rounds: int, block: int) -> dict:
    scene, mesh, lidar = million_triangle_scene()
    origin, directions = lidar.rays()
    directions = directions.reshape(-1, 3)
    systems = {
        "pyclray.scan": lambda: pyclray.scan(scene, lidar),
        "pyclray.cast (same rays)": lambda: pyclray.cast(scene, origin, directions),
    }
    try:
        import open3d as o3d

        o3d_scene = o3d.t.geometry.RaycastingScene()
        o3d_scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                                o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
        rays = o3d.core.Tensor(np.hstack([np.tile(origin, (len(directions), 1)), directions]).astype(np.float32))
        systems["Open3D cast_rays (same rays)"] = lambda: o3d_scene.cast_rays(rays)
    except ImportError:
        pass
    scan = pyclray.scan(scene, lidar)
    print(f"scan: {len(scan['ring'])} of {lidar.beams * lidar.columns} beams return, "
          f"{sum(int(np.asarray(s.faces).shape[0]) for s in scene.shapes)} triangles")
    if "Open3D cast_rays (same rays)" in systems:  # the PLY file read back by Open3D (docs/lidar.md)
        import tempfile

        with tempfile.TemporaryDirectory() as folder:
            path = os.path.join(folder, "scan.ply")
            pyclray.write_ply(path, scan)
            cloud = o3d.io.read_point_cloud(path)
            same = np.array_equal(np.asarray(cloud.points), scan["points_world"])
            print(f"Open3D read the scan's PLY: {len(cloud.points)} points, normals {cloud.has_normals()}, "
                  f"points equal to points_world: {same}")
    timed, cpu = with_cpu(systems)
    results = blocks(timed, rounds, block)
    for name, values in cpu.items():  # each call's process CPU time (all threads), ms
        results[name]["cpu"] = float(np.median(values)) * 1e3
    return results


SWEEP_SCENE = """
[[shapes]]
type = "plane"
normal = [0.0, 0.0, 1.0]
offset = 1.8
{boxes}
[[shapes]]
type = "box"
name = "car"
center = [8.0, -20.0, -1.0]
size = [4.5, 1.8, 1.5]

[lidar]
name = "roof"
preset = "VLP-16"
sweep = true
range = [0.5, 100.0]
{sensor}

[animation]
fps = 10.0
duration = 11.0

[[animation.keys]]
target = "car"
time = 0.0
center = [8.0, -20.0, -1.0]

[[animation.keys]]
target = "car"
time = 10.0
center = [8.0, 20.0, -1.0]
{keys}
"""


def sweep_scene(folder, steps: int | None, moving: str):
    rng = np.random.default_rng(1)
    boxes = "".join(f'\n[[shapes]]\ntype = "box"\ncenter = [{x:.3f}, {y:.3f}, -1.0]\nsize = [1.0, 1.0, 1.5]\n'
                    for x, y in rng.uniform(-30, 30, (20, 2)))
    sensor = "" if steps is None else f"steps = {steps}"
    keys = ""
    if moving == "sensor":
        sensor += "\nposition = [0.0, 0.0, 0.0]"
        keys = ('\n[[animation.keys]]\ntarget = "roof"\ntime = 0.0\nposition = [0.0, 0.0, 0.0]\n'
                '\n[[animation.keys]]\ntarget = "roof"\ntime = 10.0\nposition = [100.0, 0.0, 0.0]\n')
    text = SWEEP_SCENE.format(boxes=boxes, sensor=sensor, keys=keys)
    if moving == "sensor":  # the car parked: its keys removed
        text = text.split('[[animation.keys]]\ntarget = "car"')[0] + keys
    path = os.path.join(folder, f"sweep-{steps}-{moving}.toml")
    with open(path, "w") as file:
        file.write(text)
    return pyclray.load_scene(path)


def sweeps_case(count: int) -> list[tuple[str, float, float, float]]:
    import tempfile

    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for label, steps, moving in (("car moving, steps = 1800 (every column its own time)", None, "car"),
                                     ("car moving, steps = 360", 360, "car"),
                                     ("car moving, steps = 36", 36, "car"),
                                     ("sensor moving, steps = 1800", None, "sensor")):
            scene = sweep_scene(folder, steps, moving)
            pyclray.scan(scene, time=0.0)  # the handle and its programs
            start, cpu = time.perf_counter(), time.process_time()
            for k in range(count):
                pyclray.scan(scene, time=k / 10.0)
            elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
            rows.append((label, count / elapsed, elapsed / count * 1e3, cpu / count * 1e3))
    # a large still scene: a box driving past inside the 998,000-triangle mesh (every beam returns)
    big, mesh, _ = million_triangle_scene()
    car = pyclray.Box((8.0, -6.0, 0.0), (4.5, 1.8, 1.5), name="car")
    animation = pyclray.Animation(10.0, 11.0, ({"target": "car", "time": 0.0, "center": [8.0, -6.0, 0.0]},
                                               {"target": "car", "time": 10.0, "center": [8.0, 6.0, 0.0]}))
    lidar = pyclray.Lidar(preset="VLP-16", sweep=True, name="vlp16")
    scene = dataclasses.replace(big, shapes=(mesh, car), lidars=(lidar,), animation=animation)
    pyclray.scan(scene, time=0.0)
    count = max(1, count // 10)
    start, cpu = time.perf_counter(), time.process_time()
    for k in range(count):
        pyclray.scan(scene, time=k / 10.0)
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    rows.append((f"car moving inside the 998,000-triangle mesh, steps = 1800 ({count} scans)", count / elapsed,
                 elapsed / count * 1e3, cpu / count * 1e3))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--block", type=int, default=5)
    parser.add_argument("--sweeps", type=int, default=100)
    args = parser.parse_args()
    print("load before:", os.getloadavg())
    results = scan_case(args.rounds, args.block)
    base = results["pyclray.scan"]["median"]
    print("| VLP-16 scan, 998,000 triangles | median ms | q1-q3 | CPU ms (all threads) | scan / this |")
    print("|---|---|---|---|---|")
    for name, r in results.items():
        print(f"| {name} | {r['median']:.2f} | {r['q1']:.2f}-{r['q3']:.2f} | {r['cpu']:.1f} | "
              f"{base / r['median']:.2f} |")
    print(f"\n| {args.sweeps} sweeping VLP-16 scans | scans/s | ms per scan | CPU ms per scan (all threads) |")
    print("|---|---|---|---|")
    for label, rate, ms, cpu in sweeps_case(args.sweeps):
        print(f"| {label} | {rate:.1f} | {ms:.1f} | {cpu:.1f} |")
    print("load after:", os.getloadavg())


if __name__ == "__main__":
    main()
