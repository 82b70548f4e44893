"""cast and occluded of rays given as device arrays (pyopencl arrays on the handle's context), their
results left on the device where asked (out="device"): a loop over a data set's rays then never
copies them through the host.

The rays are checked on the device: one reduction per call finds the largest distance of an origin
from the scene's anchor, +inf where a ray has a coordinate that is not finite or a zero direction;
only where that is not a fine value are the arrays read back, to name the first bad row as the host
path does (engine/queries/cast.py: _cast_rays). They are cast in the order given (the coherent order,
ray_order.py, is the host's: on a CPU device it pays only for scenes beyond the cache, and each ray is
traced on its own, so no bit changes). What the host derives from the kernel's results (a block's
primitive, label, position) is derived here by small device kernels, to the same bits.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pyopencl.array as cl_array

from ...model.aovs import TABLE
from ...model.errors import RequestError
from ...model.shapes.base import labels_of
from ..launch.programs import Variant, kernel_for, ray_group
from ..launch.run import REAL
from ..launch.signatures import arguments, image_parameter
from ..opencl.device import launch
from .cast import _block_lanes_table, _distances, _ray_array, ray_arguments, run_cast
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
#pragma OPENCL FP_CONTRACT OFF

__kernel void widen(__global double *out, __global const float *in, long n) {
    for (long i = get_global_id(0); i < n; i += get_global_size(0)) out[i] = (double)in[i];
}

/* per work-item the largest distance of its rays' origins from the anchor on any axis, +inf where a
   coordinate is not finite or a direction is zero (the host path's refusals) */
__kernel void reach(__global double *partial, __global const double *o, int s, __global const double *d,
                    long n, double ax, double ay, double az) {
    double most = 0.0;
    for (long i = get_global_id(0); i < n; i += get_global_size(0)) {
        double x = o[3 * i * s], y = o[3 * i * s + 1], z = o[3 * i * s + 2];
        double u = d[3 * i], v = d[3 * i + 1], w = d[3 * i + 2];
        int fine = isfinite(x) && isfinite(y) && isfinite(z) && isfinite(u) && isfinite(v) && isfinite(w)
                   && (u != 0 || v != 0 || w != 0);
        double r = fine ? fmax(fabs(x - ax), fmax(fabs(y - ay), fabs(z - az))) : INFINITY;
        most = (r > most || isnan(r)) ? r : most;
    }
    partial[get_global_id(0)] = most;
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
   first), (0, 0, 0) on a miss */
#define POSITIONS(REAL) \
__kernel void positions_##REAL(__global REAL *pos, __global const REAL *depth, long n, __global const double *o, \
                               int s, __global const double *d) { \
    for (long i = get_global_id(0); i < n; i += get_global_size(0)) { \
        double t = (double)depth[i]; \
        if (!isfinite(t)) { pos[3 * i] = 0; pos[3 * i + 1] = 0; pos[3 * i + 2] = 0; continue; } \
        double x = d[3 * i], y = d[3 * i + 1], z = d[3 * i + 2]; \
        double scale = exp2(-floor(log2(fmax(fabs(x), fmax(fabs(y), fabs(z)))))); \
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
"""

# the work-items of the helper kernels (each loops over its share of the rays)
ITEMS = 1024


class DeviceKernels:
    """The helper kernels of device casts on one context, built at their first use."""

    def __init__(self, context):
        self.program = cl.Program(context, SOURCE).build()
        self.kernels = {name: getattr(self.program, name)
                        for name in ("widen", "reach", "block_primitives", "labels", "positions_float", "positions_double")}

    def run(self, queue, name: str, n: int, *args):
        """The kernel over n rays (a work-item per ray up to ITEMS, each looping over its share)."""
        items = max(1, min(n, ITEMS))
        return self.kernels[name](queue, (items,), None, *args)


def _kernels(tracer) -> DeviceKernels:
    kernels = tracer.ray_buffers.device_kernels
    if kernels is None:
        kernels = tracer.ray_buffers.device_kernels = DeviceKernels(tracer.ctx.context)
    return kernels


def run_cast_device(tracer, query: str, origins, directions, tmax, aovs, tmin, out: str):
    """cast or occluded (engine/queries/cast.py: run_cast) of device rays; out: "device" leaves the
    results pyopencl arrays, "host" reads each back once."""
    ctx, precision = tracer.ctx, tracer.precision
    queue = ctx.queue
    kernels = _kernels(tracer)
    directions = _device_rays(ctx, kernels, "directions", directions)
    origins = _device_rays(ctx, kernels, "origins", origins)
    shape = directions.shape[:-1]
    if origins.shape != directions.shape and origins.shape != (3,):
        raise RequestError(
            f"origins: expected shape {directions.shape} like directions, or (3,) for one origin, got {origins.shape}")
    count = int(np.prod(shape))
    inputs = tracer.cast_inputs()
    anchor, block_lanes = inputs[1], inputs[4]
    args, pairs = ray_arguments(tracer, inputs)  # the tree: pair nodes (GPUs) or wide ones
    given = (tmin, tmax)  # for the host's checks, should the device refuse a ray
    tmax = _distances("tmax", tmax, shape, np.inf, lambda v: v > 0, "numbers > 0 (inf for no limit)")
    tmin = _distances("tmin", tmin, shape, 0.0, lambda v: (v >= 0) & (v < np.inf), "finite numbers >= 0")
    stride = 1 if origins.shape == directions.shape else 0
    if count:
        partial = cl_array.empty(queue, (max(1, min(count, ITEMS)),), np.float64)
        kernels.run(queue, "reach", count, partial.data, origins.data, np.int32(stride), directions.data,
                    np.int64(count), *(np.float64(a) for a in anchor[:3]))
        partial = partial.get()  # one read of a few kB: the largest, or where a ray is refused, NaN or inf
        reach = partial.max() if not np.isnan(partial).any() else np.nan
        bound = np.sqrt(np.finfo(REAL[precision]).max) / 4
        if not reach <= bound:  # the host path's checks name the first bad row
            result = run_cast(tracer, query, origins.get(), directions.get(), given[1], aovs, given[0])
            raise RequestError(f"the rays were refused on the device but not on the host ({type(result).__name__})")
    real = REAL[precision]

    def finish(arrays: dict):
        if out == "host":
            arrays = {k: v.get() for k, v in arrays.items()}
        return arrays

    if query == "occluded":
        result = cl_array.empty(queue, shape, np.bool_)
        if count:
            _launch(tracer, Variant("occluded", tracer.prepared.types, (), precision, pairs=pairs), count, origins, stride,
                    directions, tmin, tmax, anchor, args, {"occluded_out": result.data}, *ray_group(pairs))
        return finish({"occluded": result})["occluded"]
    needed = set(aovs) | ({"id"} if "label" in aovs else set()) | ({"depth"} if "position" in aovs else set())
    kernel_aovs = tuple(a for a in ("depth", "normal", "id", "primitive", "barycentric") if a in needed)
    results = {k: cl_array.empty(queue, TABLE[k].shape((count,)), TABLE[k].dtype(precision)) for k in kernel_aovs}
    if count:
        variant = Variant("cast", tracer.prepared.types, kernel_aovs, precision, pairs=pairs)
        _launch(tracer, variant, count, origins, stride, directions, tmin, tmax, anchor, args,
                {image_parameter(k): v.data for k, v in results.items()}, *ray_group(pairs))
        if "primitive" in results and block_lanes:
            places, first, primitives = _block_lanes_table(tracer, block_lanes, queue)
            kernels.run(queue, "block_primitives", count, results["primitive"].data, np.int64(count), places.data,
                        np.int32(places.size), first.data, primitives.data)
    frame = {}
    for name in aovs:
        if name in results:
            frame[name] = results[name]
        elif name == "label":
            labels = cl_array.to_device(queue, np.append(labels_of(tracer.shapes), np.int32(-1)))
            label = cl_array.empty(queue, (count,), np.int32)
            if count:
                kernels.run(queue, "labels", count, label.data, results["id"].data, np.int64(count), labels.data,
                            np.int32(labels.size - 1))
            frame[name] = label
        elif name == "position":
            position = cl_array.empty(queue, (count, 3), real)
            if count:
                kernels.run(queue, "positions_float" if real == np.float32 else "positions_double", count,
                            position.data, results["depth"].data, np.int64(count), origins.data, np.int32(stride),
                            directions.data)
            frame[name] = position
    frame = finish({k: v.reshape(*(shape + v.shape[1:])) for k, v in frame.items()})
    return Frame(frame, precision=precision, device=ctx.device.name.strip())


def _launch(tracer, variant, count, origins, stride, directions, tmin, tmax, anchor, args, outputs, group, work_group):
    """Enqueue the kernel over the device rays (in their order: no order buffer is read)."""
    ctx = tracer.ctx
    to_device = lambda array: cl_array.to_device(ctx.queue, np.ascontiguousarray(array)).data  # noqa: E731
    groups = -(-count // group)
    sizes = ((-(-groups // work_group) * work_group,), (work_group,))
    values = {"n_rays": np.int32(count), "ordered": np.int32(0), "order": to_device(np.zeros(1, np.int32)),
              "origins": origins.data, "origin_stride": np.int32(stride), "directions": directions.data,
              "limits": to_device(tmax), "limit_stride": np.int32(1 if len(tmax) > 1 else 0),
              "starts": to_device(tmin), "start_stride": np.int32(1 if len(tmin) > 1 else 0),
              "scene_anchor": anchor.astype(np.float64).view(cl.cltypes.double4)[0], **args, **outputs}
    launch(ctx, kernel_for(ctx, variant), *sizes, arguments(variant, values))
