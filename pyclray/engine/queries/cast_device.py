"""cast and occluded of rays given as device arrays (pyopencl arrays on the handle's context), their
results left on the device where asked (out="device"): a loop over a data set's rays then never
copies them through the host; and of host arrays on a device of the GPU class
(engine/opencl/device.py: gpu_class), where the host does nothing per ray: each array is uploaded
once, checked (and a refused ray made harmless) by a kernel, and the results, written into regions of
one kept buffer, read back in one copy.

The rays are checked on the device: one reduction per call finds the largest distance of an origin
from the scene's anchor, +inf where a ray has a coordinate that is not finite or a zero direction;
only where that is not a fine value are the arrays read back, to name the first bad row as the host
path does (engine/queries/cast.py: _cast_rays). They are cast in the order given (the coherent order,
ray_order.py, is the host's: on a CPU device it pays only for scenes beyond the cache, and each ray is
traced on its own, so no bit changes). What the host derives from the kernel's results (a block's
primitive, label, position) is derived here by small device kernels, to the same bits.

On the GPU class the hit queries (engine/queries/hits.py) of host rays take the same check (HitRays)
and put all_hits' rows in their CSR places on the device (all_hits_device); occupancy's parity grid
is looked up here too (grid_lookup_device: engine/queries/closest.py).
"""
from __future__ import annotations

import math

import numpy as np
import pyopencl as cl
import pyopencl.array as cl_array

from ...model.aovs import TABLE
from ...model.errors import RequestError
from ...model.shapes.base import labels_of
from ..launch.programs import Variant, kernel_for, ray_group
from ..launch.run import REAL, input_buffer
from ..launch.signatures import arguments, image_parameter
from ..opencl.buffers import shares_host_memory
from ..opencl.device import launch, launch_kept
from .cast import _BOUNDS, RayBatch, _block_lanes_table, _distances, _ray_array, ray_arguments, run_cast
from .requests import Frame

OUTS = ("host", "device")


def is_device_array(value) -> bool:
    return isinstance(value, cl_array.Array)


def check_out(out) -> str:
    if not isinstance(out, str) or out not in OUTS:
        raise RequestError(f"out: expected one of {', '.join(OUTS)}, got {out!r}")
    return out


def _device_rays(ctx, kernels, name: str, value) -> cl_array.Array:
    """value as a contiguous float64 device array of shape (..., 3) on ctx's context: a device array
    converted there (float32 widened exactly), a host array uploaded."""
    if not is_device_array(value):  # a host array, checked as cast's (cast.py: _ray_array)
        value = cl_array.to_device(ctx.queue, np.ascontiguousarray(_ray_array(name, value)))
    elif value.context.int_ptr != ctx.context.int_ptr:
        raise RequestError(f"{name}: a pyopencl array on another context than the handle's (its device's context)")
    if value.dtype not in (np.float32, np.float64):
        raise RequestError(f"{name}: expected a device array of float32 or float64, got {value.dtype}")
    if value.ndim == 0 or value.shape[-1] != 3:
        raise RequestError(f"{name}: expected an array of shape (..., 3), got shape {value.shape}")
    if not value.flags.c_contiguous:
        raise RequestError(f"{name}: expected a contiguous device array")
    if value.queue is None or value.queue != ctx.queue:
        value = value.with_queue(ctx.queue)
    if value.dtype == np.float64:
        return value
    wide = cl_array.empty(ctx.queue, value.shape, np.float64)
    if value.size:
        kernels.run(ctx.queue, "widen", value.size, wide.data, value.data, np.int64(value.size))
    return wide


# The device kernels of device casts (OpenCL C; FP_CONTRACT off: positions round each operation as
# numpy does, to the host path's bits).
SOURCE = """
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#define CHECK_GROUP 64
#pragma OPENCL FP_CONTRACT OFF

__kernel void widen(__global double *out, __global const float *in, long n) {
    for (long i = get_global_id(0); i < n; i += get_global_size(0)) out[i] = (double)in[i];
}

/* the largest distance of the rays' origins from the anchor on any axis, +inf where a coordinate is
   not finite or a direction is zero (the host path's refusals), one per work-group (CHECK_GROUP items,
   reduced in local memory: a few kB however many work-items share the rays); with repair, each ray
   refused (not within bound) becomes a harmless one in the buffers (the call's own copies: a shared
   origin, s 0, is checked on the host), which the cast kernel may then follow before the host reads
   the partial results */
__kernel __attribute__((reqd_work_group_size(CHECK_GROUP, 1, 1)))
void reach(__global double *partial, __global double *o, int s, __global double *d,
           long n, double ax, double ay, double az, double bound, int repair) {
    __local double most_of[CHECK_GROUP];
    double most = 0.0;
    for (long i = get_global_id(0); i < n; i += get_global_size(0)) {
        double x = o[3 * i * s], y = o[3 * i * s + 1], z = o[3 * i * s + 2];
        double u = d[3 * i], v = d[3 * i + 1], w = d[3 * i + 2];
        int fine = isfinite(x) && isfinite(y) && isfinite(z) && isfinite(u) && isfinite(v) && isfinite(w)
                   && (u != 0 || v != 0 || w != 0);
        double r = fine ? fmax(fabs(x - ax), fmax(fabs(y - ay), fabs(z - az))) : INFINITY;
        most = (r > most || isnan(r)) ? r : most;
        if (repair && !(r <= bound)) {
            d[3 * i] = 1.0; d[3 * i + 1] = 0.0; d[3 * i + 2] = 0.0;
            if (s) { o[3 * i] = ax; o[3 * i + 1] = ay; o[3 * i + 2] = az; }
        }
    }
    const int l = get_local_id(0);
    most_of[l] = most;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int apart = CHECK_GROUP / 2; apart > 0; apart >>= 1) {
        if (l < apart) {
            const double other = most_of[l + apart];
            most_of[l] = (other > most_of[l] || isnan(other)) ? other : most_of[l];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (l == 0) partial[get_group_id(0)] = most_of[0];
}

/* a block's key (-2 - key) -> its triangle's primitive (cast.py: _block_primitives): the block at
   place key >> 3, found by a binary search of the sorted places */
__kernel void block_primitives(__global int *p, long n, __global const long *places, int n_places,
                               __global const long *first, __global const int *primitives) {
    for (long i = get_global_id(0); i < n; i += get_global_size(0)) {
        if (p[i] > -2) continue;
        long key = -2 - (long)p[i];
        long place = key >> 3;
        int lo = 0, hi = n_places - 1;
        while (lo < hi) { int mid = (lo + hi) / 2; if (places[mid] < place) lo = mid + 1; else hi = mid; }
        p[i] = primitives[first[lo] + (key & 7)];
    }
}

__kernel void labels(__global int *label, __global const int *id, long n, __global const int *table, int n_table) {
    for (long i = get_global_id(0); i < n; i += get_global_size(0))
        label[i] = (id[i] < 0 || id[i] >= n_table) ? -1 : table[id[i]];
}

/* origin + t times the unit direction (RayBatch.positions: the direction scaled by a power of two
   first, from the exponent bits of its largest magnitude, as kernels/rays.h does), (0, 0, 0) on a miss */
#define POSITIONS(REAL) \
__kernel void positions_##REAL(__global REAL *pos, __global const REAL *depth, long n, __global const double *o, \
                               int s, __global const double *d) { \
    for (long i = get_global_id(0); i < n; i += get_global_size(0)) { \
        double t = (double)depth[i]; \
        if (!isfinite(t)) { pos[3 * i] = 0; pos[3 * i + 1] = 0; pos[3 * i + 2] = 0; continue; } \
        double x = d[3 * i], y = d[3 * i + 1], z = d[3 * i + 2]; \
        long field = 2046L - (as_long(fmax(fabs(x), fmax(fabs(y), fabs(z)))) >> 52); \
        double scale = as_double((field < 1L ? 1L : field) << 52); \
        x = x * scale; y = y * scale; z = z * scale; \
        double length = sqrt((x * x + y * y) + z * z); \
        double ux = x / length, uy = y / length, uz = z / length; \
        pos[3 * i] = (REAL)(o[3 * i * s] + t * ux); \
        pos[3 * i + 1] = (REAL)(o[3 * i * s + 1] + t * uy); \
        pos[3 * i + 2] = (REAL)(o[3 * i * s + 2] + t * uz); \
    } \
}
POSITIONS(float)
POSITIONS(double)

/* the hit queries' rows (engine/queries/hits.py): each of a pass's rays' hits, stored by the all_hits
   kernel from i * capacity on, copied to its ray's place in the CSR rows (offsets[ray], ray = rays[i]
   where mapped: a second pass over the rays with more hits than the first had room for); a ray
   with more hits than its pass's room is skipped (the second pass writes its rows) */
__kernel void hit_rows(__global double *t_out, __global int *kind_out, __global int *k_out, __global int *sub_out,
                       __global const double *t, __global const int *kind, __global const int *k,
                       __global const int *sub, __global const int *counts, long n, int capacity,
                       __global const long *offsets, __global const long *rays, int mapped) {
    for (long i = get_global_id(0); i < n; i += get_global_size(0)) {
        const int c = counts[i];
        if (c > capacity) continue;
        const long to = offsets[mapped ? rays[i] : i], from = i * (long)capacity;
        for (int j = 0; j < c; j++) {
            t_out[to + j] = t[from + j]; kind_out[to + j] = kind[from + j];
            k_out[to + j] = k[from + j]; sub_out[to + j] = sub[from + j];
        }
    }
}

/* occupancy's parity grid (engine/queries/parity_grid.py: _lookup, the same operations): per point
   decided (1 beyond the grid, in an empty coarse cell or in an empty fine cell of a refined block)
   and inside (its empty cell's state) */
__kernel void grid_lookup(__global uchar *decided, __global uchar *inside, __global const double *p, long n,
                          double lo0, double lo1, double lo2, double fine_size, long d0, long d1, long d2,
                          int shift, __global const char *state, __global const int *blocks,
                          __global const ulong *fine_bits) {
    const double lo[3] = {lo0, lo1, lo2};
    const long dims[3] = {d0, d1, d2};
    const long block = 1L << shift, mask = block - 1, words = (block * block * block) >> 6;
    for (long i = get_global_id(0); i < n; i += get_global_size(0)) {
        long cell = 0, fine[3];
        for (int axis = 2; axis >= 0; axis--) {
            const double c = (p[3 * i + axis] - lo[axis]) / fine_size;
            if (!(c >= 0.0 && c < (double)(dims[axis] * block))) { cell = -1; break; }
            fine[axis] = (long)c;
            cell = cell * dims[axis] + (fine[axis] >> shift);
        }
        uchar d = 1, occupied = 0;
        if (cell >= 0) {
            const char s = state[cell];
            if (s != -1) {
                occupied = (uchar)s;
            } else if (blocks[cell] >= 0) {
                const long place = ((((fine[2] & mask) << shift) + (fine[1] & mask)) << shift) + (fine[0] & mask);
                const long at = (long)blocks[cell] * 2 * words + (place >> 6);
                const ulong bit = (ulong)(place & 63);
                d = !((fine_bits[at] >> bit) & 1UL);
                occupied = d ? (uchar)((fine_bits[at + words] >> bit) & 1UL) : 0;
            } else {
                d = 0;
            }
        }
        decided[i] = d;
        inside[i] = occupied;
    }
}
"""

# the work-items of the helper kernels, each looping over its share of the rays: at most 65,536 (each
# over 16 or more rays of a million: a GPU's memory is read at its pace; 1,024 were few for it)
ITEMS = 1 << 16
# the check's (kernel reach): work-groups of CHECK_GROUP items (SOURCE's), at most CHECK_GROUPS of them
# (ITEMS in all), each group's result one double of the partial results read back
CHECK_GROUP = 64
CHECK_GROUPS = 1024


def check_groups(count: int) -> int:
    """The work-groups of the check of count rays."""
    return max(1, min(-(-count // CHECK_GROUP), CHECK_GROUPS))


class DeviceKernels:
    """The helper kernels of device casts on one context, built at their first use."""

    def __init__(self, context):
        self.program = cl.Program(context, SOURCE).build()
        self.kernels = {name: getattr(self.program, name)
                        for name in ("widen", "reach", "block_primitives", "labels", "positions_float", "positions_double",
                                     "hit_rows", "grid_lookup")}

    def run(self, queue, name: str, n: int, *args):
        """The kernel over n rays (a work-item per ray up to ITEMS, each looping over its share; the
        check: check_groups(n) work-groups)."""
        if name == "reach":
            groups = check_groups(n)
            return self.kernels[name](queue, (groups * CHECK_GROUP,), (CHECK_GROUP,), *args)
        items = max(1, min(n, ITEMS))
        return self.kernels[name](queue, (items,), None, *args)


def _kernels(tracer) -> DeviceKernels:
    kernels = tracer.ray_buffers.device_kernels
    if kernels is None:
        kernels = tracer.ray_buffers.device_kernels = DeviceKernels(tracer.ctx.context)
    return kernels


def run_cast_device(tracer, query: str, origins, directions, tmax, aovs, tmin, out: str):
    """cast or occluded (engine/queries/cast.py: run_cast) of device rays, or of host rays on a device of
    the GPU class (engine/opencl/device.py: gpu_class); out: "device" leaves the results pyopencl
    arrays, "host" reads each back once.

    Host rays are uploaded once each into copies of the call's own (a host-results call's into the
    handle's kept buffers, under their lock), which the check's kernel may repair: it writes a
    harmless ray over each refused one, so the cast kernel follows it at once, and the check's
    partial results are read back with the cast's (a host-results call's all in one copy of one kept
    buffer's regions); only a refused batch is then cast by the host path, which names its first bad
    row. Device rays are the caller's: checked before the cast."""
    try:
        if is_device_array(origins) or is_device_array(directions):
            return _cast(tracer, query, origins, directions, tmax, aovs, tmin, out, own=False, kept=None)
        if out == "device":  # its results are new arrays, its rays new copies (no later call waits for them)
            return _cast(tracer, query, origins, directions, tmax, aovs, tmin, out, own=True, kept=None)
        kept = tracer.ray_buffers
        with kept.lock:  # from the rays' writes to the results' reads
            return _cast(tracer, query, origins, directions, tmax, aovs, tmin, out, own=True, kept=kept)
    except RaysRefused as refused:  # the host path's checks name the first bad row (of the rays as given)
        result = run_cast(tracer, query, *refused.rays, tmax, aovs, tmin)
        raise RequestError(f"the rays were refused on the device but not on the host ({type(result).__name__})") from None


class RaysRefused(Exception):
    """The device's check refused a ray: the host path is to name it (outside the kept buffers' lock,
    which the host path takes)."""

    def __init__(self, rays: tuple):
        super().__init__()
        self.rays = rays


def _given_rays(ctx, kernels, origins, directions, tmin, tmax, bad_distance):
    """The checks every device path makes of its arguments before any kernel, in the host path's
    order: (origins, directions, shape, stride, tmin, tmax): device rays (pyopencl arrays, float32
    widened) or host arrays as cast's (cast.py: _ray_array), their shapes (one origin: stride 0), and
    tmin and tmax (cast.py: _distances). bad_distance(origins, directions) runs before a bad
    distance's RequestError: the rays' own refusal comes first, as on the host path."""
    if is_device_array(origins) or is_device_array(directions):
        directions = _device_rays(ctx, kernels, "directions", directions)
        origins = _device_rays(ctx, kernels, "origins", origins)
    else:
        directions = _ray_array("directions", directions)
        origins = _ray_array("origins", origins)
    shape = directions.shape[:-1]
    if origins.shape != directions.shape and origins.shape != (3,):
        raise RequestError(
            f"origins: expected shape {directions.shape} like directions, or (3,) for one origin, got {origins.shape}")
    try:
        tmax = _distances("tmax", tmax, shape, np.inf, lambda v: v > 0, "numbers > 0 (inf for no limit)")
        tmin = _distances("tmin", tmin, shape, 0.0, lambda v: (v >= 0) & (v < np.inf), "finite numbers >= 0")
    except RequestError:
        bad_distance(origins, directions)
        raise
    return origins, directions, shape, 1 if origins.shape == directions.shape else 0, tmin, tmax


def _cast(tracer, query, origins, directions, tmax, aovs, tmin, out, own: bool, kept):
    ctx, precision = tracer.ctx, tracer.precision
    queue = ctx.queue
    kernels = _kernels(tracer)
    given = (origins, directions)

    def refused():
        raise RaysRefused(given if own else (origins.get(), directions.get()))

    # (host rays: the host path's first refusal, a bad ray's before a bad distance's; device rays: the distance's)
    origins, directions, shape, stride, tmin, tmax = _given_rays(
        ctx, kernels, origins, directions, tmin, tmax, lambda *rays: refused() if own else None)
    count = math.prod(shape)
    inputs = tracer.cast_inputs()
    anchor, block_lanes = inputs[1], inputs[4]
    args, pairs = ray_arguments(tracer, inputs)  # the tree: pair nodes (GPUs) or wide ones
    real = REAL[precision]
    # the distances the kernel squares must stay below the square root of the largest real (cast.py: RayBatch)
    bound = _BOUNDS[precision]
    partial = None  # the check's largest distance per work-item, where it is read back after the cast
    items = check_groups(count)  # the check's partial results
    needed = set(aovs) | ({"id"} if "label" in aovs else set()) | ({"depth"} if "position" in aovs else set())
    kernel_aovs = tuple(a for a in ("depth", "normal", "id", "primitive", "barycentric") if a in needed)
    regions = None
    if kept is not None:  # the results and the check's in regions of one kept buffer, read back in one copy
        parts = [("check", (items,), np.float64)] if count else []
        if query == "occluded":
            parts.append(("occluded_out", shape, np.bool_))
        else:
            parts += [(image_parameter(k), TABLE[k].shape((count,)), TABLE[k].dtype(precision)) for k in kernel_aovs]
            parts += [(k, (count,) + TABLE[k].shape(()), TABLE[k].dtype(precision)) for k in ("label", "position")
                      if k in aovs]
        layout = {part: (shape_, np.dtype(dtype)) for part, shape_, dtype in parts}
        subs, offsets, total = kept.regions(ctx, "results", tuple((part, math.prod(shape_) * dtype.itemsize)
                                                                  for part, (shape_, dtype) in layout.items()))
        regions = (layout, subs, offsets, total)
    if own:
        if stride == 0:  # one origin: checked here (the kernel repairs no shared origin), even without rays
            with np.errstate(over="ignore", invalid="ignore"):
                if not np.abs(origins - anchor[:3]).max() <= bound:
                    refused()
        if kept is not None:
            o_buffer, d_buffer = kept.write(ctx, "origins", origins), kept.write(ctx, "directions", directions)
        else:
            o_buffer, d_buffer = (cl_array.to_device(queue, np.ascontiguousarray(a)).data for a in (origins, directions))
        if count:
            partial = regions[1]["check"] if kept is not None else cl.Buffer(ctx.context, cl.mem_flags.READ_WRITE, 8 * items)
            kernels.run(queue, "reach", count, partial, o_buffer, np.int32(stride), d_buffer, np.int64(count),
                        *(np.float64(a) for a in anchor[:3]), np.float64(bound), np.int32(1))
    else:
        o_buffer, d_buffer = origins.data, directions.data
        if count:
            check = cl_array.empty(queue, (items,), np.float64)
            kernels.run(queue, "reach", count, check.data, o_buffer, np.int32(stride), d_buffer, np.int64(count),
                        *(np.float64(a) for a in anchor[:3]), np.float64(bound), np.int32(0))
            if not _fine(check.get(), bound):  # one read of a few kB before the cast: the caller's rays
                refused()
    rays = (count, o_buffer, stride, d_buffer, _constant(tracer, tmin), len(tmin) > 1, _constant(tracer, tmax),
            len(tmax) > 1, anchor, args)

    # the results: regions of the handle's kept buffer (host results of host rays), else new device arrays
    def result(name: str, shape: tuple, dtype):
        if kept is None:
            return cl_array.empty(queue, shape, dtype)
        return name, regions[1][name]

    def data(value):  # a result's buffer
        return value.data if isinstance(value, cl_array.Array) else value[1]

    if query == "occluded":
        results = {"occluded": result("occluded_out", shape, np.bool_)}
        if count:
            _launch(tracer, Variant("occluded", tracer.prepared.types, (), precision, pairs=pairs), *rays,
                    {"occluded_out": data(results["occluded"])}, *ray_group(pairs), kept)
        return _finish(ctx, kept, results, out, partial, items, bound, refused, regions)["occluded"]
    results = {k: result(image_parameter(k), TABLE[k].shape((count,)), TABLE[k].dtype(precision)) for k in kernel_aovs}
    if count:
        variant = Variant("cast", tracer.prepared.types, kernel_aovs, precision, pairs=pairs)
        _launch(tracer, variant, *rays, {image_parameter(k): data(v) for k, v in results.items()}, *ray_group(pairs),
                kept)
        if "primitive" in results and block_lanes:
            places, first, primitives = _block_lanes_table(tracer, block_lanes, queue)
            kernels.run(queue, "block_primitives", count, data(results["primitive"]), np.int64(count), places.data,
                        np.int32(places.size), first.data, primitives.data)
    frame = {}
    for name in aovs:
        if name in results:
            frame[name] = results[name]
        elif name == "label":
            labels = _label_table(tracer, queue)
            label = frame[name] = result("label", (count,), np.int32)
            if count:
                kernels.run(queue, "labels", count, data(label), data(results["id"]), np.int64(count), labels.data,
                            np.int32(labels.size - 1))
        elif name == "position":
            position = frame[name] = result("position", (count, 3), real)
            if count:
                kernels.run(queue, "positions_float" if real == np.float32 else "positions_double", count,
                            data(position), data(results["depth"]), np.int64(count), o_buffer, np.int32(stride),
                            d_buffer)
    frame = _finish(ctx, kept, frame, out, partial, items, bound, refused, regions)
    frame = {k: v.reshape(shape + v.shape[1:]) for k, v in frame.items()}
    return Frame(frame, precision=precision, device=ctx.device.name.strip())


def _fine(partial: np.ndarray, bound: float) -> bool:
    """Whether the check's partial results (kernel reach) pass: no ray refused, every origin within bound."""
    return not np.isnan(partial).any() and partial.max() <= bound


def _finish(ctx, kept, results: dict, out: str, partial, items: int, bound: float, refused, regions) -> dict:
    """The results by name: device arrays (out="device"), else host arrays read back behind one wait:
    the kept buffer's regions (KeptBuffers.regions) in one copy, whose views they are (out of its
    host memory after the wait on a device whose buffers are host memory), else a copy each of the
    device arrays. The check's partial results are read with them, and a refused batch raises
    (refused)."""
    queue = ctx.queue
    if out == "device":
        if partial is not None:
            check = np.empty(items, np.float64)
            cl.enqueue_copy(queue, check, partial)
            if not _fine(check, bound):
                refused()
        return results
    if kept is None:
        arrays = {k: np.empty(v.shape, v.dtype) for k, v in results.items()}
        for k, v in results.items():
            if v.size:
                cl.enqueue_copy(queue, arrays[k], v.data, is_blocking=False)
        queue.finish()
        return arrays
    layout, _, offsets, total = regions
    block = np.empty(total, np.uint8)
    if shares_host_memory(ctx):
        queue.finish()  # then the results are in the kept buffer's memory, copied out at once
        kept.read(ctx, "results", block)
    else:
        kept.read(ctx, "results", block)
        queue.finish()

    def view(part):
        shape, dtype = layout[part]
        return block[offsets[part]:offsets[part] + math.prod(shape) * dtype.itemsize].view(dtype).reshape(shape)

    if partial is not None and not _fine(view("check"), bound):
        refused()
    return {k: view(part) for k, (part, _) in results.items()}


def _constant(tracer, values: np.ndarray) -> cl.Buffer:
    """A read-only buffer of tmin's or tmax's values: one number's kept on the handle by its value
    (KeptBuffers.constant: no later call copies it again), an array's a new copy."""
    if len(values) > 1:
        return input_buffer(tracer.ctx, np.ascontiguousarray(values))
    return tracer.ray_buffers.constant(tracer.ctx, values)


def _label_table(tracer, queue) -> cl_array.Array:
    """The shapes' labels and -1 (label_of's table) on the device, uploaded once per shapes."""
    kept = tracer.ray_buffers
    shapes = tracer.shapes
    if kept.label_table is None or kept.label_table[0] is not shapes:
        kept.label_table = (shapes, cl_array.to_device(queue, np.append(labels_of(shapes), np.int32(-1))))
    return kept.label_table[1]


def _launch(tracer, variant, count, o_buffer, stride, d_buffer, starts, start_stride, limits, limit_stride, anchor,
            args, outputs, group, work_group, kept=None):
    """Enqueue the kernel over the device rays (in their order: the order buffer is not read); with
    kept (the rays and results in the handle's kept buffers), its arguments set only where they
    changed (device.py: launch_kept)."""
    ctx = tracer.ctx
    groups = -(-count // group)
    sizes = ((-(-groups // work_group) * work_group,), (work_group,))
    values = {"n_rays": np.int32(count), "ordered": np.int32(0), "order": _constant(tracer, NO_ORDER),
              "origins": o_buffer, "origin_stride": np.int32(stride), "directions": d_buffer,
              "limits": limits, "limit_stride": np.int32(limit_stride), "starts": starts,
              "start_stride": np.int32(start_stride), **args, **outputs}  # (args: the scene's anchor too)
    if kept is None:
        launch(ctx, kernel_for(ctx, variant), *sizes, arguments(variant, values))
    else:
        launch_kept(ctx, kernel_for(ctx, variant), *sizes, arguments(variant, values), kept.launches)


NO_ORDER = np.zeros(1, np.int32)  # (the kernel reads no order: ordered is 0)


# -- the hit queries (engine/queries/hits.py) of host rays on a device of the GPU class ---------------
class HitRays:
    """Rays checked on the device by the check's kernel (reach) for count_hits' and all_hits' kernels:
    host arrays uploaded once into the call's own copies, which the check repairs (each refused ray
    made harmless, its partial results read back with the first results); device arrays (pyopencl
    arrays on the handle's context, float32 widened there) the caller's, checked before the query
    (a few kB read back). origins and directions: the host's float64 arrays, flattened, for what the
    host derives from the hits (all_hits' positions, its second pass's rays): device rays read back
    only then. Also their buffers, tmin and tmax, shape, count and the kernels' arguments (launch). A
    refused ray raises RaysRefused (the host path names it)."""

    def __init__(self, tracer, origins, directions, tmin, tmax):
        ctx = tracer.ctx
        self.tracer, self.given = tracer, (origins, directions, tmin, tmax)
        self.kernels = _kernels(tracer)
        self.device = is_device_array(origins) or is_device_array(directions)
        inputs = tracer.cast_inputs()
        self.anchor, self.block_lanes = inputs[1], inputs[4]
        # (before a bad distance's line, a bad ray's: check_now)
        origins, directions, shape, self.stride, tmin, tmax = _given_rays(ctx, self.kernels, origins, directions, tmin,
                                                                          tmax, self.check_now)
        self.args, self.pairs = ray_arguments(tracer, inputs)
        self.bound = _BOUNDS[tracer.precision]  # (as cast's: RayBatch)
        self.shape, self.count = shape, math.prod(shape)
        self._rays = (origins, directions)
        self._host = None if self.device else (origins.reshape(-1, 3), directions.reshape(-1, 3))
        self.tmin, self.tmax = tmin, tmax
        if self.stride == 0:  # one origin: checked here (the kernel repairs no shared origin), even without rays
            origin = origins.get() if self.device else origins
            with np.errstate(over="ignore", invalid="ignore"):
                if not np.abs(origin - self.anchor[:3]).max() <= self.bound:
                    self.refused()
        self.items = check_groups(self.count)
        self.partial = None
        if self.count and self.device:  # the caller's rays: checked before the query, not repaired
            self.buffers = (origins.data, self.stride, directions.data, _constant(tracer, tmin), len(tmin) > 1,
                            _constant(tracer, tmax), len(tmax) > 1)
            if not _fine(self.reach(cl_array.empty(ctx.queue, (self.items,), np.float64).data, repair=False),
                         self.bound):
                self.refused()
        elif self.count:
            self.buffers = self.upload(self._host[0], self._host[1], tmin, tmax)
            self.partial = cl.Buffer(ctx.context, cl.mem_flags.READ_WRITE, 8 * self.items)
            self.reach(self.partial, repair=True)

    def reach(self, partial, repair: bool):
        """The check's kernel over the rays into partial; without repair, its results read back now."""
        queue = self.tracer.ctx.queue
        self.kernels.run(queue, "reach", self.count, partial, self.buffers[0], np.int32(self.stride), self.buffers[2],
                         np.int64(self.count), *(np.float64(a) for a in self.anchor[:3]), np.float64(self.bound),
                         np.int32(1 if repair else 0))
        if not repair:
            check = np.empty(self.items, np.float64)
            cl.enqueue_copy(queue, check, partial)
            return check

    def check_now(self, origins, directions):
        """Before a bad distance's line: a bad ray's, as on the host path (host rays: that path names
        either; device rays: checked here, else the distance's line stands)."""
        if not self.device:
            self.refused()
        count = math.prod(directions.shape[:-1])
        if count:
            self.count, self.items = count, check_groups(count)
            self.stride = 1 if origins.shape == directions.shape else 0
            self.bound = _BOUNDS[self.tracer.precision]
            self.buffers = (origins.data, self.stride, directions.data)
            if not _fine(self.reach(cl_array.empty(self.tracer.ctx.queue, (self.items,), np.float64).data, False),
                         self.bound):
                self.refused()

    @property
    def origins(self):
        return self.host()[0]

    @property
    def directions(self):
        return self.host()[1]

    def host(self) -> tuple:
        """(origins, directions): the rays as float64 host arrays, flattened (device rays read back once)."""
        if self._host is None:
            self._host = tuple(a.get().reshape(-1, 3) for a in self._rays)
        return self._host

    # the points at distances along rays, as the host path's batch makes them (all_hits' positions)
    unit_directions = RayBatch.unit_directions
    positions = RayBatch.positions

    def refused(self):
        if self.device:  # the host path names the row of the rays as given, read back
            origins, directions, tmin, tmax = self.given
            raise RaysRefused(tuple(a.get() if is_device_array(a) else a for a in (origins, directions)) + (tmin, tmax))
        raise RaysRefused(self.given)

    def upload(self, origins, directions, tmin, tmax) -> tuple:
        """(origins, origin stride, directions, tmin, its stride, tmax, its stride): the buffers and
        strides of rays (copies of the arrays: the check's kernel may repair them)."""
        queue = self.tracer.ctx.queue
        o_buffer, d_buffer = (cl_array.to_device(queue, np.ascontiguousarray(a)).data for a in (origins, directions))
        return (o_buffer, 1 if len(origins) > 1 else 0, d_buffer, _constant(self.tracer, tmin), len(tmin) > 1,
                _constant(self.tracer, tmax), len(tmax) > 1)

    def launch(self, query: str, count: int, buffers: tuple, outputs: dict, aovs: tuple = ()) -> None:
        """Enqueue the query's kernel (count_hits, all_hits; with aovs) over count rays in buffers (upload)."""
        variant = Variant(query, self.tracer.prepared.types, aovs, self.tracer.precision, pairs=self.pairs)
        o_buffer, stride, d_buffer, starts, start_stride, limits, limit_stride = buffers
        _launch(self.tracer, variant, count, o_buffer, stride, d_buffer, starts, start_stride, limits, limit_stride,
                self.anchor, self.args, outputs, *ray_group(self.pairs))

    def read_checked(self, arrays: dict) -> None:
        """Read back the device arrays into the host arrays (name -> (buffer, array)) behind one wait,
        with the check's partial results: a refused batch raises RaysRefused."""
        queue = self.tracer.ctx.queue
        check = np.empty(self.items, np.float64)
        if self.partial is not None:
            cl.enqueue_copy(queue, check, self.partial, is_blocking=False)
        for buffer, array in arrays.values():
            if array.size:
                cl.enqueue_copy(queue, array, buffer, is_blocking=False)
        queue.finish()
        if self.partial is not None and not _fine(check, self.bound):
            self.refused()


def hit_counts_device(tracer, origins, directions, tmin, tmax, surface: dict | None = None):
    """count_hits (hits.py: run_count_hits) of host rays on a device of the GPU class: uploaded once,
    checked and counted on the device, the counts and the check's results read back once; with
    surface (occupancy's rays from points: hits.py's count_from_points, its surface test's
    arguments), (counts, on, signed) of the flat rays. A refused ray raises RaysRefused, whose rays
    the caller's host path checks to name the first bad row (hits.py)."""
    rays = HitRays(tracer, origins, directions, tmin, tmax)
    counts = np.zeros(rays.count, np.int32)
    on = np.zeros(rays.count, np.uint8)
    signed = np.zeros(rays.count, np.int32)
    if rays.count:
        context = tracer.ctx.context
        buffer = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, counts.nbytes)
        if surface is None:
            rays.launch("count_hits", rays.count, rays.buffers, {"hit_counts": buffer})
            rays.read_checked({"counts": (buffer, counts)})
        else:
            on_buffer = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, on.nbytes)
            signed_buffer = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, signed.nbytes)
            rays.launch("count_hits", rays.count, rays.buffers, {**surface, "hit_counts": buffer, "surface_out": on_buffer,
                                                                 "surface_signed_out": signed_buffer}, ("surface",))
            rays.read_checked({"counts": (buffer, counts), "on": (on_buffer, on), "signed": (signed_buffer, signed)})
    return counts.reshape(rays.shape) if surface is None else (counts, on, signed)


def all_hits_device(tracer, origins, directions, tmin, tmax, capacity: int):
    """(rays, counts, t, kinds, entries, subs) of all_hits (hits.py: run_all_hits) of host rays on a
    device of the GPU class: rays (HitRays) uploaded once and checked on the device; one pass of the
    all_hits kernel with room for capacity hits a ray, its counts read back with the check's results
    (the CSR offsets their cumulative sum, in numpy); the rays with more hits again, alone (gathered
    on the host: numpy's fancy indexing of those rows), with room for the most; each pass's rows
    copied into their CSR places on the device (kernel hit_rows) and the hits read back once."""
    return _all_hits(tracer, HitRays(tracer, origins, directions, tmin, tmax), capacity)


def _stored_pass(rays: HitRays, count: int, buffers: tuple, capacity: int) -> tuple:
    """The all_hits kernel over count rays in buffers with room for capacity hits each: its device
    buffers (counts, t, kinds, entries, subs)."""
    context = rays.tracer.ctx.context
    rows = max(1, count * capacity)
    out = (cl.Buffer(context, cl.mem_flags.READ_WRITE, 4 * count), cl.Buffer(context, cl.mem_flags.READ_WRITE, 8 * rows),
           *(cl.Buffer(context, cl.mem_flags.READ_WRITE, 4 * rows) for _ in range(3)))
    rays.launch("all_hits", count, buffers, {"hit_counts": out[0], "hit_capacity": np.int32(capacity), "hit_t": out[1],
                                             "hit_kind": out[2], "hit_k": out[3], "hit_sub": out[4]})
    return out


def _all_hits(tracer, rays: HitRays, capacity: int):
    ctx, n = tracer.ctx, rays.count
    queue = ctx.queue
    counts = np.zeros(n, np.int32)
    if not n:
        return rays, counts, np.zeros(0), *(np.zeros(0, np.int32) for _ in range(3))
    first = _stored_pass(rays, n, rays.buffers, capacity)
    rays.read_checked({"counts": (first[0], counts)})
    offsets = np.zeros(n + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    total = int(offsets[-1])
    hits = (np.empty(total, np.float64), *(np.empty(total, np.int32) for _ in range(3)))
    if not total:
        return (rays, counts, *hits)
    outs = tuple(cl.Buffer(ctx.context, cl.mem_flags.READ_WRITE, a.nbytes) for a in hits)
    offsets_buffer = cl_array.to_device(queue, offsets)
    rays.kernels.run(queue, "hit_rows", n, *outs, *first[1:], first[0], np.int64(n), np.int32(capacity),
                     offsets_buffer.data, offsets_buffer.data, np.int32(0))  # (rays: not read, mapped 0)
    over = np.flatnonzero(counts > capacity)
    if len(over):  # those rays again, alone, with room for all their hits (the same hits)
        pick = (lambda a: a[over] if len(a) > 1 else a)
        buffers = rays.upload(pick(rays.origins), rays.directions[over], pick(rays.tmin), pick(rays.tmax))
        most = int(counts[over].max())
        second = _stored_pass(rays, len(over), buffers, most)
        over_buffer = cl_array.to_device(queue, over.astype(np.int64))
        rays.kernels.run(queue, "hit_rows", len(over), *outs, *second[1:], second[0], np.int64(len(over)),
                         np.int32(most), offsets_buffer.data, over_buffer.data, np.int32(1))
    for array, buffer in zip(hits, outs):
        cl.enqueue_copy(queue, array, buffer, is_blocking=False)
    queue.finish()
    return (rays, counts, *hits)


def grid_lookup_device(tracer, grid, points: np.ndarray, sign: str) -> tuple[np.ndarray, np.ndarray]:
    """(decided, inside) per point, bool each: occupancy's parity grid (parity_grid.py:
    ParityGrid.lookup) on a device of the GPU class, its arrays (the coarse cells' states and
    blocks, the fine cells' bits) uploaded once per grid and sign (kept on the grid), the points
    uploaded once, two bytes per point read back."""
    queue = tracer.ctx.queue
    count = len(points)
    decided, inside = np.zeros(count, np.uint8), np.zeros(count, np.uint8)
    if count:
        kept = grid.device_states
        if sign not in kept:
            state, bits = grid.states[sign]
            kept[sign] = [cl_array.to_device(queue, np.ascontiguousarray(a, dtype))
                          for a, dtype in ((state, np.int8), (grid.blocks, np.int32), (bits, np.uint64))]
        outs = [cl_array.empty(queue, count, np.uint8) for _ in range(2)]
        p = cl_array.to_device(queue, np.ascontiguousarray(points, np.float64))
        shift = int(grid.block).bit_length() - 1  # block = 2^shift
        _kernels(tracer).run(queue, "grid_lookup", count, outs[0].data, outs[1].data, p.data, np.int64(count),
                             *(np.float64(x) for x in grid.lo), np.float64(grid.fine_size),
                             *(np.int64(d) for d in grid.dims), np.int32(shift), *(a.data for a in kept[sign]))
        for out, array in zip(outs, (decided, inside)):
            cl.enqueue_copy(queue, array, out.data, is_blocking=False)
        queue.finish()
    return decided.view(bool), inside.view(bool)
