"""Rays along an axis (issue 38): the BVH's box test of one ray (kernels/bvh_ray.h's box_ray and
box_entered, as cast, occluded, count_hits and all_hits use it; bvh_packet.h's box_entries_of
for mesh instances' trees and shadow rays likewise) widens the ray into a cone of slope
BVH_WIDEN. Along an axis k where |d_k| <= BVH_WIDEN the cone never leaves a slab it reaches, but it
reaches one beyond its far face only after a while too: a test that took such a slab as entered at 0
entered every box on that side of an axis-aligned ray, which then visited much of the tree (casts
200-400x slower than the same rays tilted by 1%: docs/benchmarks.md, bench/axis_rays.py).

No timing here: the box test itself is checked against the exact cone, in float64 on the host,
for directions with components 0, below, at and just above BVH_WIDEN: it must enter every box the
exact cone (with the origin's margin) meets (else a hit could be dropped), and no box that a cone of
twice the slope and margin misses by far (the work the traversal does on such rays stays that of
any other ray: a box beyond an axis-aligned ray's far side is not visited)."""
import numpy as np
import pyopencl as cl
import pytest

import pyclray
from pyclray.engine.bvh.tree import NODE
from pyclray.engine.bvh.wide import WIDE_NODE
from pyclray.engine.launch.programs import kernel_dir
from pyclray.engine.opencl.device import context_for
from pyclray.model.layout import c_header

from oracle_checks import assert_agrees_with_oracle

WIDEN = 2.0 ** -12  # kernels/bvh.h's BVH_WIDEN

SOURCE = """
__kernel void entered(__global const float* rays, __global const float* boxes, __global int* out, const int n_boxes)
{
    const int r = get_global_id(0), k = get_global_id(1);
    __global const float* ray = rays + 7 * r;
    __global const float* box = boxes + 6 * k;
#ifdef PACKET  /* kernels/bvh_packet.h's test (mesh instances' trees, shadow rays), one lane */
    const BoxPacket b = box_packet(v3(ray[3], ray[4], ray[5]), (float4)(ray[0], ray[1], ray[2], ray[6]));
    const float entry = box_entries_of((float3)(box[0], box[1], box[2]), (float3)(box[3], box[4], box[5]), &b, INFINITY);
    out[r * n_boxes + k] = entry < INFINITY ? 1 : 0;
#else  /* kernels/bvh_ray.h's (cast, occluded, count_hits, all_hits) */
    const BoxRay b = box_ray((float3)(ray[0], ray[1], ray[2]), (float3)(ray[3], ray[4], ray[5]), ray[6]);
    const float8 lohi = (float8)(box[0], box[1], box[2], box[3], box[4], box[5], 0.0f, 0.0f);
    out[r * n_boxes + k] = box_entered(lohi, &b, INFINITY) ? 1 : 0;
#endif
}
"""


def box_test(origins, directions, margins, lo, hi, test):
    """(rays, boxes) 0/1: whether the kernel's box test (test: "ray" or "packet") enters each box,
    with no limit."""
    ctx = context_for()
    files = ("common.h", "lanes.h", "bvh.h", "bvh_ray.h" if test == "ray" else "bvh_packet.h")
    source = ("#define PACKET 1\n" if test == "packet" else "") + c_header([WIDE_NODE, NODE], "fp32")
    source = "\n".join(kernel_dir().joinpath(name).read_text() for name in files[:2]) + source
    source += "\n".join(kernel_dir().joinpath(name).read_text() for name in files[2:]) + SOURCE
    program = cl.Program(ctx.context, source).build()
    rays = np.ascontiguousarray(np.column_stack([origins, directions, margins]), np.float32)
    boxes = np.ascontiguousarray(np.column_stack([lo, hi]), np.float32)
    out = np.zeros((len(rays), len(boxes)), np.int32)
    flags = cl.mem_flags
    ray_buffer = cl.Buffer(ctx.context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=rays)
    box_buffer = cl.Buffer(ctx.context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=boxes)
    out_buffer = cl.Buffer(ctx.context, flags.WRITE_ONLY, out.nbytes)
    program.entered(ctx.queue, (len(rays), len(boxes)), None, ray_buffer, box_buffer, out_buffer, np.int32(len(boxes)))
    cl.enqueue_copy(ctx.queue, out, out_buffer)
    return out.astype(bool)


def cone_meets(origins, directions, margins, lo, hi, slope):
    """(rays, boxes): whether some point o + t d, t >= 0, lies within margin + slope t of the box on
    every axis (float64: per axis the interval of t where it does, intersected)."""
    o, d, m = origins[:, None, :], directions[:, None, :], margins[:, None, None]
    start = np.zeros(o.shape[:1] + lo.shape[:1])
    end = np.full_like(start, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for below, rate in ((lo[None] - m - o, d + slope), (o - hi[None] - m, slope - d)):
            # rate t >= below on every axis (the cone's upper edge reaches lo, its lower edge hi)
            rate = np.broadcast_to(rate, below.shape)
            bound = below / rate
            start = np.maximum(start, np.where(rate > 0, bound, 0).max(axis=2))
            end = np.minimum(end, np.where(rate < 0, bound, np.inf).min(axis=2))
            never = ((rate == 0) & (below > 0)).any(axis=2)
            end = np.where(never, -np.inf, end)
    return start <= end


def rays_and_boxes(rng):
    count = 400
    origins = rng.uniform(-2.0, 2.0, (count, 3))
    # per ray one or two components of: 0, tiny, just below, at and just above BVH_WIDEN (either sign)
    flat = rng.choice([0.0, 1e-9, 0.5 * WIDEN, WIDEN * (1 - 2.0 ** -20), WIDEN, 1.5 * WIDEN], (count, 3))
    flat *= rng.choice([-1.0, 1.0], (count, 3))
    steep = rng.uniform(0.3, 1.0, (count, 3)) * rng.choice([-1.0, 1.0], (count, 3))
    keep = rng.random((count, 3)) < 0.4
    keep[np.arange(count), rng.integers(0, 3, count)] = True  # one steep axis at least
    directions = np.where(keep, steep, flat).astype(np.float32).astype(np.float64)
    directions[:60] = np.eye(3)[rng.integers(0, 3, 60)] * rng.choice([-1.0, 1.0], (60, 1))  # along an axis exactly
    margins = np.full(count, 2.0 ** -20 * 6)
    centres = rng.uniform(-3.0, 3.0, (300, 3))
    sizes = rng.uniform(0.01, 0.5, (300, 3))
    lo = (centres - sizes).astype(np.float32).astype(np.float64)
    hi = (centres + sizes).astype(np.float32).astype(np.float64)
    return origins.astype(np.float32).astype(np.float64), directions, margins, lo, hi


@pytest.mark.parametrize("test", ["ray", "packet"])
def test_the_box_test_of_flat_axes_is_the_cone(test):
    """The kernel's box test enters every box the exact cone meets and none that twice the cone
    misses (a flat axis's far face: the test of that side)."""
    origins, directions, margins, lo, hi = rays_and_boxes(np.random.default_rng(38))
    entered = box_test(origins, directions, margins, lo, hi, test)
    exact = cone_meets(origins, directions, margins, lo, hi, WIDEN)
    assert not (exact & ~entered).any(), f"{(exact & ~entered).sum()} boxes the cone meets were not entered"
    wide = cone_meets(origins, directions, 2 * margins, lo, hi, 2 * WIDEN)
    extra = entered & ~wide
    assert not extra.any(), (f"{extra.sum()} boxes entered that twice the cone misses (first ray "
                             f"{np.nonzero(extra)[0][0]}, direction {directions[np.nonzero(extra)[0][0]]})")
    # the case the check is for: boxes behind a flat axis's far face are among those tested
    assert (~wide).sum() > 0.5 * wide.size


def test_axis_aligned_rays_on_a_mesh_agree_with_the_oracle():
    """Rays along +x and -z through the bunny (their box tests now take the flat axes' far faces):
    cast agrees with the float64 oracle (the error model's tolerances), occluded and count_hits with
    cast on which rays hit, and all_hits' rows with count_hits."""
    mesh = pyclray.Mesh.load(kernel_dir().parents[2] / "scenes" / "meshes" / "bunny.ply")
    scene = pyclray.Scene(pyclray.Camera((0, 0, 10), (0, 0, 0)), pyclray.Image(4, 4), (mesh,))
    lo, hi = np.asarray(mesh.box())
    rng = np.random.default_rng(7)
    origins = rng.uniform(lo, hi, (2000, 3))
    origins[:1000, 0] = lo[0] - 0.1
    origins[1000:, 2] = hi[2] + 0.1
    directions = np.repeat([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0]], 1000, axis=0)
    nearest = pyclray.cast(scene, origins, directions)
    assert_agrees_with_oracle(scene, origins, directions, nearest, "fp32")
    counts = pyclray.count_hits(scene, origins, directions)
    assert np.array_equal(nearest["id"] >= 0, counts > 0)
    assert np.array_equal(pyclray.occluded(scene, origins, directions), counts > 0)
    assert np.array_equal(np.diff(pyclray.all_hits(scene, origins, directions)["offsets"]), counts)
    assert (counts > 0).mean() > 0.3  # the rays cross the bunny
