"""The speed targets measured in blocks: each system runs a block of calls on its own, with a pause at
each switch, so that one runtime's worker threads winding down (PoCL's, Dr.Jit's) do not weigh on the
next (interleaving call by call roughly doubles pyclray's time on tp02). Blocks of every case of a
group are repeated over a few rounds in rotating order, so that load on the machine over the run
weighs on all cases alike; a case's figure is the median of all its timed calls.

The floor is a trivial kernel that writes the three images (depth inf, normal 0, id -1) into new numpy
arrays exactly as pyclray does on a CPU device (USE_HOST_PTR buffers, then a map): no render can be
faster than that.

    python -m bench.blocks            # prints the table (about a minute and a half)
"""
from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

SCENES = Path(__file__).resolve().parent.parent / "scenes"
PAUSE = 0.5  # seconds of quiet at each switch
WARM_CALLS = 3  # untimed calls at the start of each block
ROUNDS = 3  # blocks of each case
BLOCK_SECONDS = 1.0  # timed calls per block: about this long, between 5 and 100 calls

# group name -> (scene file, image side, cases); a case is (label, kind, options)
GROUPS = {
    "tp02 512": ("tp02", 512, ("floor", "all", "depth", "all fp64", "depth fp64", "llvm")),
    "tp02 2048": ("tp02", 2048, ("floor", "all", "depth", "llvm")),
    "grid64 512": ("grid64", 512, ("floor", "all", "depth", "llvm")),
    "grid1024 512": ("grid1024", 512, ("floor", "all", "depth", "llvm")),
    "shapes 512": ("shapes", 512, ("floor", "all", "depth", "llvm")),  # every shape type
    # tp02 with two point lights and shadows (scenes/tp02-lit.toml)
    "tp02-lit 512": ("tp02-lit", 512, ("unshaded", "shaded", "shaded no-shadows", "direct llvm")),
}
UNSHADED = ("depth", "normal", "id", "zdepth", "position")  # every AOV but shaded

FLOOR_SOURCE = """
__kernel void floor_kernel(__global float* depth, __global float* normal, __global int* id, const int width, const int height)
{
    const int i = get_global_id(0), j = get_global_id(1);
    if (i >= width || j >= height) return;
    const size_t index = (size_t)j * (size_t)width + (size_t)i;
    depth[index] = INFINITY;
    vstore3((float3)(0, 0, 0), index, normal);
    id[index] = -1;
}
"""


def floor_in_place(ctx, size: int):
    """A call that writes the three images of a size x size render into new numpy arrays, as pyclray
    does on a CPU device."""
    kernel = cl.Program(ctx.context, FLOOR_SOURCE).build().floor_kernel
    count = size * size

    def run():
        out = [np.empty(count, np.float32), np.empty((count, 3), np.float32), np.empty(count, np.int32)]
        flags = cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR
        own = [cl.Buffer(ctx.context, flags, hostbuf=array) for array in out]
        kernel(ctx.queue, (size, size), None, *own, np.int32(size), np.int32(size))
        maps = [cl.enqueue_map_buffer(ctx.queue, b, cl.map_flags.READ, 0, a.shape, a.dtype, is_blocking=False)[0]
                for a, b in zip(out, own)]
        ctx.queue.finish()
        for mapped in maps:
            mapped.base.release()
        ctx.queue.finish()
        return out

    return run


def mitsuba_direct(scene):
    """Mitsuba llvm_ad_rgb's direct integrator on the scene (its diffuse version: two-sided diffuse
    BSDFs, the same lights as emitters), one pixel-centre sample per pixel and as many emitter
    samples as the scene has lights: the same number of shadow rays per pixel as pyclray casts."""
    from pyclray.engine.opencl import device
    from pyclray.reference import mitsuba
    from pyclray.reference.validation import shaded as shaded_check
    from pyclray.model.lights import effective_lights

    mi = mitsuba.import_mitsuba("llvm_ad_rgb")
    lights = effective_lights(scene)
    description = shaded_check.direct_scene_dict(shaded_check.diffuse_version(scene), lights[0], "llvm_ad_rgb")
    description["integrator"]["emitter_samples"] = len(lights)
    for k, light in enumerate(lights[1:]):
        description[f"light{k + 1}"] = mitsuba.emitter_dict(light)
    mi_scene = mi.load_dict(description, optimize=False)
    sensor, integrator = mi_scene.sensors()[0], mi_scene.integrator()
    return lambda: np.array(integrator.render(mi_scene, sensor))


def calls_of(group: str) -> dict:
    """label -> a call of the group's cases."""
    import pyclray
    from pyclray.engine.opencl import device

    name, size, cases = GROUPS[group]
    scene = pyclray.load_scene(SCENES / f"{name}.toml").with_size(size, size)
    calls = {}
    for case in cases:
        label = f"{name} {size} {case}"
        if case == "floor":
            calls[label] = floor_in_place(device.context_for(None), size)
        elif case == "direct llvm":
            calls[label] = mitsuba_direct(scene)
        elif case == "unshaded":
            calls[label] = lambda: pyclray.render(scene, UNSHADED)
        elif case.startswith("shaded"):
            from dataclasses import replace

            shadows = case == "shaded"
            lit = replace(scene, shading=replace(scene.shading, shadows=shadows))
            calls[label] = lambda lit=lit: pyclray.render(lit, ("shaded",))
        elif case == "llvm":
            from pyclray.engine.opencl import device
            from pyclray.reference import mitsuba

            mitsuba.import_mitsuba("llvm_ad_rgb")
            mi_scene, _ = mitsuba.load(scene, "llvm_ad_rgb")
            sensor, integrator = mi_scene.sensors()[0], mi_scene.integrator()
            calls[label] = lambda s=mi_scene, c=sensor, i=integrator: np.array(i.render(s, c))
        else:
            aovs, _, precision = case.partition(" ")
            aovs = ("depth", "normal", "id") if aovs == "all" else (aovs,)
            calls[label] = lambda aovs=aovs, precision=precision or "fp32": pyclray.render(scene, aovs, precision)
    return calls


def measure(groups=tuple(GROUPS), rounds: int = ROUNDS, pause: float = PAUSE, progress=None) -> dict:
    """label -> statistics (seconds) of every case of these groups, each group measured on its own."""
    results = {}
    for group in groups:
        calls = calls_of(group)
        per_call = {}
        for label, call in calls.items():  # builds, JIT, and how long a call takes
            call()
            start = time.perf_counter()
            call()
            per_call[label] = time.perf_counter() - start
        labels = list(calls)
        times = {label: [] for label in labels}
        for r in range(rounds):
            for label in labels[r % len(labels):] + labels[: r % len(labels)]:
                time.sleep(pause)
                count = int(min(100, max(5, BLOCK_SECONDS / max(per_call[label], 1e-6))))
                for _ in range(WARM_CALLS):
                    calls[label]()
                for _ in range(count):
                    start = time.perf_counter()
                    calls[label]()
                    times[label].append(time.perf_counter() - start)
                if progress:
                    progress(label)
        for label, t in times.items():
            results[label] = {
                "median": statistics.median(t), "q1": float(np.percentile(t, 25)), "q3": float(np.percentile(t, 75)),
                "min": min(t), "max": max(t), "rounds": len(t),
            }
        del calls
    return results


# target name -> (numerator label, denominator label, goal, "<=" or ">=")
TARGETS = {
    "tp02 512 all AOVs: pyclray / floor": ("tp02 512 all", "tp02 512 floor", 2.0, "<="),
    "tp02 512 all AOVs: llvm / pyclray": ("tp02 512 llvm", "tp02 512 all", 8.0, ">="),
    "tp02 512: depth only / all AOVs": ("tp02 512 depth", "tp02 512 all", 0.6, "<="),
    "tp02 512 all AOVs: fp64 / fp32": ("tp02 512 all fp64", "tp02 512 all", None, ""),
    "tp02 2048 all AOVs: pyclray / floor": ("tp02 2048 all", "tp02 2048 floor", None, ""),
    "tp02 2048 all AOVs: llvm / pyclray": ("tp02 2048 llvm", "tp02 2048 all", None, ""),
    "tp02 2048: depth only / all AOVs": ("tp02 2048 depth", "tp02 2048 all", None, ""),
    "grid64 512 all AOVs: llvm / pyclray": ("grid64 512 llvm", "grid64 512 all", 2.0, ">="),
    "grid1024 512 all AOVs: pyclray / floor": ("grid1024 512 all", "grid1024 512 floor", None, ""),
    "grid1024 512 all AOVs: llvm / pyclray": ("grid1024 512 llvm", "grid1024 512 all", None, ""),
    "shapes 512 all AOVs: pyclray / floor": ("shapes 512 all", "shapes 512 floor", None, ""),
    "shapes 512 all AOVs: llvm / pyclray": ("shapes 512 llvm", "shapes 512 all", None, ""),
    "tp02-lit 512 shaded: Mitsuba direct llvm / pyclray": ("tp02-lit 512 direct llvm", "tp02-lit 512 shaded", 5.0, ">="),
    "tp02-lit 512: shaded with shadows / all AOVs unshaded": ("tp02-lit 512 shaded", "tp02-lit 512 unshaded", 2.0, "<="),
    "tp02-lit 512: shaded without shadows / all AOVs unshaded": ("tp02-lit 512 shaded no-shadows", "tp02-lit 512 unshaded", None, ""),
}


def ms(seconds: float) -> str:
    value = seconds * 1e3
    return f"{value:.3g}" if value < 100 else f"{value:.0f}"


def tables(cases: dict) -> list[str]:
    """Markdown: the cases, then the targets as ratios of medians measured in the same process."""
    out = ["| case (warm, fp32 unless said) | median ms | IQR ms | min ms | timed calls |", "|---|---|---|---|---|"]
    for label, v in cases.items():
        out.append(f"| {label} | {ms(v['median'])} | {ms(v['q1'])}–{ms(v['q3'])} | {ms(v['min'])} | {v['rounds']} |")
    out += ["", "| ratio | measured | goal | met |", "|---|---|---|---|"]
    for name, (top, bottom, goal, sense) in TARGETS.items():
        if top not in cases or bottom not in cases:
            continue
        ratio = cases[top]["median"] / cases[bottom]["median"]
        met = "" if goal is None else ("yes" if (ratio <= goal if sense == "<=" else ratio >= goal) else "**no**")
        text = f"{ratio:.2f} ({ms(cases[top]['median'])} ms / {ms(cases[bottom]['median'])} ms)"
        out.append(f"| {name} | {text} | {'' if goal is None else f'{sense} {goal:g}'} | {met} |")
    return out


def main(argv=None) -> None:
    import argparse
    import sys
    import warnings

    warnings.simplefilter("ignore")
    parser = argparse.ArgumentParser(prog="python -m bench.blocks", description=__doc__.split("\n\n")[0])
    parser.add_argument("groups", nargs="*", default=list(GROUPS), help=f"of: {', '.join(GROUPS)}")
    parser.add_argument("--rounds", type=int, default=ROUNDS)
    args = parser.parse_args(argv)
    cases = measure(args.groups, args.rounds, progress=lambda label: print(f"  {label}", file=sys.stderr))
    print("\n".join(tables(cases)))


if __name__ == "__main__":
    main()
