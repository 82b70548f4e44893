"""Cast arbitrary rays through a scene's shapes: the nearest hit of each (cast) or whether any
(occluded), each ray traced on its own from its float64 origin and direction."""
from __future__ import annotations

import math

import numpy as np
import pyopencl as cl

from ...model.aovs import TABLE
from ...model.errors import DeviceError, RequestError
from ...model.layout import layout
from ...model.shapes.base import labels_of
from ...model.shapes.capabilities import capability
from ..launch.programs import Variant, kernel_for, lanes_for, pairs_for, ray_group
from ..launch.run import REAL, input_buffer, run_kernel
from ..launch.signatures import arguments, image_parameter, shared_arguments
from ..opencl.buffers import shares_host_memory
from ..opencl.device import gpu_class, has_fp64, launch, launch_kept
from ..scene.prepared import PreparedScene
from .requests import Frame


def _ray_array(name: str, value) -> np.ndarray:
    if type(value).__module__.startswith("pyopencl"):  # (cast, occluded and the hit queries take them: cast_device.py)
        raise RequestError(f"{name}: a pyopencl array is taken by cast, occluded, count_hits and all_hits only; pass a "
                           "numpy array here (the device array's .get())")
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise RequestError(f"{name}: expected an array of shape (..., 3) of numbers") from None
    if array.size == 0 and array.ndim == 1:  # an empty list: no rays
        array = array.reshape(0, 3)
    if array.ndim == 0 or array.shape[-1] != 3:
        raise RequestError(f"{name}: expected an array of shape (..., 3), got shape {array.shape}")
    return array


def _first_bad(name: str, bad: np.ndarray, rows: np.ndarray, what: str):
    if not bad.ndim or not bad.size:  # one shared origin and no rays: the origin itself
        raise RequestError(f"{name}: {what}: {rows}")
    index = np.unravel_index(int(np.argmax(bad)), bad.shape)
    where = "row " + (str(index[0]) if len(index) == 1 else str(tuple(int(i) for i in index)))
    raise RequestError(f"{name}: {where} {what}: {rows[index]}")


def _distances(name: str, value, shape: tuple, default: float, good, expected: str) -> np.ndarray:
    """tmin or tmax as float64, (1,) for one number (None: default), else flattened from the rays'
    leading shape; a value that is not good is a RequestError naming its index."""
    if value is None:
        return np.full(1, default)
    if type(value) is float or type(value) is int:  # one Python number (cast's tmin=0.0): no numpy call to check it
        if not good(value):
            raise RequestError(f"{name}: expected {expected}, got {float(value)}")
        return np.array([value], np.float64)
    if type(value).__module__.startswith("pyopencl"):
        raise RequestError(f"{name}: expected a number or a numpy array (pyopencl arrays are taken for origins and "
                           "directions only)")
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise RequestError(f"{name}: expected a number or an array of numbers") from None
    if array.ndim == 0:
        if not good(array):
            raise RequestError(f"{name}: expected {expected}, got {float(array)}")
        return array.reshape(1)
    try:
        array = np.broadcast_to(array, shape)
    except ValueError:
        raise RequestError(f"{name}: expected one number or the shape {shape} of the rays, got {array.shape}") from None
    bad = ~good(array)
    if bad.any():
        index = np.unravel_index(int(np.argmax(bad)), bad.shape)
        where = str(index[0]) if len(index) == 1 else str(tuple(int(i) for i in index))
        raise RequestError(f"{name}: expected {expected}, got {array[index]} at row {where}")
    return np.ascontiguousarray(array).reshape(-1)


def _cast_rays(origins, directions, tmax, codes: bool = True, tmin=None, near=None):
    """(origins (M, 3), directions (N, 3), tmin, tmax, leading shape, extent): float64 arrays of the rays as
    given, flattened, checked; M is N, or 1 for one origin shared by every ray; tmin and tmax (1,) for
    one number, else (N,); extent: the origins'
    (lo, hi) and the rays' direction codes (None unless codes: a batch that is not ordered) where a
    large batch's compiled scan found them (cast_order.scan_codes), else None. The kernel normalizes the
    directions (scaled by a power of two near their largest component first, so that neither a tiny
    nor a huge finite direction under- or overflows in the length). Each check is one pass over the arrays; the row
    of a failure is looked for only then. near: (anchor, bound): a small batch is first checked in one
    fused pass (_fine_and_near), its extent then NEAR where it passes; else it is checked as above."""
    directions = _ray_array("directions", directions)
    shape = directions.shape[:-1]
    origins = _ray_array("origins", origins)
    if origins.shape != directions.shape and origins.shape != (3,):
        raise RequestError(
            f"origins: expected shape {directions.shape} like directions, or (3,) for one origin, got {origins.shape}"
        )
    extent = None
    if directions.size // 3 >= COHERENT_FROM:  # one compiled pass: the checks below, the origins' box, the codes
        from .ray_order import scan_codes

        fine, lo, hi, direction_codes = scan_codes(origins.reshape(-1, 3), directions.reshape(-1, 3), codes)
        extent = (lo, hi, direction_codes) if fine else None
    elif near is not None and directions.size and _fine_and_near(origins, directions, *near):
        extent = NEAR
    if extent is None:  # numpy's checks (and where one fails, its row)
        for name, array in (("directions", directions), ("origins", origins)):
            if not np.isfinite(array).all():
                rows = array if array.shape == directions.shape else array[None]  # a shared origin: row 0, even with no rays
                _first_bad(name, ~np.isfinite(rows).all(axis=-1), rows, "is not finite")
        # column by column: numpy's reductions over the short last axis of an (N, 3) array are slow
        flat = directions.reshape(-1, 3)
        if ((flat[:, 0] == 0) & (flat[:, 1] == 0) & (flat[:, 2] == 0)).any():
            _first_bad("directions", ~directions.any(axis=-1), directions, "has zero length")
    tmax = _distances("tmax", tmax, shape, np.inf, lambda v: v > 0, "numbers > 0 (inf for no limit)")
    tmin = _distances("tmin", tmin, shape, 0.0, lambda v: (v >= 0) & (v < np.inf), "finite numbers >= 0")
    return origins.reshape(-1, 3), directions.reshape(-1, 3), tmin, tmax, shape, extent


FEW_RAYS = 16  # _fine_and_near's batches checked as Python's floats

# _cast_rays' extent of a small batch found fine with every origin within the bound of the scene's anchor
NEAR = "near"


def _fine_and_near(origins: np.ndarray, directions: np.ndarray, anchor: np.ndarray, bound: float) -> bool:
    """Whether every coordinate is finite, no direction is zero and every origin lies within bound of
    anchor on each axis, in a few numpy passes without temporaries of the rays' size but one (the
    separate checks and the origins' box took 14 numpy passes): a direction's largest magnitude is > 0 and finite
    exactly for a fine one (np.maximum keeps a NaN), and the origins' smallest and largest coordinates
    bound their distances from the anchor on every axis (NaN where one is NaN: refused here, then
    named by the separate checks). A few rays are checked as Python's floats (numpy's calls cost more
    than their arithmetic there), each by the same rules."""
    if directions.size <= 3 * FEW_RAYS:
        a0, a1, a2 = anchor.tolist()
        for x, y, z in directions.reshape(-1, 3).tolist():
            if not 0 < abs(x) + abs(y) + abs(z) < math.inf:  # (a sum of huge magnitudes: inf, refused here)
                return False
        for x, y, z in origins.reshape(-1, 3).tolist():
            if not (abs(x - a0) <= bound and abs(y - a1) <= bound and abs(z - a2) <= bound):
                return False
        return True
    flat = np.abs(directions).reshape(-1, 3)
    largest = np.maximum(flat[:, 0], flat[:, 1])
    np.maximum(largest, flat[:, 2], out=largest)
    if not (largest.min() > 0 and largest.max() < np.inf):
        return False
    lo, hi = float(origins.min()), float(origins.max())  # Python's floats: an overflow is inf, never a warning
    return hi - float(anchor.min()) <= bound and float(anchor.max()) - lo <= bound


# Rays are cast in the order of a 15-bit Morton code of their origins and directions when there are
# at least this many (pyclray.engine.queries.ray_order): neighbouring work-items then walk the same
# nodes and shapes, which stay in cache (docs/benchmarks.md, "Why the engine does what it does":
# COHERENT_FROM). Each ray is traced on its own, so the order changes no bit.
COHERENT_FROM = 4096

# ... on a CPU device, only where the scene's cast data (its tree, anchors and entries) outgrow this
# share of the device's last-level cache (CL_DEVICE_GLOBAL_MEM_CACHE_SIZE: 32 MiB of L3 here). Within
# it any ray finds its nodes and shapes in the cache, and the order's cost (the host's sort, the
# kernel's rows read and results written through it at scattered places) is more than it saves.
# (docs/benchmarks.md, "Cast's ray order by scene size").
# A GPU on the CPU's host path ($PYCLRAY_GPU_CLASS=0) orders every large batch: its work-items run in
# lock-step groups, where rays that part ways wait for each other. A device of the GPU class orders
# none: its host does nothing per ray (cast and occluded: cast_device.py; the hit queries' batches too).
ORDER_CACHE_SHARE = 0.25


def _orders(ctx, scene_bytes: int) -> bool:
    """Whether the scene's batches of COHERENT_FROM rays or more are cast in the coherent order on
    this device (ORDER_CACHE_SHARE)."""
    if not ctx.device.type & cl.device_type.CPU:
        return True
    return scene_bytes > ORDER_CACHE_SHARE * ctx.device.global_mem_cache_size


NO_ORDER = np.zeros(1, np.int32)  # (a batch cast in its own order: the kernel reads none)

# cast's bound on the distances of origins from the scene's anchor, per precision: RayBatch
_BOUNDS = {precision: float(np.sqrt(np.finfo(real).max) / 4) for precision, real in REAL.items()}

# The rays one work-item traces, one after the other, their setups done together (kernels/rays.h's
# CAST_GROUP, which the program's source takes from programs.ray_group), and the work-items of a
# work-group: 128 rays, so that the device's threads share a batch evenly (left to PoCL, 12,500
# work-items made 5 work-groups for 2 threads); the global size is rounded up to whole work-groups,
# whose items past the rays do nothing. Where the pair nodes are traversed (a GPU) one ray per
# work-item, 128 work-items a work-group (ray_group(True)).
CAST_GROUP, CAST_WORK_GROUP = ray_group(False)


def _columns_extent(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) per axis of (N, 3) points, column by column (numpy's reductions of an (N, 3) array
    along its first axis are slow)."""
    return (np.array([points[:, i].min() for i in range(3)]), np.array([points[:, i].max() for i in range(3)]))


# -- the inputs of casts: each bounded entry in its own space (its anchor), the BVH around the scene's anchor
def cast_inputs(prepared: PreparedScene) -> tuple[dict, np.ndarray, float, int, dict, "PairNodes | None"]:
    """(arguments by name, anchor, size, bytes, block lanes, pair nodes): the BVH around the scene's anchor (its root box's
    centre), its refs and the entries' anchors, and per packed kind its buffer (each bounded entry
    relative to its own anchor, in leaf order) and count; bytes: those buffers' sizes together.
    They depend on the shapes only, never on the rays: a scene handle makes them at its first cast
    and keeps them until its shapes change. block lanes: per cast_blocks type, which entry each
    block's lane is (engine/queries/cast_blocks.py: regroup), for the hit queries. pair nodes: the
    tree for one ray per work-item (ray_arguments), made from the wide nodes when first asked."""
    ctx, precision, shape_types = prepared.ctx, prepared.precision, prepared.types
    tree = prepared.bvh
    anchor = 0.5 * (tree.tree.lo[0] + tree.tree.hi[0]) if tree.types else np.zeros(3)
    # the largest side of the bounded shapes' box (0 without any): the coarsest cells of the rays' order
    size = float(np.max(tree.tree.hi[0] - tree.tree.lo[0])) if tree.types else 0.0
    # w: 1 where the scene reaches beyond 2^100 from its anchor, too far for the float box tests
    # (kernels/rays.h: its rays then test every bounded shape)
    large = bool(tree.types) and not np.all(np.abs(np.stack([tree.tree.lo[0], tree.tree.hi[0]]) - anchor) < 2.0**100)
    anchor = np.append(anchor, 1.0 if large else 0.0)
    args = {"scene_anchor": anchor.astype(np.float64).view(cl.cltypes.double4)[0]}
    # each type's world entries, read once (an indexed type's are packed anew at each read: Kind.world)
    worlds = {name: prepared.kinds[name].world for name in shape_types}
    blocks, block_lanes = {}, {}
    pairs = None
    if tree.types:
        nodes = tree.nodes(anchor[:3])
        if any(capability(prepared.kinds[name].cls, "cast_blocks") for name in tree.types):  # a leaf's triangles of a mesh at once
            from .cast_blocks import regroup

            refs, anchors, per_type = regroup(tree, shape_types, prepared.kinds, worlds, nodes)
            blocks = {name: v for name, v in per_type.items() if capability(prepared.kinds[name].cls, "cast_blocks")}
            entry_anchors = {name: v for name, v in per_type.items() if name not in blocks}
        else:
            anchors, refs = tree.anchors(), tree.refs(shape_types)
            for name in tree.types:  # a type may anchor its entries otherwise
                kind = prepared.kinds[name]
                own = kind.cls.cast_anchors(worlds[name], kind.ids)
                if own is not None:
                    anchors[: len(tree.leaf_type)][tree.leaf_type == tree.types.index(name)] = own
        anchors = np.ascontiguousarray(anchors)
        args.update(nodes=input_buffer(ctx, nodes), refs=input_buffer(ctx, refs), anchors=input_buffer(ctx, anchors),
                    box_anchors=input_buffer(ctx, _box_anchors(anchors, anchor)), root_box=_root_box(nodes))
        pairs = PairNodes(prepared, nodes, anchor[:3])
    identity = np.eye(3)
    for name in shape_types:
        kind = prepared.kinds[name]
        if name in blocks:  # its blocks in place of its world entries, and no packed entries (kernels/mesh.cl)
            data, count, lanes = blocks[name]
            block_lanes[name] = lanes
            args.update({f"{name}s": input_buffer(ctx, np.zeros(1, layout(kind.cls.struct, precision).dtype)),
                         f"{name}_worlds": input_buffer(ctx, data), **shared_arguments(name, kind.shared),
                         f"n_{name}s": np.int32(count)})
            continue
        if kind.cls.bounded and blocks:
            origin = entry_anchors[name][:, :3]
        elif kind.cls.bounded:
            origin = anchors[: len(tree.leaf_type)][tree.leaf_type == tree.types.index(name), :3]
        else:
            origin = np.zeros(3)
        with np.errstate(over="ignore", invalid="ignore"):
            packed = kind.cls.rebase(worlds[name], origin, identity, precision, kind.ids, kind.primitives)
        if not all(np.isfinite(packed[field]).all() for field in packed.dtype.names if packed[field].dtype.kind == "f"):
            raise RequestError(f"the scene's {name}s are too large for {precision}: their packed values overflow")
        # the packed entries (their ids) and the float64 world entries the kernel rebases on each ray
        args.update({f"{name}s": input_buffer(ctx, packed if len(packed) else np.zeros(1, packed.dtype)),
                     f"{name}_worlds": input_buffer(ctx, np.ascontiguousarray(worlds[name])),
                     **shared_arguments(name, kind.shared), f"n_{name}s": np.int32(kind.count)})
    held = sum(a.size for a in args.values() if isinstance(a, cl.MemoryObjectHolder))
    return args, anchor, size, held, block_lanes, pairs


class PairNodes:
    """cast's pair nodes (one ray per work-item: engine/bvh/pairs.py), around cast's anchor, with the
    wide nodes' leaf codes (regroup's, where it rewrote them): made on the device when first asked
    (a CPU's casts traverse the wide nodes and never ask)."""

    def __init__(self, prepared: PreparedScene, wide: np.ndarray, origin: np.ndarray):
        self.prepared, self.wide, self.origin = prepared, wide, origin
        self._buffer = None

    def buffer(self):
        if self._buffer is None:
            with self.prepared.lock:
                if self._buffer is None:
                    with np.errstate(over="ignore", invalid="ignore"):
                        pairs = self.prepared.bvh.pair_nodes(self.origin, wide_child=self.wide["child"])
                    self._buffer = input_buffer(self.prepared.ctx, pairs)
        return self._buffer

    def arguments(self) -> dict:
        """The pair nodes' arguments in place of the wide tree's: the nodes, and the arrays the
        kinds' entries share as a program traversing pair nodes takes them (mesh instances' own
        trees: PreparedScene.shared_of)."""
        shared = {}
        for name, kind in self.prepared.kinds.items():
            if kind.shared:
                shared.update(shared_arguments(name, self.prepared.shared_of(kind, True)))
        return {"nodes": self.buffer(), **shared}


def ray_arguments(tracer, inputs) -> tuple[dict, bool]:
    """(the cast inputs' arguments, pairs): pairs where this device's lane width traverses the pair
    nodes (programs.pairs_for: a GPU's), which then take the wide nodes' place (Variant.pairs)."""
    pairs = pairs_for(lanes_for(tracer.ctx.device, tracer.precision))
    args = inputs[0]
    if pairs and inputs[5] is not None:
        args = {**args, **inputs[5].arguments()}
    return args, pairs


def _box_anchors(anchors: np.ndarray, scene_anchor: np.ndarray) -> np.ndarray:
    """(N, 4) float32: per leaf position its anchor from the scene's anchor (the float64 difference)
    and its radius, each rounded once to nearest, the bits the kernel's leaf pre-test had made of
    them itself (kernels/rays.h: cast_may_pass; an overflow is inf there too)."""
    out = np.empty((len(anchors), 4), np.float32)
    with np.errstate(over="ignore", invalid="ignore"):
        out[:, :3] = anchors[:, :3] - scene_anchor[:3]
        out[:, 3] = anchors[:, 3]
    return out


def _root_box(nodes: np.ndarray):
    """The box of the wide root's children (float8: lo xyz, hi xyz, 0, 0, around the scene's anchor),
    which a ray tests before the tree (kernels/rays.h: PYCLRAY_CAST_BOUNDED). An empty slot has
    lo > hi: the minima and maxima pass over it (all empty: lo > hi, a box no ray enters)."""
    root = nodes[0]
    lo = [root[f"lo_{axis}"].min() for axis in "xyz"]
    hi = [root[f"hi_{axis}"].max() for axis in "xyz"]
    return np.array(lo + hi + [0.0, 0.0], np.float32).view(cl.cltypes.float8)[0]


def check_cast_device(ctx) -> None:
    if not has_fp64(ctx.device):
        raise DeviceError(
            f"cast takes its rays' coordinate differences in float64 and needs the cl_khr_fp64 extension, which "
            f"{ctx.device.name.strip()} lacks; use another device"
        )


class RayBatch:
    """A batch of rays checked and set up for a kernel of kernels/rays.h on a scene handle: args (the
    kernel's arguments by name but for its results: engine/launch/signatures.py's RAYS and the
    scene's cast inputs), shape (the rays' leading shape), count, sizes (global, local). Batches of
    COHERENT_FROM rays or more are traced in a coherent order where _orders says so, or always with
    order_always."""

    def __init__(self, tracer, origins, directions, tmin, tmax, order_always: bool = False, kept=None):
        ctx, precision = tracer.ctx, tracer.precision
        inputs = tracer.cast_inputs()
        _, anchor, scene_size, scene_bytes = inputs[:4]
        self.block_lanes = inputs[4]
        args, self.pairs = ray_arguments(tracer, inputs)  # the tree: pair nodes (GPUs) or wide ones
        # the scan of a large batch makes its codes only where it is ordered (order_always: every large
        # batch, as the hit queries', whose rays traverse to their ends, want: engine/queries/hits.py)
        orders = (order_always or _orders(ctx, scene_bytes)) and not gpu_class(ctx.device)
        # the distances the kernel squares, from a shape's anchor, must stay below the square root of
        # the largest real (rays too far for the BVH's float32 box tests test every bounded shape)
        bound = _BOUNDS[precision]
        origins, directions, tmin, tmax, shape, extent = _cast_rays(origins, directions, tmax, codes=orders, tmin=tmin,
                                                                    near=(anchor[:3], bound))
        count = len(directions)
        ordered = orders and count >= COHERENT_FROM
        direction_codes = None
        if extent is NEAR:  # checked: every origin within bound
            reach = 0.0
        else:
            if extent is not None:
                lo, hi, direction_codes = extent
            else:
                lo, hi = _columns_extent(origins) if len(origins) else (anchor[:3], anchor[:3])
            with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused here, not a warning
                reach = np.maximum(np.abs(hi - anchor[:3]), np.abs(lo - anchor[:3])).max()
        if not reach <= bound:  # the row, looked for only now
            with np.errstate(over="ignore", invalid="ignore"):
                reach = np.abs(origins - anchor[:3]).max(axis=-1)
            row = int(np.argmax(~(reach <= bound)))
            raise RequestError(
                f"origins: row {row} ({origins[row]}) is too far from the scene's shapes for {precision} "
                "(their distances overflow)"
            )
        self.origins, self.directions, self.tmin, self.tmax = origins, directions, tmin, tmax
        self.shape, self.count = shape, count
        if count == 0:
            return
        if ordered:  # numba's code, imported for large batches only
            from .ray_order import coherent_order

            order = coherent_order(origins, directions, lo, hi, scene_size, direction_codes)
        else:
            order = NO_ORDER
        # the rays' buffers: new ones (on a CPU device the arrays' own memory), or the handle's kept
        # ones (kept: a small cast, run_cast's KEPT_BELOW), the rays copied into them (KeptBuffers.write),
        # one number (a tmin, a tmax, no order) a kept constant (KeptBuffers.constant)
        rays = {"order": order, "origins": origins, "directions": directions, "limits": tmax, "starts": tmin}
        if kept is None:
            buffers = {name: _ray_buffer(ctx, array) for name, array in rays.items()}
        else:
            buffers = {name: kept.constant(ctx, array) if len(array) == 1 and name != "origins" else
                       kept.write(ctx, name, array) for name, array in rays.items()}
        # the kernel's arguments by name (engine/launch/signatures.py: the rays), but for the results
        self.args = {"n_rays": np.int32(count), "ordered": np.int32(1 if ordered else 0),
                     "origin_stride": np.int32(1 if len(origins) > 1 else 0),
                     "limit_stride": np.int32(1 if len(tmax) > 1 else 0),
                     "start_stride": np.int32(1 if len(tmin) > 1 else 0), **buffers, **args}
        group, work_group = ray_group(self.pairs)  # a work-item per group of rays (kernels/rays.h: CAST_GROUP)
        groups = -(-count // group)
        self.sizes = ((-(-groups // work_group) * work_group,), (work_group,))

    def unit_directions(self) -> np.ndarray:
        """(N, 3) float64: each direction over its length, scaled first as the kernel scales it
        (kernels/rays.h: cast_directions4): by 2^-e for its largest magnitude m in [2^e, 2^(e+1)), from
        m's exponent bits, at least 2^-1022 and 2^1023 for a subnormal m (whose 2^-e overflows)."""
        d = self.directions
        field = 2046 - (np.abs(d).max(axis=1).view(np.int64) >> 52)  # the exponent bits of 2^-e
        scale = (np.maximum(field, 1) << 52).view(np.float64)[:, None]
        scaled = d * scale
        return scaled / np.sqrt((scaled * scaled).sum(axis=1))[:, None]

    def positions(self, rows: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(M, 3) float64: the points at distances t along rays rows (origin + t times the unit direction)."""
        origins = self.origins[rows] if len(self.origins) > 1 else np.broadcast_to(self.origins, (len(rows), 3))
        return origins + t[:, None] * self.unit_directions()[rows]


def run_cast(tracer, query: str, origins, directions, tmax, aovs, tmin=None):
    """The nearest hit of each ray ("cast": a Frame of the aovs) or whether any ("occluded": a bool
    array), on a scene handle (engine/tracer.py) whose request and device were checked, for rays
    given as host arrays (device arrays: engine/queries/cast_device.py)."""
    kept = tracer.ray_buffers
    if _ray_count(directions) < KEPT_BELOW or not shares_host_memory(tracer.ctx):
        with kept.lock:  # from the rays' writes to the results' reads
            return _run_cast(tracer, query, origins, directions, tmax, aovs, tmin, kept)
    return _run_cast(tracer, query, origins, directions, tmax, aovs, tmin, None)


def _ray_count(directions) -> int:
    """The number of rays directions holds, for choosing a path (exact for an array, else 0: a list
    is small enough for the kept buffers' path in any case a user writes by hand)."""
    size = getattr(directions, "size", None)
    return size // 3 if isinstance(size, int) else 0


# A cast of fewer rays than this (or any on a device whose buffers are not host memory) writes its rays
# into its handle's kept buffers and reads its results out of them (engine/opencl/buffers.py:
# KeptBuffers): a copy of its arrays each way, where a larger one's buffers are its arrays' own
# memory on a CPU device (no copy of 24 MB per million rays; docs/benchmarks.md, "The host path of a cast").
KEPT_BELOW = 1 << 16


def _run_cast(tracer, query, origins, directions, tmax, aovs, tmin, kept):
    ctx, precision = tracer.ctx, tracer.precision
    real = REAL[precision]
    batch = RayBatch(tracer, origins, directions, tmin, tmax, kept=kept)
    shape, count = batch.shape, batch.count
    if query == "occluded":
        if count == 0:
            return np.zeros(shape, bool)
        variant = Variant("occluded", tracer.prepared.types, (), precision, pairs=batch.pairs)
        out = np.empty(count, np.bool_)  # the kernel's chars 0 and 1: numpy's bools
        if kept is None:
            _run_into(ctx, variant, batch.sizes, batch.args, out)
        else:
            _run_kept(ctx, variant, batch, kept, {"occluded_out": out})
        return out.reshape(shape)
    # what the kernel makes (in the table's order): label comes from id, position from depth (on the host)
    needed = set(aovs) | ({"id"} if "label" in aovs else set()) | ({"depth"} if "position" in aovs else set())
    kernel_aovs = tuple(a for a in ("depth", "normal", "id", "primitive", "barycentric") if a in needed)
    if count == 0:
        results = {k: TABLE[k].empty((0,), precision) for k in kernel_aovs}
    else:
        variant = Variant("cast", tracer.prepared.types, kernel_aovs, precision, pairs=batch.pairs)
        if kept is None:
            results = run_kernel(ctx, variant, batch.args, batch.sizes[0], count, kernel_aovs, precision, (count,),
                                 tracer.outputs, local_size=batch.sizes[1])
        else:
            results = {k: TABLE[k].empty((count,), precision) for k in kernel_aovs}
            _run_kept(ctx, variant, batch, kept, {image_parameter(k): v for k, v in results.items()})
    if "primitive" in results:
        results["primitive"] = _block_primitives(tracer, batch, results["primitive"])
    out = {}
    for name in aovs:
        if name in results:
            out[name] = results[name]
        elif name == "label":
            out[name] = label_of(tracer, results["id"])
        elif name == "position":
            depth = results["depth"].astype(np.float64)
            hit = np.isfinite(depth)
            position = np.zeros((count, 3), real)
            rows = np.flatnonzero(hit)
            position[rows] = batch.positions(rows, depth[rows])
            out[name] = position
    out = {k: v.reshape(shape + v.shape[1:]) for k, v in out.items()}
    return Frame(out, precision=precision, device=ctx.device.name.strip())


def _block_primitives(tracer, batch, primitive: np.ndarray) -> np.ndarray:
    """The kernel's primitives with each block's key (-2 - key: kernels/cast.cl) turned into its
    triangle's index in its mesh (the block lanes' entries: RayBatch.block_lanes)."""
    keyed = primitive <= -2
    if not keyed.any():
        return primitive
    places, first, lane_primitives = _lane_primitives(tracer, batch.block_lanes)
    key = -2 - primitive[keyed].astype(np.int64)
    primitive = primitive.copy()
    primitive[keyed] = lane_primitives[first[np.searchsorted(places, key >> 3)] + (key & 7)]
    return primitive


def _lane_primitives(tracer, block_lanes: dict) -> tuple:
    """(places, first, primitives): the block lanes' tables (RayBatch.block_lanes) with each lane's
    entry as its triangle's primitive, made once per cast inputs (an indexed mesh makes its
    primitives anew at each read: 0.1 ms on 80,000 triangles), kept on the handle's kept buffers."""
    kept = tracer.ray_buffers
    cached = kept.lane_primitives
    if cached is None or cached[0] is not block_lanes:
        (name, (places, first, entries)), = block_lanes.items()  # one type is cast in blocks: meshes
        primitives = np.asarray(tracer.prepared.kinds[name].primitives)[entries]
        cached = kept.lane_primitives = (block_lanes, (places, first, primitives))
    return cached[1]


def _block_lanes_table(tracer, block_lanes: dict, queue) -> tuple:
    """(places, first, primitives) on the device: the block lanes' tables (RayBatch.block_lanes) with
    each lane's entry as its triangle's primitive, for cast_device's block_primitives; uploaded once
    per cast inputs (kept beside them on the handle's kept buffers)."""
    import pyopencl.array as cl_array

    kept = tracer.ray_buffers
    cached = getattr(kept, "block_tables", None)
    if cached is None or cached[0] is not block_lanes:
        places, first, primitives = _lane_primitives(tracer, block_lanes)
        tables = tuple(cl_array.to_device(queue, np.ascontiguousarray(a))
                       for a in (np.asarray(places, np.int64), np.asarray(first, np.int64), primitives.astype(np.int32)))
        cached = kept.block_tables = (block_lanes, tables)
    return cached[1]


def label_of(tracer, ids: np.ndarray) -> np.ndarray:
    """int32: each id's shape's label (-1 for a miss and for a shape without one)."""
    return np.append(labels_of(tracer.shapes), np.int32(-1))[ids]


def _ray_buffer(ctx, array: np.ndarray):
    """A read-only buffer of the rays' array: on a CPU device the array's own memory (USE_HOST_PTR:
    no copy of 2.4 MB per 100,000 rays; the array lives until the kernel is done, as the call waits
    for it), elsewhere a copy."""
    array = np.ascontiguousarray(array)
    if ctx.device.type & cl.device_type.CPU:
        return cl.Buffer(ctx.context, cl.mem_flags.READ_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=array)
    return input_buffer(ctx, array)


def _run_kept(ctx, variant, batch: RayBatch, kept, outputs: dict) -> None:
    """Run the kernel over the batch (its rays in the kept buffers) with kept buffers for its results
    (outputs: parameter name -> the array each is read back into, once, at the end), and wait."""
    buffers = {name: kept.get(ctx, name, out.nbytes)[0] for name, out in outputs.items()}
    done = launch_kept(ctx, kernel_for(ctx, variant), *batch.sizes, arguments(variant, {**batch.args, **buffers}),
                       kept.launches)
    if shares_host_memory(ctx):
        done.wait()  # then the results are in the kept arrays, each copied out
        for name, out in outputs.items():
            kept.read(ctx, name, out)
    else:  # the copies out enqueued behind the kernel, then one wait for all
        for name, out in outputs.items():
            kept.read(ctx, name, out)
        ctx.queue.finish()


def _run_into(ctx, variant, sizes, args: dict, out: np.ndarray) -> None:
    """Run the occluded kernel over sizes (global, local) with its arguments args (by name) and out as
    its result, and wait: on a CPU device it writes into out's own memory, then a map makes it current
    (as request.run_kernel does for the images)."""
    kernel = kernel_for(ctx, variant)
    if ctx.device.type & cl.device_type.CPU:
        buffer = cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=out)
        launch(ctx, kernel, *sizes, arguments(variant, {**args, "occluded_out": buffer}))
        mapped = cl.enqueue_map_buffer(ctx.queue, buffer, cl.map_flags.READ, 0, out.shape, out.dtype, is_blocking=True)[0]
        mapped.base.release()
        ctx.queue.finish()
    else:
        buffer = cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
        launch(ctx, kernel, *sizes, arguments(variant, {**args, "occluded_out": buffer}))
        cl.enqueue_copy(ctx.queue, out, buffer)
