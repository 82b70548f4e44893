"""A BOP data set's speed (issue 40): views/s of `--format bop` for a 5-object scene of 500k
triangles at 640x480, here, and on a local Dask cluster of 2 workers against 1.

    python bench/dataset_bop.py [VIEWS] [CLUSTER_VIEWS] [SPLIT_VIEWS]     # default 100, 60 and 0

Each object is a torus mesh of 100,000 triangles (labels 1..5) on a ground plane, under a light
(rgb is the shaded image). The local run writes VIEWS views after a warm-up of 4 (the programs built
and the scene prepared; their time is reported apart) and extrapolates to 1,000 views, with the
process's CPU time (all its threads: PoCL's, the writers'), the figure a shared machine moves least;
the cluster
runs alternate 1 and 2 workers, two blocks each, with a pause between, and report the views/s of
each once its workers are warm (from the end of each worker's first task: the scene prepared there,
the programs built), and in all. SPLIT_VIEWS: where a view's CPU time goes (the process's, all its
threads, per view, blocks of SPLIT_VIEWS views after a warm-up): the scene's render alone (zdepth,
id, shaded), the scene's and the objects' renders as the data set makes them (DatasetViews.views),
and the format's encoding of the view's files (records and PNGs, a writer's work)."""
from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import pyclray
from pyclray.io.dataset import Placement, make_format, view_cameras, write_dataset


def torus(rings: int = 250, sides: int = 200, major: float = 1.0, minor: float = 0.35):
    """A torus mesh of 2 rings sides triangles, around z."""
    u = np.linspace(0, 2 * np.pi, rings, endpoint=False)
    v = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    U, V = np.meshgrid(u, v, indexing="ij")
    vertices = np.stack([(major + minor * np.cos(V)) * np.cos(U), (major + minor * np.cos(V)) * np.sin(U),
                         minor * np.sin(V)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rings), np.arange(sides), indexing="ij")
    a = i * sides + j
    b = ((i + 1) % rings) * sides + j
    c = ((i + 1) % rings) * sides + (j + 1) % sides
    d = i * sides + (j + 1) % sides
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return vertices, faces


def bench_scene() -> pyclray.Scene:
    vertices, faces = torus()
    places = [(-1.2, 0.35, -0.4, 0.0), (0.9, 0.4, -0.6, 40.0), (0.0, 0.5, 0.6, 80.0), (-0.8, 0.6, 1.1, 120.0),
              (1.3, 0.3, 0.9, 160.0)]
    shapes = [pyclray.Plane((0.0, 1.0, 0.0), 0.0, name="ground")]
    for label, (x, y, z, angle) in enumerate(places, start=1):
        shapes.append(pyclray.Mesh(vertices, faces, scale=0.45, axis=(1.0, 0.3, 0.0), angle=angle + 60.0,
                                   translate=(x, y, z), name=f"torus{label}", label=label))
    camera = pyclray.Camera((0.0, 2.5, 5.0), (0.0, 0.4, 0.0), fov=50.0)
    lights = (pyclray.PointLight((3.0, 5.0, 4.0), (30.0, 30.0, 30.0), name="key"),)
    return pyclray.Scene(camera, pyclray.Image(640, 480), tuple(shapes), lights=lights)


def local(scene, count: int) -> None:
    fmt = make_format("bop")
    cameras = view_cameras(scene, Placement("hemisphere", (4.0, 6.0), (15.0, 70.0), 1), count + 4)
    folder = Path(tempfile.mkdtemp(prefix="pyclray-bench-dataset-"))
    try:
        start = time.perf_counter()
        write_dataset(scene, folder / "warm", cameras[:4], fmt)
        warm = time.perf_counter() - start
        start, cpu = time.perf_counter(), time.process_time()
        written = write_dataset(scene, folder / "run", cameras[4:], fmt)
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    rate = written.rendered / seconds
    print(f"here: {written.rendered} views in {seconds:.2f} s = {rate:.2f} views/s (render loop {written.render_seconds:.2f} s, "
          f"writers busy {written.writer_seconds:.2f} s; warm-up of 4 views with builds {warm:.2f} s); "
          f"1,000 views: {1000 / rate:.0f} s extrapolated; the process's CPU time (all its threads) {cpu:.2f} s, "
          f"{1000 * cpu / written.rendered:.0f} ms a view")


class Clock:
    """A progress object that notes when each view was written."""

    def __init__(self):
        self.times = []

    def update(self, n: int = 1) -> None:
        self.times.extend([time.perf_counter()] * n)

    def rate(self, skip: int) -> float:
        """Views/s from the view after the first `skip` to the last (the steady state)."""
        times = self.times[skip - 1:] if skip else self.times
        return (len(times) - 1) / (times[-1] - times[0])


def cluster(scene, count: int) -> None:
    from pyclray.apps import cluster as dask_cluster
    from pyclray.io.dataset import REMOTE_BATCH

    fmt = make_format("bop")
    cameras = view_cameras(scene, Placement("hemisphere", (4.0, 6.0), (15.0, 70.0), 2), count)
    rates = {1: [], 2: []}
    for block in range(2):
        for workers in (1, 2):
            folder = Path(tempfile.mkdtemp(prefix="pyclray-bench-dataset-"))
            clock = Clock()
            try:
                with dask_cluster.connect(workers) as client:
                    remote = lambda work, todo: dask_cluster.map_work(client, work, todo)
                    start = time.perf_counter()
                    written = write_dataset(scene, folder / "run", cameras, fmt, remote=remote, progress=clock)
                    seconds = time.perf_counter() - start
            finally:
                shutil.rmtree(folder, ignore_errors=True)
            # the steady state: from the end of each worker's first task (its prepare, builds) to the last view
            steady = clock.rate(REMOTE_BATCH * workers)
            rates[workers].append(steady)
            print(f"block {block}: {workers} worker{'s' if workers > 1 else ''}: {written.rendered} views in {seconds:.2f} s "
                  f"({written.rendered / seconds:.2f} views/s with each worker's prepare); steady {steady:.2f} views/s")
            time.sleep(2)
    best = {w: max(r) for w, r in rates.items()}
    print(f"2 workers / 1 worker, steady views/s: {best[2] / best[1]:.2f}x (best of 2 blocks each)")


def split(scene, count: int) -> None:
    from pyclray.io.dataset import DatasetViews

    fmt = make_format("bop")
    cameras = view_cameras(scene, Placement("hemisphere", (4.0, 6.0), (15.0, 70.0), 1), count + 4)
    work = DatasetViews(scene, cameras, fmt)
    handle = pyclray.prepare(scene)
    try:
        rendered = list(work.views(range(4)))  # the programs built, the scene and the objects prepared
        handle.render(cameras[0], aovs=fmt.aovs)
        for block in range(2):
            cpu = time.process_time()
            for camera in cameras[4:]:
                handle.render(camera, aovs=fmt.aovs)
            scene_cpu = time.process_time() - cpu
            cpu = time.process_time()
            rendered = list(work.views(range(4, count + 4)))
            views_cpu = time.process_time() - cpu
            cpu = time.process_time()
            for view in rendered:
                encoded = work.encode(view)
                for value in encoded.files.values():
                    value() if callable(value) else value
            encode_cpu = time.process_time() - cpu
            print(f"split, block {block}: CPU ms per view: the scene's render {1000 * scene_cpu / count:.1f}, the scene's "
                  f"and the objects' renders {1000 * views_cpu / count:.1f} (the objects' "
                  f"{1000 * (views_cpu - scene_cpu) / count:.1f}), encoding {1000 * encode_cpu / count:.1f}")
            time.sleep(1)
    finally:
        handle.close()
        work.close()


def main() -> None:
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    cluster_count = int(sys.argv[2]) if len(sys.argv) > 2 else 60
    split_count = int(sys.argv[3]) if len(sys.argv) > 3 else 0
    scene = bench_scene()
    triangles = sum(s.primitive_count() for s in scene.shapes if s.label is not None)
    print(f"scene: {triangles:,} triangles in 5 labelled meshes, 640x480")
    if count:
        local(scene, count)
    if cluster_count:
        cluster(scene, cluster_count)
    if split_count:
        split(scene, split_count)


if __name__ == "__main__":
    main()
