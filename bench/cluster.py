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
    base = [sys.executable, "-m", "pyclray", "animate", args.scene, "--frames", f"0:{args.frames}",
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


def _start_cluster(workers: int, folder: Path):
    """A scheduler and `workers` worker processes (one task thread each, PoCL threads as --workers
    gives them), each started as its own command in a session of its own (see --sessions)."""
    from distributed import Client

    dask = str(Path(sys.executable).parent / "dask")
    file = folder / f"scheduler-{workers}.json"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    processes = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                   "--scheduler-file", str(file)], **quiet)]
    threads = str(max(1, len(os.sched_getaffinity(0)) // workers))
    # the nannies leave MALLOC_TRIM_THRESHOLD_ out, as in a local cluster (docs/clusters.md)
    config = folder / "dask-config"
    config.mkdir(exist_ok=True)
    (config / "pyclray.yaml").write_text("distributed: {nanny: {pre-spawn-environ: {MALLOC_TRIM_THRESHOLD_: null}}}\n")
    env = dict(os.environ, POCL_CPU_MAX_CU_COUNT=threads, POCL_MAX_PTHREAD_COUNT=threads, DASK_CONFIG=str(config))
    for _ in range(workers):
        processes.append(subprocess.Popen([dask, "worker", "--scheduler-file", str(file), "--host", "127.0.0.1",
                                           "--nthreads", "1", "--nworkers", "1", "--no-dashboard"], env=env, **quiet))
    deadline = time.monotonic() + 120
    while not file.exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    with Client(scheduler_file=str(file), set_as_default=False) as client:
        client.wait_for_workers(workers, timeout=120)
        trims = client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))
        assert set(trims.values()) == {None}, trims
        return processes, client.scheduler.address


def _stop(processes) -> None:
    for process in processes:
        process.terminate()
    for process in processes:
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def sessions(args) -> None:
    """1 worker against 2, each worker (and the scheduler) in a session of its own, the commands
    reaching them with --scheduler. Linux shares the CPU fairly between sessions (autogroups), not
    between processes: while other sessions keep the cores busy, every process of one session
    together gets one session's share, so `--workers 2` (whose workers are in the command's session)
    can go no faster than `--workers 1` on a machine shared that way. A worker per session gets a
    share per worker, as a worker gets a core of its own on an idle machine."""
    walls, phases = {}, {}
    with tempfile.TemporaryDirectory(prefix="pyclray-bench-cluster-") as tmp:
        folder = Path(tmp)
        clusters = {n: _start_cluster(n, folder) for n in (1, 2)}
        try:
            base = [sys.executable, "-m", "pyclray", "animate", args.scene, "--frames", f"0:{args.frames}",
                    "--size", f"{args.size}x{args.size}"] + ([] if args.output == "folder" else ["--aov", "depth"])
            suffix = "/" if args.output == "folder" else ".mp4"
            names = {1: "1 worker", 2: "2 workers"}
            for r in range(args.rounds):
                for n in ((1, 2) if r % 2 == 0 else (2, 1)):
                    time.sleep(PAUSE_S)
                    out = f"{folder}/s{n}{suffix}"
                    start = time.perf_counter()
                    result = subprocess.run(base + ["-o", out, "--scheduler", clusters[n][1]], capture_output=True, text=True)
                    wall = time.perf_counter() - start
                    if result.returncode != 0:
                        sys.exit(f"{names[n]}: {result.stderr.strip()}")
                    walls.setdefault(n, []).append(wall)
                    phases.setdefault(n, []).append(frames_phase(result.stdout.strip().splitlines()[-1]))
                    print(f"round {r + 1}: {names[n]} (own sessions): {wall:.2f} s wall, frames {phases[n][-1]:.2f} s", flush=True)
            if not _same_tree(Path(f"{folder}/s1{suffix}"), Path(f"{folder}/s2{suffix}")):
                sys.exit("the outputs of 1 and 2 workers differ")
        finally:
            for processes, _ in clusters.values():
                _stop(processes)
    wall = {n: statistics.median(v) for n, v in walls.items()}
    phase = {n: statistics.median(v) for n, v in phases.items()}
    print(f"\nworkers in sessions of their own, {args.frames} frames of {args.size}x{args.size}, {args.output}, "
          f"{args.rounds} rounds (medians; clusters started beforehand):")
    print("| run | wall s (min-max) | frames phase s |")
    print("|---|---|---|")
    for n in (1, 2):
        print(f"| {n} worker{'s' if n > 1 else ''} | {wall[n]:.2f} ({min(walls[n]):.2f}-{max(walls[n]):.2f}) | {phase[n]:.2f} |")
    pairs = [a / b for a, b in zip(walls[1], walls[2])]  # round by round: the machine's drift cancels
    print(f"2 workers over 1: {wall[1] / wall[2]:.2f}x wall, {phase[1] / phase[2]:.2f}x frames phase (medians); "
          f"round by round {', '.join(f'{p:.2f}x' for p in pairs)}, median {statistics.median(pairs):.2f}x")


def overhead(args) -> None:
    import pyclray
    from pyclray.apps import cluster

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

    def task(job: str, method: str, argument):
        """One task as pyclray.cluster.run submits it: the method of the Job the worker holds."""
        from distributed import get_worker

        return getattr(get_worker().plugins[job], method)(argument)

    def round_trip(client, n=50):
        job = cluster.Job(scene, aovs=("depth",))
        client.register_plugin(job, name=job.name)
        start = time.perf_counter()
        for k in range(n):
            client.submit(task, job.name, "frame", frames[k % len(frames)], pure=False).result()
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
    parser.add_argument("--only", choices=("speedups", "sessions", "overhead"))
    args = parser.parse_args(argv)
    os.environ.setdefault("PYCLRAY_CACHE_DIR", str(Path(tempfile.gettempdir()) / "pyclray-bench-cluster-cache"))
    if args.only in (None, "speedups"):
        speedups(args)
    if args.only in (None, "sessions"):
        sessions(args)
    if args.only in (None, "overhead"):
        overhead(args)


if __name__ == "__main__":
    main()
