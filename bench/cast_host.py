"""The host path of a cast (issue 41): a prepared handle's cast of 1, 1,000 and 1,000,000 incoherent
rays on the bunny (bench.meshes' 80,000-triangle subdivided scan), its wall time split into host
phases and the kernel's own time, beside Open3D's RaycastingScene.cast_rays and PoCL's launch floor.

    .venv/bin/python -m bench.cast_host [--rounds 3] [--block 20] [--sizes 1,1000,1000000]

- wall: `tracer.cast(origins, directions)` (depth, normal, id, primitive: cast's default AOVs), the
  rays float64 numpy arrays, timed in rotating blocks beside Open3D's cast_rays of the same rays (its
  float32 (N, 6) tensor made beforehand: its best case) and beside PoCL's bare launch (an empty
  kernel's enqueue and wait on the same queue): bench.open3d_compare.blocks, medians in ms;
- the split (a second pass, on a profiling queue): per call the time inside each host phase, found by
  wrapping the engine's functions: checks (the rays' checks and conversions, cast.py's _cast_rays),
  order (numba's coherent order, ray_order.coherent_order), uploads (the rays' buffers: new ones, or
  the copies into a handle's kept ones), launch (the enqueue), wait (from the enqueue's end until the
  kernel is done), readback (the results' copies out of kept buffers; a large cast's are its arrays)
  and other (the rest: argument checks, output arrays, the Frame); kernel: the kernel's time from
  its OpenCL profiling event (start to end), which lies within launch and wait. Medians per phase;
- host CPU: the call's process CPU time with its kernels' enqueues stubbed (host_cpu): the host's own
  part, the steadiest figure on a loaded machine.
The machine is shared: compare each size's figures with each other (ratios), and note `uptime`.
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

import pyclray
from pyclray.engine.opencl.buffers import KeptBuffers
from pyclray.engine.opencl.device import context_for
from pyclray.engine.queries import cast as cast_module
from pyclray.engine.queries import ray_order

from .engine_ab import subdivided
from .meshes import incoherent_rays, open3d_scene
from .open3d_compare import blocks

SCENES = Path(__file__).resolve().parent.parent / "scenes"
PHASES = ("checks", "order", "uploads", "launch", "wait", "readback", "other", "kernel")


def bunny():
    base = pyclray.Mesh.load(SCENES / "meshes" / "bunny.ply")
    return pyclray.Mesh(*subdivided(base.vertices, base.faces, 2), name="bunny")


def empty_launch(ctx):
    """PoCL's floor: an empty kernel's enqueue and wait (one work-item) on the engine's queue."""
    kernel = cl.Program(ctx.context, "__kernel void nothing(void) {}").build().nothing

    def call():
        kernel(ctx.queue, (1,), None).wait()
    return call


def _launching_modules():
    """(module, name): the engine's modules that enqueue kernels through engine/opencl/device.py's
    launch or launch_kept, and the name they call it by."""
    import sys

    from pyclray.engine.opencl import device

    return [(module, name) for module_name, module in list(sys.modules.items()) if module_name.startswith("pyclray.engine")
            for name in ("launch", "launch_kept")
            if getattr(device, name, None) is not None and getattr(module, name, None) is getattr(device, name)]


class _Enqueued:
    def wait(self):
        pass


def host_cpu(tracer, origins, directions, calls: int) -> float:
    """The call's process CPU time with its kernels' enqueues left out (the engine's launch functions
    stubbed; the results are not looked at): the host's own part, which a shared machine's load
    moves far less than the wall phases. ms per call, the median of 5 blocks of calls."""
    tracer.cast(origins, directions)  # warm: programs built, kept buffers grown
    saved = [(module, name, getattr(module, name)) for module, name in _launching_modules()]
    for module, name, _ in saved:
        setattr(module, name, lambda *args, **kwargs: _Enqueued())
    try:
        blocks = []
        for _ in range(5):
            start = time.process_time()
            for _ in range(calls):
                tracer.cast(origins, directions)
            blocks.append((time.process_time() - start) / calls)
    finally:
        for module, name, original in saved:
            setattr(module, name, original)
    return float(np.median(blocks)) * 1e3


def profiling_queue(ctx):
    """Swap ctx's queue for a profiling one (the kernels' events then carry their times); returns the
    queue to put back."""
    plain = ctx.queue
    ctx.queue = cl.CommandQueue(ctx.context, ctx.device, properties=cl.command_queue_properties.PROFILING_ENABLE)
    return plain


def kernel_ms(call, calls: int) -> float:
    """The median over calls of call()'s kernels' time (ms: the sum of their profiling events,
    start to end); the engine's queue must be a profiling one (profiling_queue)."""
    totals = []
    for _ in range(calls):
        with Split() as phases:
            call()
        totals.append(sum((e.profile.end - e.profile.start) * 1e-6 for e in phases.events if e is not None))
    return float(np.median(totals))


class Split:
    """The engine's phases wrapped in timers while in use (see the module's docstring)."""

    def __init__(self):
        self.times = {name: 0.0 for name in PHASES}
        self.events = []
        self.saved = []

    def _wrap(self, module, name, phase):
        original = getattr(module, name)
        times = self.times

        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                times[phase] += time.perf_counter() - start
        self.saved.append((module, name, original))
        setattr(module, name, timed)

    def __enter__(self):
        self._wrap(cast_module, "_cast_rays", "checks")
        self._wrap(ray_order, "coherent_order", "order")
        self._wrap(cast_module, "_ray_buffer", "uploads")
        self._wrap(KeptBuffers, "write", "uploads")
        self._wrap(KeptBuffers, "read", "readback")
        events = self.events
        for module, name in _launching_modules():
            original = getattr(module, name)

            def launched(*args, _original=original, **kwargs):
                start = time.perf_counter()
                event = _original(*args, **kwargs)
                self.times["launch"] += time.perf_counter() - start
                self.launched_at = time.perf_counter()
                events.append(event)
                return event
            self.saved.append((module, name, original))
            setattr(module, name, launched)
        return self

    def __exit__(self, *exc):
        for module, name, original in reversed(self.saved):
            setattr(module, name, original)


def split(tracer, origins, directions, calls: int) -> dict:
    """Per phase the median ms per call over calls casts, on a profiling queue."""
    ctx = tracer.ctx
    plain = profiling_queue(ctx)
    try:
        tracer.cast(origins, directions)  # warm
        rows = []
        for _ in range(calls):
            with Split() as phases:
                start = time.perf_counter()
                tracer.cast(origins, directions)
                end = time.perf_counter()
            times = phases.times
            # wait: from the enqueue's return to the call's end, less the phases within it (the
            # readback; the rest, the Frame, counts as other)
            times["wait"] = end - getattr(phases, "launched_at", end) - times["readback"]
            # a kept buffers' read waits for the kernel itself: that wait is the wait's, not the copy's
            times["kernel"] = sum((e.profile.end - e.profile.start) * 1e-9 for e in phases.events if e is not None)
            times["other"] = (end - start) - sum(times[p] for p in PHASES if p not in ("other", "kernel"))
            times["wall"] = end - start
            rows.append(dict(times))
        return {name: float(np.median([row[name] for row in rows])) * 1e3 for name in rows[0]}
    finally:
        ctx.queue.finish()
        ctx.queue = plain


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--block", type=int, default=20)
    parser.add_argument("--sizes", default="1,1000,1000000")
    parser.add_argument("--no-open3d", action="store_true", help="leave Open3D out (a machine without it)")
    args = parser.parse_args(argv)
    mesh = bunny()
    scene = pyclray.Scene(pyclray.Camera((0, 0, 3), (0, 0, 0)), pyclray.Image(8, 8), (mesh,))
    tracer = pyclray.prepare(scene)
    ctx = context_for(None)
    floor = empty_launch(ctx)
    o3d_scene = None if args.no_open3d else open3d_scene(mesh)
    print(f"device: {ctx.device.name.strip()}; load {os.getloadavg()[0]:.1f}; mesh {len(mesh.faces):,} triangles")
    header = (f"{'rays':>9} | {'pyclray':>9} | {'Open3D':>9} | {'launch floor':>12} | "
              + " | ".join(f"{p:>7}" for p in PHASES) + f" | {'host CPU':>8}")
    print(header)
    for size in (int(s) for s in args.sizes.split(",")):
        origins, directions = incoherent_rays(mesh, size)
        systems = {"pyclray": lambda: tracer.cast(origins, directions), "floor": floor}
        if o3d_scene is not None:
            import open3d as o3d

            rays = o3d.core.Tensor(np.concatenate([origins, directions], 1).astype(np.float32))
            systems["open3d"] = lambda: o3d_scene.cast_rays(rays)
        block = max(3, min(args.block, int(2e5 // size) or 3))
        timed = blocks(systems, args.rounds, block)
        phases = split(tracer, origins, directions, block)
        host = host_cpu(tracer, origins, directions, max(block, int(2e4 // size)))
        theirs = f"{timed['open3d']['median']:9.3f}" if "open3d" in timed else f"{'-':>9}"
        print(f"{size:>9,} | {timed['pyclray']['median']:9.3f} | {theirs} | {timed['floor']['median']:12.3f} | "
              + " | ".join(f"{phases[p]:7.3f}" for p in PHASES) + f" | {host:8.3f}", flush=True)
    print(f"load {os.getloadavg()[0]:.1f} (ms per call, medians; the phases: means on a profiling queue)")


if __name__ == "__main__":
    main()
