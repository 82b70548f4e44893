"""pyclray beside NVIDIA Warp's mesh_query_ray on one device (issue 41's GPU table): the same meshes,
the same rays, timed the same way, one table.

    python -m bench.gpu_warp [--rounds 3] [--block 5] [--size 512] [--rays 1000000] [--warp-device cuda:0]

Rows (bench.meshes' bunny, 80,000 triangles, and its 1,000,000-triangle perturbed sphere):
- primary rays size x size: pyclray's render of depth, normal, id and primitive against a Warp kernel
  casting the same unit pinhole rays (pyclray.reference.oracle.camera_rays) with mesh_query_ray and
  writing t, the face normal and the face: the call's wall time (blocks: bench.open3d_compare.blocks)
  and the kernels' own time (pyclray: its OpenCL profiling events, bench.cast_host.kernel_ms; Warp: CUDA
  events around the launch, on a CPU device its launch's wall time);
- RAYS incoherent rays (bench.meshes.incoherent_rays) cast from host arrays (pyclray: tracer.cast of
  float64 numpy arrays, the Frame's numpy arrays back; Warp: wp.array of the float32 rays uploaded,
  the launch, .numpy() of t, normal and face) and from device buffers (pyclray: pyopencl arrays in,
  out="device"; Warp: wp.arrays already on the device, launch and synchronize), each call's wall time.
Where pyclray's lane width is 1 (a GPU: its pair nodes, kernels/bvh_pairs.h), the primary rays'
kernel and the device buffers' cast also run through the wide tree at one lane (PYCLRAY_TRAVERSAL=wide),
rows marked "wide tree": the pair nodes' figures against the layout they replace, on the same device.
Warp builds its BVH once per mesh (wp.Mesh), pyclray prepares its handle once: neither is timed.
Here (no GPU) both run on the CPU, Warp through its LLVM backend and pyclray through PoCL: a dry run of
the script, its figures for scale only (docs/benchmarks.md, "The host path of a cast").
"""
from __future__ import annotations

import argparse
import os
import time
from contextlib import contextmanager

import numpy as np
import pyopencl.array as cl_array

import pyclray
from pyclray.engine.launch.programs import lanes_for, pairs_for
from pyclray.engine.opencl.device import context_for

from .cast_host import kernel_ms, profiling_queue
from .meshes import camera_for, incoherent_rays, meshes
from .open3d_compare import blocks

AOVS = ("depth", "normal", "id", "primitive")


def warp_kernel():
    import warp as wp

    @wp.kernel
    def cast_rays(mesh: wp.uint64, origins: wp.array(dtype=wp.vec3), directions: wp.array(dtype=wp.vec3),
                  depth: wp.array(dtype=float), normal: wp.array(dtype=wp.vec3), face: wp.array(dtype=int)):
        i = wp.tid()
        query = wp.mesh_query_ray(mesh, origins[i], directions[i], 1.0e30)
        if query.result:
            depth[i] = query.t
            normal[i] = query.normal
            face[i] = query.face
        else:
            depth[i] = wp.inf
            normal[i] = wp.vec3(0.0, 0.0, 0.0)
            face[i] = -1

    return cast_rays


class WarpCaster:
    """A mesh in Warp (wp.Mesh: its BVH built once) and its cast of rays on one device."""

    def __init__(self, mesh, device: str):
        import warp as wp

        self.wp, self.device = wp, device
        points = wp.array(mesh.world_vertices().astype(np.float32), dtype=wp.vec3, device=device)
        faces = wp.array(mesh.faces.astype(np.int32).reshape(-1), dtype=int, device=device)
        self.mesh = wp.Mesh(points=points, indices=faces)
        self.kernel = warp_kernel()
        self.outputs = {}

    def _outputs(self, count: int):
        wp = self.wp
        if count not in self.outputs:
            self.outputs[count] = (wp.empty(count, dtype=float, device=self.device),
                                   wp.empty(count, dtype=wp.vec3, device=self.device),
                                   wp.empty(count, dtype=int, device=self.device))
        return self.outputs[count]

    def upload(self, origins, directions):
        wp = self.wp
        return (wp.array(np.ascontiguousarray(origins, np.float32), dtype=wp.vec3, device=self.device),
                wp.array(np.ascontiguousarray(directions, np.float32), dtype=wp.vec3, device=self.device))

    def launch(self, origins, directions):
        outputs = self._outputs(origins.shape[0])
        self.wp.launch(self.kernel, dim=origins.shape[0], inputs=[self.mesh.id, origins, directions, *outputs],
                       device=self.device)
        return outputs

    def on_device(self, origins, directions):
        """A cast of rays already on the device, its results left there."""
        outputs = self.launch(origins, directions)
        self.wp.synchronize_device(self.device)
        return outputs

    def from_host(self, origins, directions):
        """A cast of host arrays: uploads, the launch, the results read back."""
        return [array.numpy() for array in self.launch(*self.upload(origins, directions))]

    def kernel_ms(self, origins, directions, calls: int) -> float:
        """The launch's own time: CUDA events around it on a GPU, its wall time on a CPU."""
        wp = self.wp
        times = []
        for _ in range(calls):
            if wp.get_device(self.device).is_cuda:
                start, end = wp.Event(self.device, enable_timing=True), wp.Event(self.device, enable_timing=True)
                wp.record_event(start)
                self.launch(origins, directions)
                wp.record_event(end)
                wp.synchronize_event(end)
                times.append(wp.get_event_elapsed_time(start, end))
            else:
                begin = time.perf_counter()
                self.on_device(origins, directions)
                times.append((time.perf_counter() - begin) * 1e3)
        return float(np.median(times))


@contextmanager
def wide_tree():
    """pyclray's kernels through the wide tree at a lane width of 1 (programs.pairs_for)."""
    saved = os.environ.get("PYCLRAY_TRAVERSAL")
    os.environ["PYCLRAY_TRAVERSAL"] = "wide"
    try:
        yield
    finally:
        if saved is None:
            os.environ.pop("PYCLRAY_TRAVERSAL")
        else:
            os.environ["PYCLRAY_TRAVERSAL"] = saved


def traversal(ctx) -> str:
    """The tree pyclray's kernels traverse on this device."""
    lanes = lanes_for(ctx.device, "fp32")
    return "pair nodes, one ray per work-item" if pairs_for(lanes) else f"wide tree, {lanes} lanes"


def run(rounds: int, block: int, size: int, rays: int, warp_device: str) -> list[tuple]:
    """(case, pyclray ms, Warp ms) rows."""
    from pyclray.reference import oracle

    rows = []
    ctx = context_for(None)
    pairs = pairs_for(lanes_for(ctx.device, "fp32"))  # a wide-tree row beside each pair-node one
    for label, mesh in meshes(None).items():
        scene = camera_for(mesh, size)
        tracer = pyclray.prepare(scene)
        caster = WarpCaster(mesh, warp_device)
        # primary rays: the scene's own unit pinhole rays
        origins, directions = (a.reshape(-1, 3) for a in oracle.camera_rays(scene))
        w_origins, w_directions = caster.upload(origins, directions)
        tracer.render(aovs=AOVS)
        caster.on_device(w_origins, w_directions)
        timed = blocks({"pyclray": lambda: tracer.render(aovs=AOVS),
                        "warp": lambda: caster.on_device(w_origins, w_directions)}, rounds, block)
        plain = profiling_queue(ctx)
        try:
            ours = kernel_ms(lambda: tracer.render(aovs=AOVS), block)
            if pairs:
                with wide_tree():
                    tracer.render(aovs=AOVS)  # (its program built)
                    wide = kernel_ms(lambda: tracer.render(aovs=AOVS), block)
        finally:
            ctx.queue.finish()
            ctx.queue = plain
        theirs = caster.kernel_ms(w_origins, w_directions, block)
        rows.append((f"{label}: primary rays {size}x{size}, kernel", ours, theirs))
        if pairs:
            rows.append((f"{label}: primary rays {size}x{size}, kernel, wide tree", wide, theirs))
        rows.append((f"{label}: primary rays {size}x{size}, call (wall)", timed["pyclray"]["median"],
                     timed["warp"]["median"]))
        # incoherent rays, from host arrays and from device buffers
        origins, directions = incoherent_rays(mesh, rays)
        d_origins, d_directions = (cl_array.to_device(ctx.queue, a) for a in (origins, directions))
        w_origins, w_directions = caster.upload(origins, directions)
        inner = max(2, block // 2)
        timed = blocks({"pyclray host": lambda: tracer.cast(origins, directions, aovs=AOVS),
                        "warp host": lambda: caster.from_host(origins, directions),
                        "pyclray device": lambda: tracer.cast(d_origins, d_directions, aovs=AOVS, out="device"),
                        "warp device": lambda: caster.on_device(w_origins, w_directions)}, rounds, inner)
        rows.append((f"{label}: {rays:,} incoherent rays from host arrays", timed["pyclray host"]["median"],
                     timed["warp host"]["median"]))
        rows.append((f"{label}: {rays:,} incoherent rays from device buffers", timed["pyclray device"]["median"],
                     timed["warp device"]["median"]))
        if pairs:
            def wide_device():
                with wide_tree():
                    return tracer.cast(d_origins, d_directions, aovs=AOVS, out="device")

            wide = blocks({"pyclray device": wide_device}, rounds, inner)
            rows.append((f"{label}: {rays:,} incoherent rays from device buffers, wide tree",
                         wide["pyclray device"]["median"], timed["warp device"]["median"]))
        tracer.close()
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--block", type=int, default=5)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--warp-device", default=None, help="Warp's device (default: cuda:0 where there is one, else cpu)")
    args = parser.parse_args(argv)
    import warp as wp

    wp.config.quiet = True
    wp.init()
    device = args.warp_device or ("cuda:0" if wp.is_cuda_available() else "cpu")
    ctx = context_for(None)
    rows = run(args.rounds, args.block, args.size, args.rays, device)
    print(f"pyclray on {ctx.device.name.strip()} ({traversal(ctx)}), Warp {wp.config.version} on "
          f"{wp.get_device(device).name}; load {os.getloadavg()[0]:.1f}; ms, medians")
    print("| case | pyclray ms | Warp ms | Warp / pyclray |\n|---|---|---|---|")
    for case, ours, theirs in rows:
        print(f"| {case} | {ours:.3f} | {theirs:.3f} | {theirs / ours:.2f}x |")


if __name__ == "__main__":
    main()
