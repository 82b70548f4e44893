"""Frames per second of an animation: render only, encode only, and `pyclray animate` end to end
(render and encode overlapped in a writer thread), in one process, in rounds that alternate them.

    python -m bench.animation [SCENE] [--size N] [--rounds R]

Default: scenes/tp02_orbit.toml (the exercise's scene, orbiting camera and a bouncing ball, 100
frames) at 512x512. The ratios compare each to render only, measured in the same rounds.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import resource
import statistics
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def main(argv=None) -> None:
    import pyclray
    from pyclray.apps import cli
    from pyclray.io import video

    parser = argparse.ArgumentParser(prog="python -m bench.animation")
    parser.add_argument("scene", nargs="?", default=str(REPO / "scenes" / "tp02_orbit.toml"))
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)

    scene = pyclray.load_scene(args.scene).with_size(args.size, args.size)
    count = scene.animation.frame_count()
    frames = [frame for _, frame in pyclray.render_animation(scene, aovs=("depth",))]  # warms the programs

    def render_only():
        for _ in pyclray.render_animation(scene, aovs=("depth",)):
            pass

    def encode_only(suffix):
        def run():
            with tempfile.TemporaryDirectory() as folder:
                out = Path(folder) / f"x{suffix}"
                tmp = str(out) + ".tmp"
                if suffix == ".mp4":
                    sink = video.Video(tmp, out, "depth", scene.animation.fps, args.size, args.size)
                elif suffix == ".gif":
                    sink = video.Gif(tmp, "depth", scene.animation.fps)
                else:
                    sink = video.Folder(out, 5, "bench")
                for k, frame in enumerate(frames):
                    sink.write(k, frame)
                sink.finish()
        return run

    def end_to_end(suffix, aov="depth"):
        def run():
            with tempfile.TemporaryDirectory() as folder:
                argv = ["animate", args.scene, "-o", str(Path(folder) / f"x{suffix}"), "--aov", aov,
                        "--size", f"{args.size}x{args.size}"]
                with contextlib.redirect_stdout(io.StringIO()) as printed:
                    assert cli.main(argv) == 0
                run.line = printed.getvalue().strip()
        return run

    cases = {
        "render only (depth)": render_only,
        "encode only .mp4": encode_only(".mp4"),
        "encode only .gif": encode_only(".gif"),
        "write only folder (EXR + PNG)": encode_only("/"),
        "animate -o .mp4": end_to_end(".mp4"),
        "animate -o .gif": end_to_end(".gif"),
        "animate -o folder/ (depth)": end_to_end("/"),
    }
    seconds = {name: [] for name in cases}
    cpu = {name: [] for name in cases}  # CPU seconds of this process and of ffmpeg: less swayed by other load
    for _ in range(args.rounds):
        for name, case in cases.items():
            time.sleep(0.3)  # settle between systems
            cpu_start = _cpu()
            start = time.perf_counter()
            case()
            seconds[name].append(time.perf_counter() - start)
            cpu[name].append(_cpu() - cpu_start)
    base = statistics.median(seconds["render only (depth)"])
    print(f"{Path(args.scene).name} at {args.size}x{args.size}: {count} frames, median of {args.rounds} rounds")
    for name, values in seconds.items():
        median = statistics.median(values)
        print(f"  {name:32s} {count / median:7.1f} frames/s  ({median:6.2f} s, {base / median:4.2f} x render only), "
              f"CPU {statistics.median(cpu[name]) / count * 1e3:5.2f} ms a frame")
    for name, case in cases.items():
        if hasattr(case, "line"):
            print(f"  last {name}: {case.line}")


def _cpu() -> float:
    """User and system seconds of this process (all its threads) and of its waited-for children (ffmpeg)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


if __name__ == "__main__":
    main()
