"""Every hit along arbitrary rays: count_hits (how many, without storing them) and all_hits (each of
them, nearest first, in CSR form), each ray traced on its own from its float64 origin and direction
(kernels/allhits.cl, over cast's rays and inputs: engine/queries/cast.py).

Each crossing of a surface counts once: a mesh's triangles are tested with kernels/mesh.cl's tie rule
(a ray through a shared edge or vertex crosses exactly one triangle there, or two or none where it
only touches the surface), each analytic shape reports its real crossings (a tangent ray: none). So
the parity of count_hits from a point is inside/outside for a closed mesh, on every ray."""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from ...model.aovs import TABLE
from ...model.errors import RequestError
from ..launch.programs import Variant, kernel_for
from ..launch.run import REAL
from ..launch.signatures import arguments
from ..opencl.device import gpu_class, launch
from .cast import RayBatch, label_of
from .cast_device import RaysRefused, all_hits_device, hit_counts_device
from .requests import Frame

# The hit queries trace every large batch in cast's coherent order (engine/queries/ray_order.py), also
# where cast would not for a scene that fits the cache: each ray traverses the tree to its end, and
# neighbouring rays then share more of it (docs/benchmarks.md, "Hit counts": 117 against 138 ms on
# the bunny's 100,000 incoherent rays). Each ray's hits are the same in any order. A device of the GPU
# class takes none: its rays go through cast_device.py (HitRays: checked on the device, traced in
# their own order, all_hits' rows put in place there), as rays given as pyopencl arrays do anywhere.
ORDER_ALWAYS = True

# what all_hits can return per hit (and its default): the per-hit AOVs that hold for every hit
HIT_AOVS = ("depth", "normal", "id", "primitive", "barycentric", "label", "position")
DEFAULT_HIT_AOVS = ("depth", "id", "primitive")


def check_hit_aovs(aovs) -> tuple[str, ...]:
    """The AOVs asked of all_hits, in HIT_AOVS' order; anything else is a RequestError."""
    if isinstance(aovs, str):
        aovs = tuple(a.strip() for a in aovs.split(","))
    try:
        aovs = tuple(aovs)
    except TypeError:
        raise RequestError(f"aovs: expected a selection of {', '.join(HIT_AOVS)}, got {type(aovs).__name__}") from None
    bad = [a for a in aovs if not isinstance(a, str) or a not in HIT_AOVS]
    if bad or len(set(aovs)) != len(aovs):
        shown = ", ".join(a if isinstance(a, str) and a.isprintable() else repr(a) for a in aovs) or "none"
        raise RequestError(f"aovs: expected a selection of {', '.join(HIT_AOVS)} without repeats, got {shown}")
    return tuple(a for a in HIT_AOVS if a in aovs)


def _run(ctx, variant, batch: RayBatch, inputs: dict, outputs: dict) -> None:
    """Run the variant's kernel over the batch with its inputs and outputs (name -> array, written in
    place), and wait: on a CPU device it writes into the arrays' own memory (a map makes them
    current), elsewhere through device buffers copied back."""
    kernel = kernel_for(ctx, variant)
    cpu = bool(ctx.device.type & cl.device_type.CPU)
    buffers = {}
    for name, array in outputs.items():
        if cpu:
            buffers[name] = cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR,
                                      hostbuf=array if array.size else np.zeros(1, array.dtype))
        else:
            buffers[name] = cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY, max(array.nbytes, array.itemsize))
    launch(ctx, kernel, *batch.sizes, arguments(variant, {**batch.args, **inputs, **buffers}))
    for name, array in outputs.items():
        if not array.size:
            continue
        if cpu:
            mapped = cl.enqueue_map_buffer(ctx.queue, buffers[name], cl.map_flags.READ, 0, array.shape, array.dtype,
                                           is_blocking=True)[0]
            mapped.base.release()
        else:
            cl.enqueue_copy(ctx.queue, array, buffers[name])
    ctx.queue.finish()


def _counts(tracer, batch: RayBatch) -> np.ndarray:
    counts = np.zeros(batch.count, np.int32)
    if batch.count:
        variant = Variant("count_hits", tracer.prepared.types, (), tracer.precision, pairs=batch.pairs)
        _run(tracer.ctx, variant, batch, {}, {"hit_counts": counts})
    return counts


def _on_device(*arrays) -> bool:
    """Whether any of the rays' arrays is a pyopencl array (then the device path on any device)."""
    return any(type(a).__module__.startswith("pyopencl") for a in arrays)


def _name_the_refused(tracer, refused: RaysRefused, host_query) -> None:
    """Raise the host path's RequestError for rays the device's check refused (host_query: the same
    query on the host, whose checks name the first bad row of the rays as given)."""
    result = host_query(*refused.rays)
    raise RequestError(f"the rays were refused on the device but not on the host ({type(result).__name__})") from None


def run_count_hits(tracer, origins, directions, tmin, tmax, host: bool = False) -> np.ndarray:
    """int32 of the rays' leading shape: each ray's number of hits t in (tmin, tmax); on a device of
    the GPU class (but with host), or of rays given as pyopencl arrays, the rays checked and counted
    on the device (cast_device.py)."""
    if not host and (gpu_class(tracer.ctx.device) or _on_device(origins, directions)):
        try:
            return hit_counts_device(tracer, origins, directions, tmin, tmax)
        except RaysRefused as refused:
            _name_the_refused(tracer, refused, lambda *rays: run_count_hits(tracer, *rays, host=True))
    batch = RayBatch(tracer, origins, directions, tmin, tmax, ORDER_ALWAYS)
    return _counts(tracer, batch).reshape(batch.shape)


def count_from_points(tracer, points: np.ndarray, directions: np.ndarray, surface: dict,
                      host: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(counts int32, on uint8, signed int32) of rays from checked points (N, 3) along directions
    (N, 3): each one's number of hits t > 0, whether that count's parity is the point's inside (0;
    3 undecided, 2 not known: kernels/allhits.cl, PYCLRAY_AOV_SURFACE), and its meshes' crossings
    signed (+1 out, -1 in) and summed; surface: that test's arguments (the closest-point query's leaves, their slabs, refs and world entries:
    closest.py); on a device of the GPU class (but with host) checked and counted on the device
    (cast_device.py)."""
    if not host and gpu_class(tracer.ctx.device):
        try:
            return hit_counts_device(tracer, points, directions, None, None, surface)
        except RaysRefused as refused:
            _name_the_refused(tracer, refused, lambda o, d, tmin, tmax: count_from_points(tracer, o, d, surface, host=True))
    batch = RayBatch(tracer, points, directions, None, None, ORDER_ALWAYS)
    counts = np.zeros(batch.count, np.int32)
    on = np.zeros(batch.count, np.uint8)
    signed = np.zeros(batch.count, np.int32)
    if batch.count:
        variant = Variant("count_hits", tracer.prepared.types, ("surface",), tracer.precision, pairs=batch.pairs)
        _run(tracer.ctx, variant, batch, surface, {"hit_counts": counts, "surface_out": on, "surface_signed_out": signed})
    return counts, on, signed


# all_hits' rows per ray in its one pass: a ray with more hits is cast again with room for all of them
CAPACITY = 8


def _stored(tracer, batch: RayBatch, capacity: int):
    """(counts, t, kinds, entries, subs): each ray's count and its first `capacity` hits in its rows
    (ray r's from r * capacity on)."""
    n = batch.count
    counts = np.zeros(n, np.int32)
    t = np.empty(n * capacity, np.float64)
    kinds, entries, subs = (np.empty(n * capacity, np.int32) for _ in range(3))
    if n:
        variant = Variant("all_hits", tracer.prepared.types, (), tracer.precision, pairs=batch.pairs)
        _run(tracer.ctx, variant, batch, {"hit_capacity": np.int32(capacity)},
             {"hit_counts": counts, "hit_t": t, "hit_kind": kinds, "hit_k": entries, "hit_sub": subs})
    return counts, t, kinds, entries, subs


def _gather(counts: np.ndarray, capacity: int) -> np.ndarray:
    """The rows of each ray's hits (ray r's first counts[r] rows from r * capacity on), in ray order."""
    starts = np.repeat(np.arange(len(counts), dtype=np.int64) * capacity, counts)
    within = np.arange(int(counts.sum()), dtype=np.int64) - np.repeat(np.cumsum(counts) - counts, counts)
    return starts + within


def run_all_hits(tracer, origins, directions, tmin, tmax, aovs, host: bool = False) -> Frame:
    """Every hit t in (tmin, tmax) of each ray, nearest first: offsets (int64, N + 1), ray (int64 per
    hit) and the aovs asked for (HIT_AOVS), one row per hit. One pass with room for CAPACITY hits a
    ray, and a second over the rays that have more, with room for the most of them; on a device of
    the GPU class (but with host), or of rays given as pyopencl arrays, the rays checked and both
    passes' rows put in place on the device (cast_device.py: all_hits_device), the rest here as below."""
    if not host and (gpu_class(tracer.ctx.device) or _on_device(origins, directions)):
        try:
            return _hit_frame(tracer, *all_hits_device(tracer, origins, directions, tmin, tmax, CAPACITY), aovs)
        except RaysRefused as refused:
            _name_the_refused(tracer, refused, lambda *rays: run_all_hits(tracer, *rays, ("depth",), host=True))
    batch = RayBatch(tracer, origins, directions, tmin, tmax, ORDER_ALWAYS)
    counts, t, kinds, entries, subs = _stored(tracer, batch, CAPACITY)
    rows = _gather(np.minimum(counts, CAPACITY), CAPACITY)
    over = np.flatnonzero(counts > CAPACITY)
    parts = [np.asarray(x)[rows] for x in (t, kinds, entries, subs)]
    if len(over):  # those rays again, alone, with room for all their hits (the same hits)
        again = RayBatch(tracer, batch.origins[over] if len(batch.origins) > 1 else batch.origins[0], batch.directions[over],
                         batch.tmin[over] if len(batch.tmin) > 1 else batch.tmin,
                         batch.tmax[over] if len(batch.tmax) > 1 else batch.tmax, ORDER_ALWAYS)
        capacity = int(counts[over].max())
        more = _stored(tracer, again, capacity)
        more_rows = _gather(more[0], capacity)
        # each ray's rows in ray order: the first pass's where it had room, the second's elsewhere
        owner = np.concatenate([np.repeat(np.flatnonzero(counts <= CAPACITY), counts[counts <= CAPACITY]),
                                np.repeat(over, more[0])])
        order = np.argsort(owner, kind="stable")
        parts = [np.concatenate([p[np.repeat(counts <= CAPACITY, np.minimum(counts, CAPACITY))], np.asarray(m)[more_rows]])[order]
                 for p, m in zip(parts, more[1:])]
    return _hit_frame(tracer, batch, counts, *parts, aovs)


def _hit_frame(tracer, batch, counts, t, kinds, entries, subs, aovs) -> Frame:
    """all_hits' Frame of each ray's hits (counts) in ray order, nearest first (t, kinds, entries,
    subs: the kernel's), of the batch's rays (its count, block lanes and positions)."""
    ctx, precision = tracer.ctx, tracer.precision
    offsets = np.zeros(batch.count + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    total = int(offsets[-1])
    rays = np.repeat(np.arange(batch.count, dtype=np.int64), counts)
    out = {"offsets": offsets, "ray": rays}
    ids, primitives = _identify(tracer, batch, kinds, entries, subs)
    tied = (t[1:] == t[:-1]) & (rays[1:] == rays[:-1])
    if tied.any():  # hits at exactly the same distance (the kernel's order: by kind and entry): by id, primitive
        order = np.lexsort((primitives, ids, t, rays))
        t, ids, primitives = t[order], ids[order], primitives[order]
    for name in aovs:
        if name == "depth":
            out[name] = t.astype(REAL[precision])
        elif name == "id":
            out[name] = ids
        elif name == "primitive":
            out[name] = primitives
        elif name == "label":
            out[name] = label_of(tracer, ids)
        elif name == "position":
            out[name] = batch.positions(rays, t).astype(REAL[precision]) if total else TABLE[name].empty((0,), precision)
        elif name in ("normal", "barycentric"):
            out[name] = _on_surface(tracer, name, batch.positions(rays, t) if total else np.zeros((0, 3)), ids,
                                    primitives).astype(REAL[precision])
    return Frame(out, precision=precision, device=ctx.device.name.strip())


def _on_surface(tracer, name: str, points, ids, primitives) -> np.ndarray:
    """Each hit's normal or barycentrics, in float64 from its hit point (the point at its distance)
    and its primitive, by its shape's hit_normals or hit_barycentrics (a triangle's normal has the
    bits cast's has; an analytic shape's is its outward normal at the point)."""
    out = np.zeros((len(ids), 3 if name == "normal" else 2))
    shapes = tracer.shapes
    for index in np.unique(ids):
        rows = np.flatnonzero(ids == index)
        shape = shapes[index]
        method = shape.hit_normals if name == "normal" else shape.hit_barycentrics
        out[rows] = method(points[rows], primitives[rows])
    return out


def _identify(tracer, batch: RayBatch, kinds, entries, subs) -> tuple[np.ndarray, np.ndarray]:
    """(ids, primitives) of hits given as the kernel's (kind, entry, triangle): a kind is 1 + the
    type's place in the program's types; an entry the index in its type's arrays, or for a type cast
    tests in blocks its block's place times 8 plus its lane (RayBatch.block_lanes); a mesh instance's
    triangle is its index in its mesh."""
    prepared = tracer.prepared
    ids = np.full(len(kinds), -1, np.int32)
    primitives = np.zeros(len(kinds), np.int32)
    for index, name in enumerate(prepared.types):
        rows = np.flatnonzero(kinds == index + 1)
        if not len(rows):
            continue
        kind = prepared.kinds[name]
        entry = entries[rows].astype(np.int64)
        if name in batch.block_lanes:
            places, first, kept = batch.block_lanes[name]
            block = np.searchsorted(places, entry >> 3)
            entry = kept[first[block] + (entry & 7)]
        ids[rows] = np.asarray(kind.ids)[entry]
        primitives[rows] = subs[rows] if kind.shared else np.asarray(kind.primitives)[entry]
    return ids, primitives
