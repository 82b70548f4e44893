"""The cross-check's two costly parts against their named baselines, in the same process (issue 26):

- the float64 oracle of the pixel rays with "second" (pyclray.reference.oracle.trace: each shape
  against the rays crossing its box, through the scene's BVH) against trace_every_shape (every shape
  against every ray, the oracle as it was);
- Mitsuba scalar_rgb's images: the pixel rays cast from Python (reference.mitsuba.render, bit for
  bit the integrator's images) against the aov integrator's render (as the check rendered them).

Timings are medians of blocks of calls, the two taking turns with short pauses (open3d_compare.blocks);
the ratio is the baseline's time over the new one's (> 1: faster). The image side is kept small
(128 by default) so that the baselines finish in seconds.

    .venv/bin/python -m bench.check_speed [--size 128] [--rounds 2 --block 1]
"""
from __future__ import annotations

import argparse
import os

import pyclray
from pyclray.reference import mitsuba, oracle

from .open3d_compare import blocks

SCENES = ("grid1024", "rtiow", "shapes-lit")


def oracle_cases(scene):
    origins, directions = oracle.camera_rays(scene)
    aovs = ("depth", "normal", "id", "second")
    return {"oracle through the BVH": lambda: oracle.trace(scene, origins, directions, aovs),
            "every shape against every ray": lambda: oracle.trace_every_shape(scene, origins, directions, aovs)}


def mitsuba_cases(scene):
    mi = mitsuba.import_mitsuba("scalar_rgb")

    def integrator():
        mi_scene, _ = mitsuba.load(scene, "scalar_rgb")
        mi_scene.integrator().render(mi_scene, mi_scene.sensors()[0])

    return {"pixel rays cast from Python": lambda: mitsuba.render(scene, "scalar_rgb"),
            "aov integrator": integrator, "_variant": mi.variant()}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--block", type=int, default=1)
    args = parser.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.2f}; {args.size}x{args.size} (rtiow: its aspect), medians in ms")
    for name in SCENES:
        scene = pyclray.load_scene(os.path.join(os.path.dirname(__file__), "..", "scenes", f"{name}.toml"))
        height = round(args.size * scene.image.height / scene.image.width)
        scene = scene.with_size(args.size, height)
        for cases in (oracle_cases(scene), mitsuba_cases(scene)):
            cases.pop("_variant", None)
            new, baseline = list(cases)
            result = blocks(cases, args.rounds, args.block)
            ratio = result[baseline]["median"] / result[new]["median"]
            print(f"{name:10s} {new:30s} {result[new]['median']:9.1f}   {baseline:30s} "
                  f"{result[baseline]['median']:9.1f}   x{ratio:.1f}")


if __name__ == "__main__":
    main()
