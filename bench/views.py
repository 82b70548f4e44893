"""Build once, render many: the targets of the device-resident scene (pyclray.engine.scene.prepared).

    python -m bench.views               # everything (a few minutes; Open3D part only if installed)
    python -m bench.views --quick       # 100,000 spheres only
    python -m bench.views --animation   # the animation only

Each figure is a ratio of two systems measured in this process, in blocks (bench/blocks.py's rule:
each system runs a block of calls on its own, with a pause at each switch, rounds in rotating order,
the median of all timed calls):

- views: a render from the same camera again, and from a new camera each call (an orbit), at
  256x256 (depth, normal, id), over a ground plane and N spheres, as one pyclray.Spheres batch and
  (100,000 only) as N pyclray.Sphere objects; target moved / same <= 1.5;
- data set: render_views over 200 cameras at 100,000 spheres against Open3D's RaycastingScene
  casting the same pinhole rays per view (the spheres as triangle meshes, as its users must);
  target: pyclray at least 2x faster per view;
- a million spheres: pyclray.Spheres(centers, radii) construction (<= 1 s), the first render of a
  new process's scene (<= 3 s, program build from the disk cache), bytes held per sphere (<= 64);
- animation: 100,000 sphere objects of which 10 move, per frame (render_animation) against a static
  render of one frame from the same camera; target <= 1.5.
"""
from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

import numpy as np

import pyclray
from pyclray.engine import api
from pyclray.engine.scene import prepared
from pyclray.engine.opencl.device import context_for
from pyclray.model.animation import Animation

from . import scale

SIZE = 256
AOVS = ("depth", "normal", "id")
PAUSE = 0.5
ROUNDS = 3
BLOCK = 12  # timed calls per block


def orbit(count: int, radius: float = 24.0):
    """Cameras around the field, looking at its centre (a new one each call)."""
    angles = np.linspace(0.0, 2 * np.pi, count, endpoint=False)
    return [pyclray.Camera((radius * np.sin(a), scale.EYE[1], radius * np.cos(a)), scale.TARGET, fov=scale.FOV) for a in angles]


def batch_scene(count: int) -> pyclray.Scene:
    centres, radii = scale.sphere_field(count)
    shapes = (pyclray.Plane((0.0, 1.0, 0.0), 0.0), pyclray.Spheres(centres, radii))
    return pyclray.Scene(pyclray.Camera(scale.EYE, scale.TARGET, fov=scale.FOV), pyclray.Image(SIZE, SIZE), shapes)


def blocks(cases: dict, rounds: int = ROUNDS, block: int = BLOCK) -> dict:
    """Median seconds per call of each case (a callable taking the call's index), in blocks."""
    times = {name: [] for name in cases}
    names = list(cases)
    for r in range(rounds):
        for name in names[r % len(names):] + names[: r % len(names)]:
            run = cases[name]
            for k in range(2):  # warm
                run(k)
            for k in range(block):
                start = time.perf_counter()
                run(k)
                times[name].append(time.perf_counter() - start)
            time.sleep(PAUSE)
    return {name: statistics.median(values) for name, values in times.items()}


def views(scene: pyclray.Scene, label: str) -> dict:
    cameras = orbit(ROUNDS * (BLOCK + 2) + 1)
    pyclray.render(scene, AOVS)  # prepare and build
    counter = iter(range(10**9))
    result = blocks({
        "same camera": lambda k: pyclray.render(scene, AOVS),
        "moved camera": lambda k: pyclray.render(scene, AOVS, camera=cameras[next(counter) % len(cameras)]),
    })
    ratio = result["moved camera"] / result["same camera"]
    print(f"  {label}: same camera {1e3 * result['same camera']:.1f} ms, moved camera "
          f"{1e3 * result['moved camera']:.1f} ms: moved / same {ratio:.2f} (target <= 1.5)")
    return {"same_ms": 1e3 * result["same camera"], "moved_ms": 1e3 * result["moved camera"], "ratio": ratio}


def data_set(count: int = 100_000, cameras: int = 200) -> dict | None:
    try:
        import open3d as o3d
    except ImportError:
        print("  data set: Open3D is not installed (pip install 'pyclray[bench]'); skipped")
        return None
    scene = batch_scene(count)
    poses = orbit(cameras)
    o3d_scene, triangles = scale.open3d_scene(count)
    pyclray.render(scene, AOVS)

    def ours():
        for frame in pyclray.render_views(scene, poses, aovs=AOVS):
            pass

    def theirs():
        for camera in poses:
            rays = o3d.t.geometry.RaycastingScene.create_rays_pinhole(
                fov_deg=scale.FOV, center=list(camera.target), eye=list(camera.eye), up=[0.0, 1.0, 0.0],
                width_px=SIZE, height_px=SIZE)
            answer = o3d_scene.cast_rays(rays)
            answer["t_hit"].numpy(), answer["primitive_normals"].numpy(), answer["geometry_ids"].numpy()

    # the process's CPU time too (all threads: PoCL's and Embree's): on the shared machine another
    # process's load stretches the wall time of both, the CPU time of neither
    cpu = {"pyclray": [], "open3d": []}

    def on_cpu(name, run):
        start = time.process_time()
        run()
        cpu[name].append(time.process_time() - start)

    result = blocks({"pyclray": lambda k: on_cpu("pyclray", ours), "open3d": lambda k: on_cpu("open3d", theirs)},
                    rounds=2, block=2)
    per_view = {name: 1e3 * seconds / cameras for name, seconds in result.items()}
    cpu_view = {name: 1e3 * statistics.median(values) / cameras for name, values in cpu.items()}
    ratio = per_view["open3d"] / per_view["pyclray"]
    print(f"  data set of {cameras} views at {count:,} spheres: pyclray {per_view['pyclray']:.2f} ms/view, "
          f"Open3D ({triangles:,} triangles) {per_view['open3d']:.2f} ms/view: {ratio:.2f}x (target >= 2); CPU time "
          f"per view {cpu_view['pyclray']:.2f} against {cpu_view['open3d']:.2f} ms: "
          f"{cpu_view['open3d'] / cpu_view['pyclray']:.2f}x")
    return {"pyclray_ms_per_view": per_view["pyclray"], "open3d_ms_per_view": per_view["open3d"], "speedup": ratio,
            "pyclray_cpu_ms_per_view": cpu_view["pyclray"], "open3d_cpu_ms_per_view": cpu_view["open3d"]}


def million(count: int = 1_000_000) -> dict:
    centres, radii = scale.sphere_field(count)
    start = time.perf_counter()
    batch = pyclray.Spheres(centres, radii)
    built = time.perf_counter() - start
    scene = pyclray.Scene(pyclray.Camera(scale.EYE, scale.TARGET, fov=scale.FOV), pyclray.Image(SIZE, SIZE),
                          (pyclray.Plane((0.0, 1.0, 0.0), 0.0), batch))
    pyclray.clear_cache()
    start = time.perf_counter()
    pyclray.render(scene, AOVS)
    first = time.perf_counter() - start
    held = api.tracer_for(scene, context_for(None), "fp32").prepared.nbytes()
    print(f"  {count:,} spheres: Spheres() {built:.3f} s (target <= 1), first render {first:.2f} s (target <= 3; "
          f"program from the caches), {held / count:.1f} bytes per sphere (target <= 64)")
    return {"construct_s": built, "first_render_s": first, "bytes_per_sphere": held / count, "scene": scene}


def animation(count: int = 100_000, moving: int = 10) -> dict:
    centres, radii = scale.sphere_field(count)
    shapes = [pyclray.Plane((0.0, 1.0, 0.0), 0.0)]
    shapes += [pyclray.Sphere(tuple(c), float(r), name=f"s{i}") for i, (c, r) in enumerate(zip(centres.tolist(), radii.tolist()))]
    picked = np.linspace(0, count - 1, moving).astype(int)
    keys = []
    for i in picked:
        start = list(centres[i])
        keys += [{"target": f"s{i}", "time": 0.0, "center": start},
                 {"target": f"s{i}", "time": 10.0, "center": [start[0] + 8.0, start[1], start[2] - 8.0]}]
    fps = 24.0
    scene = pyclray.Scene(pyclray.Camera(scale.EYE, scale.TARGET, fov=scale.FOV), pyclray.Image(SIZE, SIZE), tuple(shapes),
                          animation=Animation.from_table({"fps": fps, "duration": 10.0, "keys": keys}))
    frames = iter(range(1, 10**9))
    static = scene.at(0.0)
    pyclray.render(static, AOVS)
    sequence = pyclray.render_animation(scene, AOVS, frames=frames)
    times = [next(sequence)[0]]  # each frame's time, the last one's scene measured below
    cpu = {"static": [], "animated": []}  # process CPU time of each call (PoCL's threads too): less shaken by load

    def timed(name, call):
        def run(k):
            start = time.process_time()
            call()
            cpu[name].append(time.process_time() - start)
        return run

    result = blocks({"static": timed("static", lambda: pyclray.render(static, AOVS)),
                     "animated": timed("animated", lambda: times.append(next(sequence)[0]))})
    ratio = result["animated"] / result["static"]
    cpu_ratio = statistics.median(cpu["animated"]) / statistics.median(cpu["static"])
    # what the refits did to the tree: the last frame's against the tree built for the static scene
    # (the frames and the static renders take turns on one prepared scene, refitted from that
    # tree), and what a rebuild of this scene would cost
    from pyclray.engine.bvh.tree import sah_cost

    ctx = context_for(None)
    built = sah_cost(prepared.PreparedScene(ctx, static.shapes, "fp32").bvh.tree)
    last = next(t.prepared for t in api._tracers.values() if t.prepared.base is scene.shapes)
    growth = sah_cost(last.bvh.tree) / built
    start = time.perf_counter()
    prepared.PreparedScene(ctx, last.shapes, "fp32")
    rebuild = time.perf_counter() - start
    print(f"  animation, {moving} of {count:,} spheres moving: {1e3 * result['animated']:.1f} ms a frame, static render "
          f"{1e3 * result['static']:.1f} ms: {ratio:.2f} (target <= 1.5; process CPU time {cpu_ratio:.2f}); after "
          f"{ROUNDS * (BLOCK + 2) + 1} frames the refitted tree's SAH cost is {growth:.4f} of the built one's; a rebuild "
          f"would take {rebuild:.2f} s")
    return {"frame_ms": 1e3 * result["animated"], "static_ms": 1e3 * result["static"], "ratio": ratio,
            "cpu_ratio": cpu_ratio, "sah_growth": growth, "rebuild_s": rebuild}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="100,000 spheres only")
    parser.add_argument("--animation", action="store_true", help="the animation only")
    args = parser.parse_args(argv)
    print(f"pyclray views, {SIZE}x{SIZE} {','.join(AOVS)}, on {context_for(None).device.name.strip()}")
    if args.animation:
        animation()
        return
    views(batch_scene(100_000), "100,000 spheres (one Spheres batch)")
    views(scale.scene(100_000, size=SIZE), "100,000 spheres (Sphere objects)")
    if not args.quick:
        big = million()
        views(big.pop("scene"), "1,000,000 spheres (one Spheres batch)")
        data_set()
    animation()


if __name__ == "__main__":
    main()
