"""`pyclray animate` on a local Dask cluster of 1 and 2 worker processes against the local run, and
the cluster's overhead per task.

    python -m bench.cluster [SCENE] [--frames 96] [--size 512] [--output folder|mp4] [--rounds 3]

Each round runs the three commands as whole processes (interpreter start, cluster start and shut-down
included), in an order that rotates from round to round, with a 2 s pause at each switch; the table
gives each one's median wall time, the median of its frames phase (from its own last line: render
and encode, start-up excluded), and the speed-ups as ratios of medians. Every run's folder is checked
to hold the local run's files, byte for byte.

The overhead per task is measured in this process on a LocalCluster of one worker: frames of 8x8
pixels (depth only: the render itself takes a fraction of a millisecond) through the cluster against
the same frames rendered here, all tasks submitted at once (the throughput a long animation sees) and
one task at a time (the round trip). The machine's cores are shared with other work: rerun, and read
the spread.
"""
from __future__ import annotations

import argparse
import filecmp
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PAUSE_S = 2.0


def _children_cpu() -> float:
    """User + system seconds of the finished child processes (and theirs: the cluster's workers)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _same_tree(left: Path, right: Path) -> bool:
    if left.is_file():
        return filecmp.cmp(left, right, shallow=False)
    names = sorted(p.name for p in left.iterdir())
    return names == sorted(p.name for p in right.iterdir()) and all(
        filecmp.cmp(left / n, right / n, shallow=False) for n in names)


def commands(args, folder: Path) -> dict[str, list[str]]:
    out = "{folder}/%s" + ("/" if args.output == "folder" else ".mp4")
    base = [sys.executable, "-m", "pyclray.cli", "animate", args.scene, "--frames", f"0:{args.frames}",
            "--size", f"{args.size}x{args.size}"] + ([] if args.output == "folder" else ["--aov", "depth"])
    return {
        "local": base + ["-o", out.format(folder=folder) % "local"],
        "1 worker": base + ["-o", out.format(folder=folder) % "w1", "--workers", "1"],
        "2 workers": base + ["-o", out.format(folder=folder) % "w2", "--workers", "2"],
    }


def frames_phase(line: str) -> float:
    """The seconds of the frames phase in animate's last line (render, or render and encode on the workers)."""
    match = re.search(r"(?:render and encode on the workers|: render) ([0-9.]+) s", line)
    return float(match.group(1))


def speedups(args) -> None:
    walls, phases, cpus = {}, {}, {}
    with tempfile.TemporaryDirectory(prefix="pyclray-bench-cluster-") as tmp:
        folder = Path(tmp)
        runs = commands(args, folder)
        names = list(runs)
        for r in range(args.rounds):
            order = names[r % 3:] + names[:r % 3]
            for name in order:
                time.sleep(PAUSE_S)
                before = _children_cpu()
                start = time.perf_counter()
                result = subprocess.run(runs[name], capture_output=True, text=True)
                wall = time.perf_counter() - start
                cpus.setdefault(name, []).append(_children_cpu() - before)
                if result.returncode != 0:
                    sys.exit(f"{name}: {result.stderr.strip()}")
                walls.setdefault(name, []).append(wall)
                phases.setdefault(name, []).append(frames_phase(result.stdout.strip().splitlines()[-1]))
                print(f"round {r + 1}: {name}: {wall:.2f} s wall, frames {phases[name][-1]:.2f} s, "
                      f"{cpus[name][-1]:.2f} s CPU", flush=True)
            local = Path(runs["local"][runs["local"].index("-o") + 1])
            for name in names[1:]:
                other = Path(runs[name][runs[name].index("-o") + 1])
                if not _same_tree(local, other):
                    sys.exit(f"{name}: its output differs from the local run's")
    median = {n: statistics.median(v) for n, v in walls.items()}
    phase = {n: statistics.median(v) for n, v in phases.items()}
    print(f"\n{args.frames} frames of {args.size}x{args.size}, {args.output}, {args.rounds} rounds (medians; "
          f"outputs identical to the local run's):")
    cpu = {n: statistics.median(v) for n, v in cpus.items()}
    print("| run | wall s (min-max) | frames phase s | CPU s (all processes) | speed-up, wall | speed-up, frames phase |")
    print("|---|---|---|---|---|---|")
    for name in names:
        print(f"| {name} | {median[name]:.2f} ({min(walls[name]):.2f}-{max(walls[name]):.2f}) | {phase[name]:.2f} | "
              f"{cpu[name]:.2f} | {median['local'] / median[name]:.2f}x | {phase['local'] / phase[name]:.2f}x |")
    print(f"2 workers over 1: {median['1 worker'] / median['2 workers']:.2f}x wall, "
          f"{phase['1 worker'] / phase['2 workers']:.2f}x frames phase")


def overhead(args) -> None:
    import pyclray
    from pyclray import cluster

    scene = pyclray.load_scene(args.scene).with_size(8, 8)
    frames = list(range(scene.animation.frame_count()))
    count = args.tasks

    def local():
        start = time.perf_counter()
        done = 0
        while done < count:
            for _ in pyclray.render_animation(scene, aovs=("depth",), frames=frames[:count - done]):
                done += 1
        return (time.perf_counter() - start) / count

    def pipelined(client):
        start = time.perf_counter()
        done = 0
        while done < count:
            for _ in cluster.render_animation(client, scene, aovs=("depth",), frames=frames[:count - done]):
                done += 1
        return (time.perf_counter() - start) / count

    def round_trip(client, n=50):
        job = cluster.Job(scene, aovs=("depth",))
        client.register_plugin(job, name=job.name)
        start = time.perf_counter()
        for k in range(n):
            client.submit(cluster._task, job.name, "frame", frames[k % len(frames)], pure=False).result()
        elapsed = (time.perf_counter() - start) / n
        client.unregister_worker_plugin(job.name)
        return elapsed

    with cluster.connect(workers=1) as client:
        local(), pipelined(client)  # warm: programs here and on the worker
        rows = []
        for _ in range(args.rounds):
            time.sleep(PAUSE_S)
            here = local()
            time.sleep(PAUSE_S)
            rows.append((here, pipelined(client)))
        here = statistics.median(r[0] for r in rows)
        there = statistics.median(r[1] for r in rows)
        time.sleep(PAUSE_S)
        trip = round_trip(client)
    print(f"\nper task, 8x8 depth frames, 1 worker, {count} tasks a run, {args.rounds} rounds (medians):")
    print(f"  local render {here * 1e3:.2f} ms; on the cluster {there * 1e3:.2f} ms: overhead {(there - here) * 1e3:.2f} ms "
          "a task when all are submitted at once")
    print(f"  one task at a time (submit, wait, fetch) in a warm job: {trip * 1e3:.1f} ms a task")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.cluster")
    parser.add_argument("scene", nargs="?", default=str(REPO / "scenes" / "tp02_orbit.toml"))
    parser.add_argument("--frames", type=int, default=96)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--output", choices=("folder", "mp4"), default="folder")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--tasks", type=int, default=100, help="tasks a run for the overhead per task")
    parser.add_argument("--only", choices=("speedups", "overhead"))
    args = parser.parse_args(argv)
    os.environ.setdefault("PYCLRAY_CACHE_DIR", str(Path(tempfile.gettempdir()) / "pyclray-bench-cluster-cache"))
    if args.only != "overhead":
        speedups(args)
    if args.only != "speedups":
        overhead(args)


if __name__ == "__main__":
    main()
