"""Closest points, distances, signed distances and occupancy of points (kernels/closest.cl): for each
point the nearest point of any shape's surface, found through the scene's BVH pruned by the best
distance so far, in float64 from the point as given; and whether the point is inside a solid.

Inside means inside any solid: an analytic one (a sphere, a box, a capped cylinder, the half-space
behind a plane: its kernel file's <type>_inside), or a mesh by one of two rules (``sign``):
"parity", the exact count of one ray's crossings of each closed mesh (Mesh.closed; the count_hits
query's tie rule makes it exact for every ray), or "winding", the meshes' generalized winding number
>= 1/2 (Jacobson et al. 2013), summed hierarchically (Barill et al. 2018: engine/bvh/winding.py), which
also gives open, self-intersecting and multi-part meshes an inside. A point on a surface (distance
0) is inside.
"""
from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np
import pyopencl as cl

from ...model.errors import RequestError
from ...model.shapes import REGISTRY
from ..bvh.scene import primitives_bvh
from ..bvh.winding import winding_slots
from ..launch.programs import Variant, kernel_for, lanes_for, pairs_for
from ..launch.run import REAL, input_buffer
from ..launch.signatures import arguments
from ..opencl.device import gpu_class, launch
from .hits import count_from_points

SIGNS = ("parity", "winding")

# the nearest point's outputs (with "distance"), the kernel's names
CLOSEST_OUTPUTS = ("position", "normal", "id", "primitive", "barycentric")

# Points are visited in the order of a Morton code of their positions when there are at least this
# many: neighbouring work-items then walk the same nodes and triangles, which stay in cache. Each
# point is computed on its own, so the order changes no bit. A device of the GPU class
# (engine/opencl/device.py: gpu_class) takes no order, and its host makes no numba pass over the
# points (point_passes.py's are the CPU's): the parity rays' directions by numpy's column passes (the
# same directions), the parity grid's lookup by a device kernel (cast_device.py: grid_lookup_device),
# the parity rays counted through count_hits' device path (cast_device.py: HitRays).
COHERENT_FROM = 4096

# the direction of the parity rays: any direction is exact (count_hits' tie rule), so each point's
# ray goes toward the nearest face of its meshes' box (the shortest way out: fewer boxes and
# triangles on it; the rays of one face, ordered, are coherent), tilted off the axis by a little of
# a direction along no axis and no simple diagonal (a ray exactly along an axis meets a mesh's
# axis-aligned edges and faces edge-on, and the float box tests' infinite slopes cost far more)
PARITY_DIRECTION = np.array([0.5773502691896258, 0.6172133998483676, 0.5345224838248488])
PARITY_TILT = 1e-2
# per face of the box (-x, -y, -z, +x, +y, +z): its ray's direction
PARITY_FACES = np.concatenate([-np.eye(3), np.eye(3)]) + PARITY_TILT * PARITY_DIRECTION * (1 - np.concatenate([np.eye(3)] * 2))

WORK_GROUP = 64


def check_points(points, name: str = "points") -> tuple[np.ndarray, tuple]:
    """(points (N, 3) float64 C-contiguous, leading shape): the points as given (float32 widened
    exactly), checked: shape (..., 3), finite; a RequestError naming the argument and the first bad row."""
    try:
        array = np.asarray(points)
        if array.dtype.kind not in "fiub":
            raise TypeError
        array = array.astype(np.float64, copy=False)
    except (TypeError, ValueError, OverflowError):
        raise RequestError(f"{name}: expected an array of shape (..., 3) of numbers") from None
    if array.size == 0 and array.ndim == 1:  # an empty list: no points
        array = array.reshape(0, 3)
    if array.ndim == 0 or array.shape[-1] != 3:
        raise RequestError(f"{name}: expected an array of shape (..., 3), got shape {array.shape}")
    shape = array.shape[:-1]
    flat = np.ascontiguousarray(array.reshape(-1, 3))
    if not np.isfinite(flat).all():  # (the rows looked at only then: numpy's reductions over the short axis are slow)
        finite = np.isfinite(flat).all(axis=1)
        row = int(np.argmin(finite))
        index = np.unravel_index(row, shape)
        where = str(index[0]) if len(index) == 1 else str(tuple(int(i) for i in index))
        raise RequestError(f"{name}: row {where} is not finite: {flat[row]}")
    return flat, shape


def check_sign(sign) -> str:
    if not isinstance(sign, str) or sign not in SIGNS:
        raise RequestError(f"sign: expected one of {', '.join(map(repr, SIGNS))}, got {sign!r}")
    return sign


class ClosestInputs:
    """What the closest-point query needs of a scene, made at its first call and kept by the handle
    until its shapes change: per type its world entries (float64), ids and primitive indices in the
    BVH's leaf order and its refs, on the device; its nodes around the scene's anchor (the wide ones,
    or the pair nodes at a lane width of 1: one point per work-item) and the winding number's
    expansions when first asked for."""

    def __init__(self, prepared, shapes: tuple):
        ctx = self.ctx = prepared.ctx
        kinds = prepared.kinds
        if all(t in REGISTRY for t in prepared.types):  # the prepared scene's own BVH and entries
            self.types, self.bvh = prepared.types, prepared.bvh
            worlds = {t: kinds[t].world for t in self.types}
            ids = {t: kinds[t].ids for t in self.types}
            primitives = {t: kinds[t].primitives for t in self.types}
        else:  # shapes packed as another kind (meshes sharing arrays as instances): each shape's own entries
            self.types, self.bvh, worlds, ids, primitives = _own_entries(shapes)
        self.worlds = worlds
        tree = self.bvh
        self.anchor = 0.5 * (tree.tree.lo[0] + tree.tree.hi[0]) if tree.types else np.zeros(3)
        if not np.isfinite(self.anchor).all():
            self.anchor = np.zeros(3)
        self.args = {"scene_anchor": np.append(self.anchor, 0.0).view(cl.cltypes.double4)[0]}
        if tree.types:
            self.args.update(refs=input_buffer(ctx, tree.refs(self.types)))
        for t in self.types:
            world = worlds[t] if len(worlds[t]) else np.zeros(1, worlds[t].dtype)
            self.args.update({f"{t}_worlds": input_buffer(ctx, np.ascontiguousarray(world)),
                              f"{t}_ids": input_buffer(ctx, _int32(ids[t])),
                              f"{t}_primitives": input_buffer(ctx, _int32(primitives[t])),
                              f"n_{t}s": np.int32(len(worlds[t]))})
        self.nbytes = sum(a.size for a in self.args.values() if isinstance(a, cl.MemoryObjectHolder))
        self._winding = None
        self._nodes: dict = {}  # pairs (bool) -> the BVH's nodes on the device (see nodes)
        self._lock = threading.Lock()
        # occupancy's grid of a closed mesh (engine/queries/parity_grid.py) and the count kernel's
        # arguments of its surface test, where asked for
        self.parity_grid = self.surface_arguments = None

    def nodes(self, pairs: bool):
        """This query's BVH's nodes around its anchor on the device, made when first asked: the wide
        nodes, or with pairs (a lane width of 1) its pair nodes (engine/bvh/pairs.py: the binary
        tree's boxes, rounded as the wide nodes' are, and the same leaves). The BVH is the prepared
        scene's where the query shares it (no mesh instance among the shapes), else the tree of the
        shapes' own entries (_own_entries)."""
        with self._lock:
            if pairs not in self._nodes:
                with np.errstate(over="ignore", invalid="ignore"):
                    nodes = self.bvh.pair_nodes(self.anchor) if pairs else self.bvh.nodes(self.anchor)
                self._nodes[pairs] = input_buffer(self.ctx, nodes)
                self.nbytes += self._nodes[pairs].size
            return self._nodes[pairs]

    def winding(self):
        """The winding number's expansion per wide child slot (engine/bvh/winding.py), on the device."""
        if self._winding is None:
            tree = self.bvh
            count = len(tree.leaf_type)
            triangles = np.zeros((max(count, 1), 3, 3))
            for position, t in enumerate(tree.types):
                if REGISTRY[t].winding_number:
                    mine = tree.leaf_type == position
                    world = self.worlds[t][tree.leaf_index[mine]]
                    triangles[:count][mine] = np.stack([world[v][:, :3] for v in ("a", "b", "c")], axis=1)
            slots = winding_slots(tree.tree, tree.wide, triangles)
            self._winding = input_buffer(self.ctx, np.ascontiguousarray(slots))
            self.nbytes += self._winding.size
        return self._winding


def _int32(a) -> np.ndarray:
    a = np.ascontiguousarray(a, np.int32)
    return a if len(a) else np.zeros(1, np.int32)


def _own_entries(shapes: tuple):
    """(types, BVH, worlds, ids, primitives) of the shapes by their own types (REGISTRY), each
    bounded type's entries in leaf order."""
    by_type: dict = {}
    for index, shape in enumerate(shapes):
        by_type.setdefault(shape.type, ([], []))
        by_type[shape.type][0].append(shape)
        by_type[shape.type][1].append(index)
    types = tuple(t for t in REGISTRY if t in by_type)
    worlds, ids, primitives, bounds = {}, {}, {}, {}
    for t in types:
        cls = REGISTRY[t]
        mine, indices = by_type[t]
        ids[t], primitives[t] = cls.entries_of(mine, indices)
        worlds[t] = cls.pack_world(mine)
        if cls.bounded:
            with np.errstate(over="ignore", invalid="ignore"):
                bounds[t] = cls.bounds_of(worlds[t])
    with np.errstate(over="ignore", invalid="ignore"):
        bvh = primitives_bvh(bounds)
    for t, order in bvh.order.items():
        worlds[t], ids[t], primitives[t] = worlds[t][order], ids[t][order], primitives[t][order]
    return types, bvh, worlds, ids, primitives


def run_closest(tracer, points: np.ndarray, outputs: tuple, within: float = np.inf) -> dict:
    """The kernel's outputs for the checked points (N, 3): "distance" (float64, inf where no shape),
    with it CLOSEST_OUTPUTS, "inside" (uint8: an analytic solid's inside, or on a surface; with
    within=0 the distance search stops at any surface point at distance 0) and "winding" (float64)."""
    ctx, precision = tracer.ctx, tracer.precision
    inputs = tracer.closest_inputs()
    count = len(points)
    dtypes = {"distance": np.float64, "position": REAL[precision], "normal": REAL[precision], "id": np.int32,
              "primitive": np.int32, "barycentric": REAL[precision], "inside": np.uint8, "winding": np.float64}
    widths = {"position": 3, "normal": 3, "barycentric": 2}
    results = {k: np.empty((count, widths[k]) if k in widths else (count,), dtypes[k]) for k in outputs}
    if count == 0:
        return results
    if "winding" in outputs and not inputs.bvh.types:  # no bounded shape: no triangle
        results["winding"][:] = 0.0
        outputs = tuple(k for k in outputs if k != "winding")
        if not outputs:
            return results
    # through the pair nodes at a lane width of 1 (a GPU's: programs.pairs_for), but for the winding
    # number, whose expansions are the wide nodes' children's
    pairs = "winding" not in outputs and pairs_for(lanes_for(ctx.device, precision))
    variant = Variant("closest", inputs.types, tuple(outputs), precision, pairs=pairs)
    order = None
    if count >= COHERENT_FROM and not gpu_class(ctx.device):  # numba's code, imported for large batches only
        from .point_passes import coherent_order

        # the points gathered in that order, their results scattered back below: the kernel then
        # also writes its outputs in order (written through the order, neighbouring work-items'
        # rows were scattered: slower where each point's search is short, near and far from the surface)
        order = coherent_order(points)
        points = points[order]
    args = {"n_points": np.int32(count), "order": input_buffer(ctx, np.zeros(1, np.int32)), "ordered": np.int32(0),
            "points": input_buffer(ctx, points), "within": np.float64(within), **inputs.args}
    if inputs.bvh.types:
        args["nodes"] = inputs.nodes(variant.through_pairs())
    if "winding" in outputs:
        args["winding_slots"] = inputs.winding()
    flags = cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR
    cpu = bool(ctx.device.type & cl.device_type.CPU)
    buffers = {k: (cl.Buffer(ctx.context, flags, hostbuf=results[k]) if cpu
                   else cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY, results[k].nbytes)) for k in outputs}
    args.update({f"{k}_out": buffers[k] for k in outputs})
    kernel = kernel_for(ctx, variant)
    size = -(-count // WORK_GROUP) * WORK_GROUP
    launch(ctx, kernel, (size,), (WORK_GROUP,), arguments(variant, args))
    for k in outputs:
        if cpu:  # written in place: a map makes it current
            mapped = cl.enqueue_map_buffer(ctx.queue, buffers[k], cl.map_flags.READ, 0, results[k].shape,
                                           results[k].dtype, is_blocking=True)[0]
            mapped.base.release()
        else:
            cl.enqueue_copy(ctx.queue, results[k], buffers[k])
    ctx.queue.finish()
    if order is not None:  # each point's results at its place in the batch given
        for k in outputs:
            placed = np.empty_like(results[k])
            placed[order] = results[k]
            results[k] = placed
    return results


# -- the queries -----------------------------------------------------------------------------------
def closest_points(tracer, points) -> dict:
    """position, distance, id, primitive, barycentric, normal per point (see Tracer.closest_points)."""
    flat, shape = check_points(points)
    out = run_closest(tracer, flat, ("distance",) + CLOSEST_OUTPUTS)
    return {k: v.reshape(shape + v.shape[1:]) for k, v in out.items()}


def distance(tracer, points) -> np.ndarray:
    flat, shape = check_points(points)
    return run_closest(tracer, flat, ("distance",))["distance"].reshape(shape)


def signed_distance(tracer, points, sign: str = "parity") -> np.ndarray:
    sign = check_sign(sign)
    flat, shape = check_points(points)
    out = run_closest(tracer, flat, ("distance", "inside"))
    inside = _inside(tracer, flat, out, sign)
    d = out["distance"]
    return np.where(inside & (d > 0), -d, d).reshape(shape)


def occupancy(tracer, points, sign: str = "parity") -> np.ndarray:
    sign = check_sign(sign)
    flat, shape = check_points(points)
    inside, rest = np.zeros(len(flat), bool), slice(None)
    closed = tracer.mesh_handle(closed=True)
    alone = closed is not None and len(closed.shapes) == len(tracer.shapes)
    if alone:  # closed meshes alone
        # a large batch's points of the meshes' grid's empty cells and beyond it decided there first
        answers = _grid_answers(tracer, closed, flat, sign)
        if answers is not None:
            decided, inside = answers
            rest = np.flatnonzero(~decided)
        if sign == "parity" and len(closed.shapes) == 1 and _shares_boxes(closed):
            inside[rest] = _one_closed_mesh(closed, flat[rest])
            return inside.astype(np.uint8).reshape(shape)
    # the meshes' inside first (the costlier part); then, for the points no mesh holds, the analytic
    # solids and whether the point lies on a surface: only a surface point at distance 0 is looked
    # for (within = 0), a traversal of the boxes that hold the point
    points = flat[rest]
    found = _mesh_inside(tracer, points, sign)
    other = ~found
    if other.any():
        found[other] = run_closest(tracer, points[other], ("inside",), within=0.0)["inside"].astype(bool)
        claimed = np.flatnonzero(other)[found[other]]
        if alone and len(claimed):  # at float64's distance 0 of a closed mesh: on it exactly, or outside
            from .parity_exact import exact_on_surface

            nearest = run_closest(tracer, points[claimed], ("distance",) + CLOSEST_OUTPUTS)
            found[claimed] = exact_on_surface(tracer.shapes, points[claimed], nearest["id"], nearest["primitive"])
    inside[rest] = found
    return inside.astype(np.uint8).reshape(shape)


def _shares_boxes(closed) -> bool:
    """Whether the closest-point query of the handle traverses the BVH its rays do (the same wide
    nodes around the same anchor: closest.cl's and rays.h's box tests of the same float boxes)."""
    inputs = closed.closest_inputs()
    return inputs.bvh is closed.prepared.bvh and bool(np.all(inputs.anchor == closed.cast_inputs()[1][:3]))


def _one_closed_mesh(closed, points: np.ndarray) -> np.ndarray:
    """Inside by parity in a scene of one closed mesh (its handle; points checked), exactly: an odd
    count of the parity ray, or a point on the surface. The count's kernel also says where its
    parity may not be the point's inside (_banded_count): a crossing within rounding of the point,
    or a triangle within the band of the corners' rounding (by the closest-point query's test of
    the leaves whose boxes hold the point: kernels/allhits.cl, PYCLRAY_AOV_SURFACE), at distance 0
    included; those points are counted again in float64 (fp32), and the ones still undecided
    decided exactly on the host (parity_exact.py)."""
    directions = parity_directions(closed, points)
    counts, on, _ = _banded_count(closed, points, directions)
    found = (counts & 1).astype(bool)
    if closed.precision != "fp64":  # fp32's undecided points: first the same count in float64
        again = np.flatnonzero(on == UNDECIDED)
        if len(again):
            on[again] = 0
            found[again] = _one_closed_mesh(closed.mesh_handle(closed=True, precision="fp64"), points[again])
    # the points left undecided (a crossing within rounding of the point: kernels/mesh_blocks.cl;
    # a triangle within the band, or at float64's distance 0: on the surface, or a rounding off it),
    # decided exactly (parity_exact.py), first by the nearest triangle (a point on it is inside)
    exact = np.flatnonzero(on == UNDECIDED)
    if len(exact):
        from .parity_exact import exact_inside

        nearest = run_closest(closed, points[exact], ("distance",) + CLOSEST_OUTPUTS)["primitive"]
        found[exact] = exact_inside(closed.shapes[0], points[exact], directions[exact], nearest)
    return found


# the count kernel's surface output for a point whose parity it cannot decide: a crossing of its
# ray within rounding of the point (kernels/mesh_blocks.cl: MESH_BLOCK_DOUBT) or a triangle within
# surface_band of it (kernels/allhits.cl), decided exactly on the host (engine/queries/parity_exact.py)
UNDECIDED = 3


def _banded_count(closed, points: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(counts, on, signed) of the count kernel's surface variant from the points
    (kernels/allhits.cl): on is UNDECIDED where the count (and its signed sum) may not be the
    point's, else 0 (a point in more leaves' boxes than the kernel notes: by the closest-point
    query's distance against the band)."""
    surface = _surface_arguments(closed)
    counts, on, signed = count_from_points(closed, points, directions, surface)
    unknown = np.flatnonzero(on == 2)
    if len(unknown):
        d = run_closest(closed, points[unknown], ("distance",))["distance"]
        reach = float(surface["surface_band"]) + 2.0**-50 * np.abs(points[unknown]).sum(axis=1)
        on[unknown] = np.where(d <= reach, UNDECIDED, 0)
    return counts, on, signed


def _undecided(closed, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """The points (indices) whose parity rays along directions the hit queries may count wrongly: a
    crossing within rounding of the point, by the count kernel's band (its surface variant, whose
    block tests run the band: kernels/mesh_blocks.cl), for the paths that count by all_hits (several
    closed meshes, the signed crossings). A handle whose rays do not traverse the closest-point
    query's tree (meshes drawn as instances) has no band: none."""
    if not len(points) or not _shares_boxes(closed):
        return np.zeros(0, np.int64)
    undecided = np.flatnonzero(_banded_count(closed, points, directions)[1] == UNDECIDED)
    if closed.precision != "fp64" and len(undecided):  # fp32's narrowed by the same band in float64
        twin = closed.mesh_handle(closed=True, precision="fp64")
        undecided = undecided[_undecided(twin, points[undecided], directions[undecided])]
    return undecided


def _surface_arguments(closed) -> dict:
    """The count kernel's arguments of its surface test (kernels/allhits.cl: PYCLRAY_AOV_SURFACE):
    the closest-point query's refs and world entries, and per place of cast's refs where a leaf
    starts the query's code of that leaf and its slab (leaf_slabs: the test's pre-test) (the two programs' wide nodes are the same but for the
    leaves' codes, which cast renumbers: engine/queries/cast_blocks.py); made once per handle."""
    inputs = closed.closest_inputs()
    with closed.lock:
        if inputs.surface_arguments is None:
            ctx = closed.ctx
            nodes = inputs.bvh.nodes(inputs.anchor)
            cast_nodes = np.empty_like(nodes)
            cl.enqueue_copy(ctx.queue, cast_nodes, closed.cast_inputs()[0]["nodes"])
            ctx.queue.finish()
            leaf = nodes["child"] < 0
            places = (~cast_nodes["child"][leaf].astype(np.int64)) >> 3
            codes = np.zeros(int(places.max()) + 1 if len(places) else 1, np.int32)
            codes[places] = nodes["child"][leaf]
            slabs = np.zeros((len(codes), 5))
            slabs[places] = leaf_slabs(inputs, nodes["child"][leaf])
            inputs.nbytes += codes.nbytes + slabs.nbytes
            inputs.surface_arguments = {"surface_leaf_codes": input_buffer(ctx, codes), "surface_refs": inputs.args["refs"],
                                        "surface_slabs": input_buffer(ctx, slabs), "surface_band": surface_band(closed),
                                        **{f"{t}_surface_worlds": inputs.args[f"{t}_worlds"] for t in inputs.types}}
        return inputs.surface_arguments


# the unit roundoff of each precision's triangle test (kernels/mesh_blocks.cl: MESH_BAND_EPSILON)
EPSILON = {"fp32": 2.0**-24, "fp64": 2.0**-53}
# surface_band's factor: the count from a point runs on the triangles' corners rounded relative to
# it (by <= u |corner - p|) and their projections rounded (by <= about 6 u of the corners' size, in
# length): 16 u of the largest triangle's size bounds how far that moves the surface near the point
SURFACE_BAND_K = 16.0


def surface_band(closed) -> np.float64:
    """The distance (float64) from the closed meshes' surface (their handle) within which the count
    kernel's parity may be off by the rounding of the triangles' corners relative to the point:
    SURFACE_BAND_K unit roundoffs of the precision's triangle test times the largest coordinate
    extent of a triangle; such points are decided again (kernels/allhits.cl: PYCLRAY_AOV_SURFACE)."""
    largest = 0.0
    for mesh in closed.shapes:
        a, b, c = mesh.corners()
        if len(a):
            extent = np.maximum(np.maximum(a, b), c) - np.minimum(np.minimum(a, b), c)
            largest = max(largest, float(extent.max()))
    return np.float64(SURFACE_BAND_K * EPSILON[closed.precision] * largest)


# the slabs' margins (leaf_slabs): of the leaf's coordinates' size (the kernel adds the same of the
# point's: kernels/allhits.cl), far above float64's rounding of a dot product and of a sum of them;
# of the leaf's extent, far above the closest-point test's barycentrics' rounding on a triangle that
# is not a sliver (amplified by at most 1 / SLAB_SLIVER); the sliver bound: a triangle whose edges'
# cross product is below SLAB_SLIVER of their lengths' product keeps its leaf tested
SLAB_SIZE_MARGIN = 2.0**-40
SLAB_EXTENT_MARGIN = 2.0**-24
SLAB_SLIVER = 2.0**-19
SLAB_TINY = 1e-150


def leaf_slabs(inputs: ClosestInputs, codes: np.ndarray) -> np.ndarray:
    """(L, 5) float64 per leaf code of the closest-point query's tree: a unit direction n and the
    interval [lo, hi] that holds n . x for every point x of the leaf's triangles, widened by
    SLAB_SIZE_MARGIN of the leaf's coordinates' size and SLAB_EXTENT_MARGIN of its extent (both
    as sums of magnitudes); (0, 0, 0, -inf, inf) for a leaf with another shape, a sliver
    or a coordinate not finite (the surface test then tests it: kernels/allhits.cl).

    Why a point p beyond the slab by more than SLAB_SIZE_MARGIN of its own size (the kernel's test)
    lies on none of the leaf's triangles as the closest-point query sees it (mesh_closest's squared
    distance of 0): every point of a triangle lies within the slab (its corners do, the slab is
    convex), so p is farther than the margins from each triangle; mesh_closest's nearest point of a
    triangle that is not a sliver lies within a few float64 roundings of the leaf's size of the
    triangle (its barycentrics within rounding of [0, 1]), and its distance over the face from its
    unit normal, within rounding of the true one: neither is 0, nor underflows (SLAB_TINY)."""
    tree = inputs.bvh
    first = ((~codes.astype(np.int64)) >> 3)
    count = (~codes.astype(np.int64)) & 7
    positions = len(tree.leaf_type)
    triangles = np.full((max(positions, 1), 3, 3), np.nan)
    for position, t in enumerate(tree.types):
        if REGISTRY[t].winding_number:  # the types whose entries are triangles (their corners a, b, c)
            mine = np.flatnonzero(tree.leaf_type == position)
            world = inputs.worlds[t][tree.leaf_index[mine]]
            triangles[mine] = np.stack([world[v][:, :3] for v in ("a", "b", "c")], axis=1)
    out = np.zeros((len(codes), 5))
    out[:, 3], out[:, 4] = -np.inf, np.inf
    for begin in range(0, len(codes), SLAB_CHUNK):  # a chunk of leaves at a time: bounded memory
        part = slice(begin, begin + SLAB_CHUNK)
        out[part] = _chunk_slabs(triangles, first[part], count[part])
    return out


# leaves per pass of leaf_slabs (its arrays about 1 KB a leaf)
SLAB_CHUNK = 1 << 15


def _chunk_slabs(triangles: np.ndarray, first: np.ndarray, count: np.ndarray) -> np.ndarray:
    """leaf_slabs' rows of the leaves (first, count) over the triangles' corners per position."""
    slots = first[:, None] + np.arange(7)
    used = np.arange(7) < count[:, None]
    corners = triangles[np.where(used, np.minimum(slots, len(triangles) - 1), first[:, None])]  # (L, 7, 3, 3)
    ab, ac = corners[:, :, 1] - corners[:, :, 0], corners[:, :, 2] - corners[:, :, 0]
    cross = np.cross(ab, ac)
    with np.errstate(over="ignore", invalid="ignore"):
        area2 = np.einsum("lsk,lsk->ls", cross, cross)
        fat = area2 > SLAB_SLIVER**2 * np.einsum("lsk,lsk->ls", ab, ab) * np.einsum("lsk,lsk->ls", ac, ac)
        normal = np.where(used[:, :, None], cross, 0.0).sum(axis=1)
        length = np.sqrt(np.einsum("lk,lk->l", normal, normal))
        normal = normal / np.where(length > 0, length, 1.0)[:, None]
        along = np.einsum("lsck,lk->lsc", corners, normal)
        lo = np.where(used[:, :, None], along, np.inf).min(axis=(1, 2))
        hi = np.where(used[:, :, None], along, -np.inf).max(axis=(1, 2))
        size = np.where(used[:, :, None], np.abs(corners).sum(axis=3), 0.0).max(axis=(1, 2))
        extent = np.where(used[:, :, None], np.abs(corners - corners[:, :1, :1]).sum(axis=3), 0.0).max(axis=(1, 2))
        widen = SLAB_SIZE_MARGIN * size + SLAB_EXTENT_MARGIN * extent + SLAB_TINY
        good = (np.all(fat | ~used, axis=1) & (length > 0) & np.isfinite(lo) & np.isfinite(hi)
                & np.isfinite(widen) & np.all(np.isfinite(normal), axis=1))
    out = np.zeros((len(first), 5))
    out[:, 3], out[:, 4] = -np.inf, np.inf
    out[good, :3] = normal[good]
    out[good, 3], out[good, 4] = lo[good] - widen[good], hi[good] + widen[good]
    return out


def _parity_grid(tracer, closed, sign: str, fine: bool = False):
    """The grid of a scene of closed meshes alone (tracer; closed: the handle of those meshes,
    which keeps it with its closest-point inputs: engine/queries/parity_grid.py), made at its first
    call (its coarse level, and with fine its fine level too: made again where the kept grid has
    none), with its cells decided by the sign rule; None where the meshes have none. Each closed
    mesh's parity and winding number is constant on a region no triangle meets: so is whether some
    mesh holds a point, decided by the rule's own test of one point per region (_mesh_inside)."""
    inputs = closed.closest_inputs()
    with closed.lock:
        kept = inputs.parity_grid
        if kept is None or (fine and kept and not kept.refined):
            from .parity_grid import ParityGrid  # numba's code, for large batches only

            corners = [mesh.corners() for mesh in closed.shapes]
            grid = ParityGrid.of(tuple(np.concatenate(c) for c in zip(*corners)), refine=fine) or False
            inputs.nbytes += (grid.nbytes if grid else 0) - (kept.nbytes if kept else 0)  # counted with the handle's
            inputs.parity_grid = grid
        grid = inputs.parity_grid or None
        if grid is not None:  # the exact inside of points on no surface
            held = grid.nbytes
            grid.decide(sign, lambda points: _mesh_inside(tracer, points, sign))
            inputs.nbytes += grid.nbytes - held  # the sign's states
        return grid


# the parity grid's fine level is made at the first batch that leaves at least this share of its
# points (and COHERENT_FROM points or more) in coarse surface cells: a batch near the surface, not
# a uniform one (a uniform batch's points are mostly in empty coarse cells; the fine level's build
# is several times the coarse one's: docs/benchmarks.md, "two-level parity grid")
FINE_FROM = 1 / 8


def _grid_answers(tracer, closed, points: np.ndarray, sign: str):
    """(decided, inside) per point by the parity grid of a scene of closed meshes alone (closed:
    their handle; see _parity_grid), bool each, for a batch of COHERENT_FROM points or more (the
    grid's build pays off there); else None. The points the coarse level leaves are looked up again
    in the fine level, made for them where they are many (FINE_FROM). On a device of the GPU class
    the lookup is the device's (cast_device.py: grid_lookup_device, the same operations)."""
    grid = _parity_grid(tracer, closed, sign) if len(points) >= COHERENT_FROM else None
    if grid is None:
        return None
    decided, inside = _grid_lookup(tracer, grid, points, sign)
    left = len(decided) - int(np.count_nonzero(decided))
    if not grid.refined and left >= max(COHERENT_FROM, FINE_FROM * len(points)):
        grid = _parity_grid(tracer, closed, sign, fine=True)
        rest = np.flatnonzero(~decided)
        decided[rest], inside[rest] = _grid_lookup(tracer, grid, points[rest], sign)
    return decided, inside


def _grid_lookup(tracer, grid, points: np.ndarray, sign: str):
    """The grid's (decided, inside) of the points: the device's lookup on a device of the GPU class."""
    if gpu_class(tracer.ctx.device):
        from .cast_device import grid_lookup_device

        return grid_lookup_device(tracer, grid, points, sign)
    return grid.lookup(points, sign)


def winding_numbers(tracer, points: np.ndarray) -> np.ndarray:
    """The generalized winding number of all the scene's meshes at each point (float64): the open
    meshes' summed hierarchically (the kernel's expansions, within 1e-3), the closed meshes' exactly,
    as the signed count of one ray's crossings (a closed mesh's winding number is the number of times
    a ray from the point leaves it less the times it enters, for any ray: count_hits' tie rule counts
    each crossing once)."""
    total = np.zeros(len(points))
    if not len(points):
        return total
    open_meshes = tracer.mesh_handle(closed=False)
    if open_meshes is not None:
        total += run_closest(open_meshes, points, ("winding",))["winding"]
    closed = tracer.mesh_handle(closed=True)
    if closed is not None:
        total += _signed_crossings(closed, points)
    return total


def parity_directions(closed, points: np.ndarray) -> np.ndarray:
    """(N, 3): each point's parity ray's direction (PARITY_FACES), toward the nearest face of the
    box of the closed meshes' handle (its BVH's root)."""
    tree = closed.prepared.bvh.tree
    lo, hi = (tree.lo[0], tree.hi[0]) if len(tree.lo) else (np.zeros(3), np.zeros(3))
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        return np.broadcast_to(PARITY_DIRECTION, points.shape)
    if len(points) < COHERENT_FROM or gpu_class(closed.ctx.device):  # numpy's (a GPU's host: no numba pass)
        gaps = np.concatenate([points - lo, hi - points], axis=1)
        return PARITY_FACES[np.argmin(gaps, axis=1)]  # the first nearest face, as numba's
    from .point_passes import nearest_face_directions  # numba's code, for large batches only

    return nearest_face_directions(points, lo, hi, PARITY_FACES)


def _signed_crossings(closed, points: np.ndarray) -> np.ndarray:
    """Per point, the crossings of its parity ray out of its closed meshes less those into them: +1
    where the ray leaves through a triangle (its outward normal along the ray), -1 where it enters.
    Where the handle's rays traverse the closest-point query's tree, the count kernel's signed sum
    (its facing from the watertight test's det) with its band, the undecided points again in
    float64 (fp32) and then exactly (_banded_signed); else from all_hits, the sign from the float64
    normal, in exact arithmetic where that is within rounding of 0."""
    directions = parity_directions(closed, points)
    if len(points) and _shares_boxes(closed):
        return _banded_signed(closed, points, directions)
    one = len(closed.shapes) == 1  # then every hit's id is 0: not asked for
    hits = closed.all_hits(points, directions, aovs=("primitive",) if one else ("id", "primitive"))
    ray, primitive = (np.asarray(hits[k]).astype(np.int64) for k in ("ray", "primitive"))
    ids = np.zeros_like(ray) if one else np.asarray(hits["id"]).astype(np.int64)
    signs = np.zeros(len(ray))
    for index, mesh in enumerate(closed.shapes):
        mine = np.flatnonzero(ids == index) if not one else slice(None)
        if not len(ray[mine]):
            continue
        # the corners of the triangles hit alone (not the mesh's every triangle's)
        world, faces = mesh.world_vertices(), mesh.faces[primitive[mine]]
        a, b, c = world[faces[:, 0]], world[faces[:, 1]], world[faces[:, 2]]
        normal = np.cross(b - a, c - a)
        d = directions[ray[mine]]
        along = np.einsum("ij,ij->i", normal, d)
        doubt = np.abs(along) <= 1e-10 * np.einsum("ij,ij->i", np.abs(normal), np.abs(d))
        for i in np.flatnonzero(doubt):
            along[i] = _exact_along(a[i], b[i], c[i], d[i])
        signs[mine] = np.sign(along)
    return np.bincount(ray, weights=signs, minlength=len(points))


def _banded_signed(closed, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """The signed crossings of the points' rays (float64), exact: the count kernel's signed sum,
    its undecided points counted again in float64 (fp32) and the rest exactly on the host, per
    mesh (parity_exact.py; a point on a surface as 1: inside)."""
    _, on, signed = _banded_count(closed, points, directions)
    total = signed.astype(np.float64)
    undecided = np.flatnonzero(on == UNDECIDED)
    if len(undecided) and closed.precision != "fp64":
        twin = closed.mesh_handle(closed=True, precision="fp64")
        total[undecided] = _banded_signed(twin, points[undecided], directions[undecided])
    elif len(undecided):
        from .parity_exact import exact_crossings

        total[undecided] = 0.0
        on_surface = np.zeros(len(undecided), bool)
        for mesh in closed.shapes:
            _, signed_exact, on_mesh = exact_crossings(mesh, points[undecided], directions[undecided])
            total[undecided] += signed_exact
            on_surface |= on_mesh
        total[undecided[on_surface]] = np.maximum(total[undecided[on_surface]], 1.0)
    return total


def _exact_along(a, b, c, direction) -> float:
    """The sign of cross(b - a, c - a) . direction in exact rational arithmetic."""
    from fractions import Fraction

    a, b, c, d = ([Fraction(float(x)) for x in v] for v in (a, b, c, direction))
    e, f = [y - x for x, y in zip(a, b)], [y - x for x, y in zip(a, c)]
    n = (e[1] * f[2] - e[2] * f[1], e[2] * f[0] - e[0] * f[2], e[0] * f[1] - e[1] * f[0])
    value = n[0] * d[0] + n[1] * d[1] + n[2] * d[2]
    return float((value > 0) - (value < 0))


def _inside(tracer, points: np.ndarray, out: dict, sign: str) -> np.ndarray:
    """Inside any solid: the kernel's analytic solids and surface points (out["inside"]), and for
    the other points the meshes' inside (_mesh_inside); in a scene of closed meshes alone the
    points of a large batch in the parity grid's empty cells by the grid (the same answers as
    their rays: engine/queries/parity_grid.py)."""
    inside = out["inside"].astype(bool)
    rest = np.flatnonzero(~inside)
    closed = tracer.mesh_handle(closed=True)
    if len(rest) and closed is not None and len(closed.shapes) == len(tracer.shapes):
        answers = _grid_answers(tracer, closed, points[rest], sign)
        if answers is not None:
            decided, grid_inside = answers
            inside[rest[decided]] = grid_inside[decided]
            rest = rest[~decided]
    if len(rest):
        inside[rest] = _mesh_inside(tracer, points[rest], sign)
    return inside


def _mesh_inside(tracer, points: np.ndarray, sign: str) -> np.ndarray:
    """Inside a mesh: by the winding number (>= 1/2), or by each closed mesh's parity."""
    if sign == "winding":
        return winding_numbers(tracer, points) >= 0.5
    closed = tracer.mesh_handle(closed=True)
    if closed is None or not len(points):
        return np.zeros(len(points), bool)
    if len(closed.shapes) == 1 and _shares_boxes(closed):  # its count's band and surface test (exact)
        return _one_closed_mesh(closed, points)
    directions = parity_directions(closed, points)
    if len(closed.shapes) == 1:
        return (closed.count_hits(points, directions) & 1).astype(bool)
    # several closed meshes: each one's own parity, from the hits' ids
    hits = closed.all_hits(points, directions, aovs=("id",))
    ray, ids = np.asarray(hits["ray"]), np.asarray(hits["id"]).astype(np.int64)
    per = np.bincount(ray * len(closed.shapes) + ids, minlength=len(points) * len(closed.shapes))
    inside = (per.reshape(len(points), len(closed.shapes)) & 1).any(axis=1)
    undecided = _undecided(closed, points, directions)
    if len(undecided):  # each mesh's inside exactly
        from .parity_exact import exact_inside

        inside[undecided] = np.any([exact_inside(mesh, points[undecided], directions[undecided])
                                    for mesh in closed.shapes], axis=0)
    return inside


def meshes_scene(scene, closed: bool):
    """The scene with only its closed meshes (closed=True) or its open ones (a type deciding its
    inside by winding or parity, whose shape says whether it is closed), or None without any."""
    shapes = tuple(s for s in scene.shapes if type(s).winding_number and bool(s.closed) == closed)
    if not shapes:
        return None
    return replace(scene, shapes=shapes)

