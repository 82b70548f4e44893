"""The kernels' programs: the source of a variant (only the shape types, images and precision a
request needs), built once per device and cached in memory and on disk."""
from __future__ import annotations

import contextlib
import hashlib
import os
import re
import sys
import tempfile
import threading
import warnings
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import pyopencl as cl

from ...model.errors import BuildError, DeviceError
from ...model.cameras.perspective import CAMERA
from ...model.layout import c_header
from ...model.lights import STRUCTS as SHADING_STRUCTS
from ...model.shapes import KINDS as REGISTRY  # the packed kinds: the scene's types and mesh instances
from ..bvh.pairs import PAIR_NODE
from ..bvh.tree import NODE
from ..bvh.wide import WIDE_NODE
from ..bvh.winding import WINDING_BETA, WINDING_SLOT
from ..opencl.device import DeviceContext, is_pocl_cpu
from ..opencl.pocl_cpu import named_cpu
from .signatures import SIGNATURES, c_defines

# each query's kernel file (the kernel of that name is in it; its signature: engine/launch/signatures.py)
QUERY_FILES = {"render": "render.cl", "cast": "cast.cl", "occluded": "anyhit.cl", "count_hits": "allhits.cl",
               "all_hits": "allhits.cl", "closest": "closest.cl"}
# the queries of rays given in world coordinates, one at a time (kernels/rays.h)
RAY_QUERIES = ("cast", "occluded", "count_hits", "all_hits")
# the queries of every hit along a ray (kernels/allhits.cl: each type's <type>_hits, the mesh's tie rule)
HIT_QUERIES = ("count_hits", "all_hits")
# the images that need the nearest hit's shape, not only its distance (PYCLRAY_TRACK_ID)
WINNER_AOVS = ("normal", "id", "shaded", "primitive", "barycentric")

# Exact IEEE division and square root on every device (CPUs do this anyway; GPUs may not by default).
BUILD_OPTIONS = ("-cl-fp32-correctly-rounded-divide-sqrt",)

# counters of program builds, for tests and the curious
stats = {"compiled": 0, "from_disk": 0, "from_memory": 0}
_lock = threading.Lock()
_programs: dict = {}


# -- sources and programs --------------------------------------------------------------------
def kernel_dir():
    """The kernels/ folder: package data of pyclray.engine (in a checkout and in an installed wheel alike)."""
    folder = resources.files("pyclray.engine").joinpath("kernels")
    if folder.joinpath("render.cl").is_file():
        return folder
    raise FileNotFoundError("pyclray's kernels/ folder is missing from this installation")


def _read(name: str) -> str:
    return kernel_dir().joinpath(name).read_text(encoding="utf-8")


# Rays per work-item (vector lanes) the kernels are built for: the device's preferred vector width for
# its precision (GPUs: 1), in vectors of at most 256 bits (8 floats, 4 doubles). PoCL reports 16 floats
# and 8 doubles on an AVX-512 CPU, but its kernel compiler targets AVX2 there: it warns that 512-bit
# arguments change the ABI, and with PoCL 3.0 on this project's machines a kernel with 512-bit lanes
# was missing from the built program (CL_INVALID_KERNEL_NAME), then after the kernels' own square roots
# and reductions (kernels/lanes.h) LLVM's code generator aborted the process on it. $PYCLRAY_LANES
# overrides the choice within the same bound.
LANE_WIDTHS = (1, 2, 4, 8)
MAX_LANE_BITS = 256
_REAL_BITS = {"fp32": 32, "fp64": 64}


def lanes_for(device: cl.Device, precision: str) -> int:
    """The packet width of the kernels on this device at this precision."""
    bits = _REAL_BITS[precision]
    widths = [w for w in LANE_WIDTHS if w * bits <= MAX_LANE_BITS]
    value = os.environ.get("PYCLRAY_LANES", "").strip()
    if value:
        # a width of fp32's; fp64 takes the widest of its own up to it (8 -> 4): one setting serves
        # both precisions, as a handle of one precision may run the other's kernels (occupancy's fp32
        # count narrows its undecided points in fp64: engine/queries/closest.py). Every width gives
        # the same bits.
        allowed = [w for w in LANE_WIDTHS if w * _REAL_BITS["fp32"] <= MAX_LANE_BITS]
        widest_fp64 = max(w for w in LANE_WIDTHS if w * _REAL_BITS["fp64"] <= MAX_LANE_BITS)
        if not value.isdigit() or int(value) not in allowed:
            raise DeviceError(f"PYCLRAY_LANES: expected one of {', '.join(map(str, allowed))} "
                              f"(vectors of at most {MAX_LANE_BITS} bits; fp64 at most {widest_fp64}), got {value!r}")
        return max(w for w in widths if w <= int(value))
    preferred = device.preferred_vector_width_double if precision == "fp64" else device.preferred_vector_width_float
    if device.type & cl.device_type.CPU and int(preferred) <= 1:
        # a CPU runtime that vectorizes across work-items itself reports 1 (Intel's): the traversal's
        # branches defeat that, and explicit packets are much faster there (docs/benchmarks.md:
        # lanes_for). Every width gives the same bits.
        return max(widths)
    return max(w for w in widths if w <= max(int(preferred), 1))


def pairs_for(lanes: int) -> bool:
    """Whether the kernels of this lane width traverse the BVH's pair nodes, one ray per work-item
    (kernels/bvh_pairs.h: a GPU's lane width, 1), rather than the wide tree (a CPU's packets).
    $PYCLRAY_TRAVERSAL=wide keeps the wide tree at a lane width of 1 (for benchmarks: the same bits)."""
    value = os.environ.get("PYCLRAY_TRAVERSAL", "").strip()
    if value not in ("", "pairs", "wide"):
        raise DeviceError(f"PYCLRAY_TRAVERSAL: expected pairs or wide, got {value!r}")
    return lanes == 1 and value != "wide"


# The rays of the ray queries a work-item traces, one after the other (kernels/rays.h: CAST_GROUP, their
# directions set up four at once in vector registers), and the rays of a work-group: where the pair
# nodes are traversed (a GPU's lane width) one ray per work-item, the work-group's items a few warps
# of rays; else 8, in work-groups of 16 (engine/queries/cast.py).
RAY_GROUP = {False: 8, True: 1}
WORK_GROUP_RAYS = 128


def ray_group(pairs: bool) -> tuple[int, int]:
    """(rays per work-item, work-items per work-group) of a ray query's program (Variant.pairs)."""
    return RAY_GROUP[pairs], WORK_GROUP_RAYS // RAY_GROUP[pairs]


def packet_shape(lanes: int) -> tuple[int, int]:
    """(columns, rows) of pixels a render work-item's packet covers: two rows where the lanes
    allow (4x2 for 8 lanes, 2x2 for 4), else one. A square packet's rays stay closer together than a
    row's, so fewer BVH nodes and leaves meet some lane of it (docs/benchmarks.md, "Render's
    packets"); each lane's arithmetic is its pixel's, whatever the packet."""
    rows = 2 if lanes >= 4 else 1
    return lanes // rows, rows


@dataclass(frozen=True)
class Variant:
    """What selects a program: its query (kernel), shape types present, images asked for, precision, lanes."""

    query: str  # "render" (camera rays, a packet of pixels per work-item), "cast" (rays given, traced one
    # at a time, CAST_GROUP of them per work-item: engine/queries/cast.py), "occluded" (cast's any-hit query) or "rebase" (the scene's per-view pass into a
    # camera's space: kernels/rebase.cl)
    shape_types: tuple[str, ...]
    aovs: tuple[str, ...]
    precision: str
    lanes: int = 1
    shadows: bool = False  # with "shaded": cast shadow rays (none are compiled in without it)
    bvh: bool = False  # render: the bounded shapes through the BVH instead of tile lists (cast: always)
    smooth: tuple[str, ...] = ()  # with "shaded": the types with a shape lit by its own normals (a smooth mesh)
    # render: each shape rebased on the eye from its float64 world entry where it is tested (devices
    # with float64), instead of read from the per-view pass's buffers (pyclray.engine.scene.prepared)
    from_world: bool = False
    # render: the indexed types' entries (meshes) assembled from shared vertices and faces (devices with
    # float64, engine/scene/indexed.py), rebased or not
    indexed: bool = False
    # render: the camera's rays read from a table (a lens or a panorama: kernels/camera.h,
    # camera_table_rays) instead of the pinhole's image plane: "plane" (each ray's image-plane
    # coordinates: every ray ahead of the eye's plane) or "sphere" (unit directions); None: a pinhole
    camera_table: str | None = None
    # the BVH's pair nodes, one ray per work-item (pairs_for: a lane width of 1), instead of the wide
    # tree: a render through the BVH, the ray queries and the closest-point query's search (kernels/bvh_pairs.h)
    pairs: bool = False

    def bounded_types(self) -> tuple[str, ...]:
        return tuple(t for t in self.shape_types if REGISTRY[t].bounded)

    def through_pairs(self) -> bool:
        """Whether the program traverses the pair nodes (kernels/bvh_pairs.h): asked for, and a BVH
        to traverse (a render through it, a ray query or the closest-point query, over some bounded type)."""
        tree = (self.query == "render" and self.bvh) or self.query in RAY_QUERIES or self.query == "closest"
        return self.pairs and tree and bool(self.bounded_types())

    def defines(self) -> list[str]:
        """The #defines that select this variant in its query's kernel file (QUERY_FILES) and the
        headers and shape files it includes."""

        def listed(types):
            return " ".join(f"X({REGISTRY[t].c_type}, {t})" for t in types)

        bounded = self.bounded_types()
        lines = [f"#define PYCLRAY_SHAPES(X) {listed(self.shape_types)}", f"#define PYCLRAY_LANES {self.lanes}"]
        if self.query == "render":
            columns, rows = packet_shape(self.lanes)
            lines += [f"#define PYCLRAY_PACKET_W {columns}", f"#define PYCLRAY_PACKET_H {rows}"]
        lines.append(f"#define PYCLRAY_BOUNDED(X) {listed(bounded)}")
        # the types whose kernel file has <type>_barycentric (the barycentric image; 0, 0 for the others)
        lines.append(f"#define PYCLRAY_BARYCENTRIC_TYPES(X) {listed(t for t in self.shape_types if REGISTRY[t].barycentric)}")
        lines.append(f"#define PYCLRAY_UNBOUNDED(X) {listed(t for t in self.shape_types if t not in bounded)}")
        if bounded:
            lines.append("#define PYCLRAY_HAS_BOUNDED 1")
        lines += self._shape_calls()
        if self.bvh and self.query == "render":
            lines.append("#define PYCLRAY_BVH 1")
        if self.through_pairs():
            lines.append("#define PYCLRAY_PAIRS 1")
        lines += [f"#define PYCLRAY_AOV_{aov.upper()} 1" for aov in self.aovs]
        if any(aov in WINNER_AOVS for aov in self.aovs):  # the winner matters, not only its distance
            lines.append("#define PYCLRAY_TRACK_ID 1")
        if self.precision == "fp64":
            lines.append("#define PYCLRAY_FP64 1")
        if self.query in HIT_QUERIES:
            lines += ["#define PYCLRAY_ALL_HITS 1", "#define PYCLRAY_TIE_RULE 1"]
            if self.query == "all_hits":
                lines.append("#define PYCLRAY_STORE_HITS 1")
        if self.query in RAY_QUERIES:
            lines.append("#define PYCLRAY_CAST 1")
            lines.append(f"#define CAST_GROUP {ray_group(self.pairs)[0]}")  # rays per work-item (kernels/rays.h)
            # how cast tests each type's entries: one by one, or a leaf's in blocks (Shape.cast_blocks)
            lines += [f"#define PYCLRAY_CAST_MODE_{t} {'BLOCKS' if REGISTRY[t].cast_blocks else 'ENTRY'}"
                      for t in self.shape_types]
            # a work-item's rays traverse interleaved where leaves are blocks (a mesh's triangles:
            # kernels/cast.cl's cast_group, on PoCL's CPU device), one after the other elsewhere
            if self.query in ("cast",) + HIT_QUERIES and any(REGISTRY[t].cast_blocks for t in self.shape_types):
                lines.append("#define PYCLRAY_CAST_INTERLEAVE 1")
        if self.query == "rebase":
            lines.append("#define PYCLRAY_REBASE 1")
        if self.from_world and self.query == "render":
            lines.append("#define PYCLRAY_FROM_WORLD 1")
        if any(self.mode(t) == "INDEXED" for t in self.shape_types):
            lines.append("#define PYCLRAY_INDEXED 1")
        if self.query == "render" and len(bounded) == 1:  # its leaf position is its index: no refs read
            lines.append(f"#define PYCLRAY_ONE_BOUNDED KIND_{bounded[0]}")
        # where a render reads each type's shapes (kernels/entries.h): rebased where tested, or copied
        lines += [f"#define PYCLRAY_MODE_{t} {self.mode(t)}" for t in self.shape_types]
        if self.shadows and "shaded" in self.aovs:
            lines.append("#define PYCLRAY_SHADOWS 1")
        if self.camera_table and self.query == "render":
            lines.append("#define PYCLRAY_CAMERA_TABLE 1")
            if self.camera_table == "plane":
                lines.append("#define PYCLRAY_CAMERA_PLANE 1")
        if self.smooth and "shaded" in self.aovs:  # each type's shading normals: one more argument each
            lines.append("#define PYCLRAY_SMOOTH 1")
            lines.append(f"#define PYCLRAY_SMOOTH_TYPES(X) {listed(self.smooth)}")
        if self.query in SIGNATURES:  # the kernel's parameters (engine/launch/signatures.py)
            lines += c_defines(self)
        return lines

    def _shape_calls(self) -> list[str]:
        """For the usual types, how the kernel calls their functions (a type with shared arrays, whose
        functions take them too, defines PYCLRAY_HIT_<type> and the others in its kernel file: mesh
        instances)."""
        lines = []
        for t in self.shape_types:
            if not REGISTRY[t].shared:
                lines += [f"#define PYCLRAY_HIT_{t}(shape, ray, limit) {t}_hit(shape, ray)",
                          # a shadow ray (kernels/shading.h): self, the lanes whose winner is this entry
                          f"#define PYCLRAY_SHADOW_HIT_{t}(shape, ray, limit, self) {t}_hit(shape, ray)",
                          f"#define PYCLRAY_SELF_{t}(self) (self)",
                          f"#define PYCLRAY_NORMAL_{t}(shape, ray, basis, best, mine) {t}_normal(shape, ray, basis)",
                          f"#define PYCLRAY_PRIMITIVE_{t}(shape, k, best, mine) SPLAT_INT(PYCLRAY_PRIMITIVE_AT({t}, k))",
                          f"#define PYCLRAY_BARYCENTRIC_{t}(shape, ray, best, mine, u, v) {t}_barycentric(shape, ray, u, v)"]
                if self.query == "cast":  # the winner's primitive and barycentrics (kernels/cast.cl)
                    lines.append(f"#define PYCLRAY_CAST_PRIMITIVE_OF_{t}(shape, ray) ((shape)->primitive)")
                    lines.append(f"#define PYCLRAY_CAST_BARYCENTRIC_OF_{t}(shape, ray, u, v) "
                                 + (f"{t}_barycentric(shape, ray, u, v)" if REGISTRY[t].barycentric else "{}"))
                if self.query in HIT_QUERIES:  # every hit of an entry (kernels/allhits.cl)
                    lines.append(f"#define PYCLRAY_ALL_HITS_{t}(shape, ray, start, kind, k) "
                                 f"ALLHITS_TWO({t}, shape, ray, start, kind, k)")
        return lines

    def mode(self, t: str) -> str:
        """Where a render reads the shapes of type t (kernels/entries.h): rebased where tested from their
        world entries, assembled from shared vertices and faces, or the per-view pass's copy."""
        shape = REGISTRY[t]
        if self.indexed and self.query == "render" and shape.indexed:
            return "INDEXED"
        return "FROM_WORLD" if self.from_world and self.query == "render" and shape.tested_from_world else "COPIED"

    def source(self, inline_builtins: bool = False) -> str:
        """The whole program: only the shape types present and the images asked for.

        inline_builtins: on PoCL's CPU device, no call into PoCL's built-in library (which LLVM does
        not inline there): the square root, reductions and vector stores written with the compiler's
        own operations (kernels/lanes.h); the camera's and the shapes' functions always inlined
        (PoCL's inliner leaves some out, just above its threshold), and each kernel's per-work-item
        function kept out of the kernel, whose body PoCL copies three times (kernels/common.h).
        None of it changes a bit of the results (tests/test_speedups.py)."""
        shapes = [REGISTRY[t] for t in self.shape_types]
        if self.query == "rebase":
            return self._rebase_source(shapes, inline_builtins)
        if self.query == "closest":
            return self._closest_source(shapes, inline_builtins)
        defines = self.defines() + (["#define PYCLRAY_INLINE_BUILTINS 1"] if inline_builtins else [])
        parts = ["\n".join(["/* pyclray program variant */"] + defines)]
        parts += [_read("common.h")]
        if inline_builtins:  # popped where the query's kernels begin (PYCLRAY_KERNELS_BEGIN)
            parts.append("#pragma clang attribute push (__attribute__((always_inline)), apply_to = function)")
        shading = "shaded" in self.aovs
        cast = self.query in RAY_QUERIES  # rebases each shape on its ray's origin: the world entries too
        from_world = self.from_world and self.query == "render"
        pairs = self.through_pairs()
        structs = _unique(([] if cast else [CAMERA]) + [NODE, WIDE_NODE] + ([PAIR_NODE] if pairs else []) + [s.struct for s in shapes] + ([s.world for s in shapes] if cast or from_world else [])
                          + [x for s in shapes for x in s.kernel_structs]
                          + (list(SHADING_STRUCTS) if shading else [])
                          + ([REGISTRY[t].smooth_struct for t in self.smooth] if shading else []))
        parts += [_read("lanes.h"), c_header(structs, self.precision)]
        parts += [_read("shapes.h")]
        if cast:  # one ray at a time through the wide tree; mesh instances' own trees as packets of one
            parts += [_read(name) for name in ("bvh.h", "bvh_ray.h", "bvh_packet.h", "cast.h")]
            if pairs:  # its traversal over the pair nodes in place of the wide tree's
                parts.append(_read("bvh_pairs.h"))
        else:  # camera packets through the wide tree (with the BVH), shadow rays through the binary one
            parts += [_read(name) for name in ("camera.h", "bvh.h", "bvh_packet.h")]
            if pairs:  # one camera ray per work-item through the pair nodes
                parts.append(_read("bvh_pairs.h"))
            elif self.bvh and self.bounded_types():
                parts.append(_read("bvh_wide_packet.h"))
        if from_world:  # each rebased type's <type>_rebase (the per-view pass's, to the same bits), then its tests
            parts += [FROM_WORLD_BEGIN, _read("space.h"), "#define PYCLRAY_REBASE 1"]
            parts += [_read(name) for name in _kernel_files([s for s in shapes if s.tested_from_world])] + [FROM_WORLD_END]
        parts += [_read(name) for name in _kernel_files(shapes)]
        if self.query == "count_hits" and "surface" in self.aovs:  # the shapes' closest points too (allhits.cl)
            parts += [SURFACE_BEGIN, _read("closest.h")] + [_read(name) for name in _kernel_files(shapes)] + [SURFACE_END]
        if cast:
            parts.append(_read("rays.h"))
        else:
            if shading:  # materials, lights and shadows: only in the programs that shade
                parts.append(_read("shading.h"))
            parts += [_read(name) for name in ("entries.h", "nearest.h", "images.h")]
        parts.append(_read(QUERY_FILES[self.query]))  # pops the always_inline attribute before its kernels
        return "\n".join(parts)

    def _closest_source(self, shapes, inline_builtins: bool = False) -> str:
        """The closest-point query's program (kernels/closest.cl): float64 throughout, one point per
        work-item, each type's world entries and its kernel file's closest-point part alone
        (PYCLRAY_CLOSEST: no ray test is compiled in); the analytic solids' inside tests, the
        winding number's expansions only where asked (the "inside" and "winding" outputs)."""

        def listed(types):
            return " ".join(f"X({REGISTRY[t].c_type}, {t})" for t in types)

        bounded = self.bounded_types()
        defines = ["#pragma OPENCL EXTENSION cl_khr_fp64 : enable", "#define PYCLRAY_CLOSEST 1",
                   f"#define PYCLRAY_SOLID(X) {listed(t for t in bounded if REGISTRY[t].inside_test)}",
                   f"#define PYCLRAY_WINDING_TYPES(X) {listed(t for t in bounded if REGISTRY[t].winding_number)}",
                   f"#define WINDING_BETA {WINDING_BETA!r}"]
        if any(REGISTRY[t].inside_test for t in bounded):  # the traversal of the boxes holding a point
            defines.append("#define PYCLRAY_HAS_SOLID 1")
        defines += self.defines() + (["#define PYCLRAY_INLINE_BUILTINS 1"] if inline_builtins else [])
        parts = ["\n".join(["/* pyclray program variant */"] + defines), _read("common.h")]
        if inline_builtins:  # popped where the query's kernels begin (PYCLRAY_KERNELS_BEGIN)
            parts.append("#pragma clang attribute push (__attribute__((always_inline)), apply_to = function)")
        pairs = self.through_pairs()  # the search through the pair nodes (a lane width of 1) in place of the wide tree's
        structs = _unique([PAIR_NODE if pairs else WIDE_NODE] + [s.world for s in shapes]
                          + ([WINDING_SLOT] if "winding" in self.aovs else []))
        parts += [_read("lanes.h"), c_header(structs, self.precision), _read("shapes.h"), _read("bvh.h"), _read("closest.h")]
        if pairs:
            parts.append(_read("bvh_pairs.h"))
        parts += [_read(name) for name in _kernel_files(shapes)]
        parts.append(_read(QUERY_FILES[self.query]))
        return "\n".join(parts)

    def _rebase_source(self, shapes, inline_builtins: bool = False) -> str:
        """The per-view pass: each type's world struct and space struct, its <type>_rebase, and the
        kernels of kernels/rebase_kernels.cl. float64 throughout (the device needs cl_khr_fp64).
        inline_builtins (PoCL's CPU device), as for the render's program: the error-free product
        with the fused multiply-add (kernels/space.h: the same exact error as Dekker's) and every
        function inlined into the kernels, so that PoCL vectorizes the pass across work-items
        (the same bits, tests/test_views.py; docs/benchmarks.md: Variant._rebase_source)."""
        defines = self.defines() + (["#define PYCLRAY_INLINE_BUILTINS 1"] if inline_builtins else [])
        parts = ["\n".join(["/* pyclray program variant */", "#pragma OPENCL EXTENSION cl_khr_fp64 : enable"] + defines)]
        structs = _unique([NODE] + [s.struct for s in shapes] + [s.world for s in shapes]
                          + [x for s in shapes for x in s.kernel_structs])
        parts += [_read("common.h"), c_header(structs, self.precision), _read("rebase.cl")]
        if inline_builtins:
            parts.append("#pragma clang attribute push (__attribute__((always_inline)), apply_to = function)")
        parts += [_read("space.h")] + [_read(name) for name in _kernel_files(shapes)]
        if inline_builtins:
            parts.append("#pragma clang attribute pop")
        parts.append(_read("rebase_kernels.cl"))
        return "\n".join(parts)

    def options(self) -> list[str]:
        return list(BUILD_OPTIONS)


# A from-world render compiles each shape file twice: its <type>_rebase first (PYCLRAY_REBASE selects that
# part), then its tests. Both, and the rest of the program, without contraction of a * b + c into an
# fma, as the per-view pass (kernels/rebase.cl): a shape rebased where it is tested has the bits the
# pass gives it. Measured on PoCL: with contraction back on (DEFAULT or ON) after the framing code,
# the images differ from the pass's in a few pixels (tests/test_views.py: a device without float64).
FROM_WORLD_BEGIN = """#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF
#define PYCLRAY_REBASE_OUT"""
FROM_WORLD_END = "#undef PYCLRAY_REBASE"
# occupancy's count (kernels/allhits.cl: PYCLRAY_AOV_SURFACE) compiles each shape file twice too: its
# ray tests, then its closest-point part (<type>_closest, as in the closest-point query's program)
SURFACE_BEGIN = "#undef PYCLRAY_CAST\n#define PYCLRAY_CLOSEST 1"
SURFACE_END = "#undef PYCLRAY_CLOSEST\n#define PYCLRAY_CAST 1"


def _unique(items) -> list:
    """Each item once, in order of first appearance (a batch type shares its single shape's struct)."""
    return list(dict.fromkeys(items))


def _kernel_files(shapes) -> list[str]:
    """The kernel files of these shape types, each once, in order."""
    return _unique(name for shape in shapes for name in shape.kernel_files)


def cache_dir() -> Path | None:
    """$PYCLRAY_CACHE_DIR ("" or "off" disables the disk cache), else ~/.cache/pyclray."""
    value = os.environ.get("PYCLRAY_CACHE_DIR")
    if value is not None:
        return None if value.strip().lower() in ("", "off", "0", "none") else Path(value)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "pyclray"


def _disk_key(source: str, options: list[str], device: cl.Device) -> str:
    h = hashlib.sha256()
    for part in (
        source,
        "\0".join(options),
        device.platform.name,
        device.platform.version,
        device.name,
        device.version,
        device.driver_version,
        cl.VERSION_TEXT,
    ):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


@contextlib.contextmanager
def _quiet_compiler():
    """pyopencl warns (CompilerWarning) whenever a successful build left a log, as PoCL's often does
    (e.g. notes on vector arguments): a user can do nothing about it, and a warnings filter that
    makes warnings errors would turn it into an exception inside the build, after the driver made
    the program (PoCL then crashes at its release). A failed build still raises with its log.
    PoCL's clang also prints its count ("4 warnings generated.") straight to the process's stderr
    (file descriptor 2): that goes to a temporary file for the build's length, and whatever else
    was printed there meanwhile (another thread's lines) is passed on afterwards."""
    with warnings.catch_warnings(), _stderr_without_compiler_counts():
        warnings.simplefilter("ignore", cl.CompilerWarning)
        yield


# clang's summary line, the one thing the compiler prints itself on a successful build
_COMPILER_COUNT = re.compile(rb"\d+ (warning|error)s? generated\.")


@contextlib.contextmanager
def _stderr_without_compiler_counts():
    """File descriptor 2 into a temporary file while the block runs (the C compiler writes there
    directly, past Python's sys.stderr), then back; the captured bytes less clang's counts are
    written to the real stderr."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no stderr to guard (a closed descriptor 2)
        yield
        return
    with _stderr_lock, tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            captured.seek(0)
            lines = captured.read().splitlines(keepends=True)
            rest = b"".join(line for line in lines if not _COMPILER_COUNT.fullmatch(line.rstrip(b"\r\n")))
            if rest:
                os.write(2, rest)


_stderr_lock = threading.Lock()


def _build(ctx: DeviceContext, variant: Variant) -> cl.Program:
    source, options = variant.source(inline_builtins=is_pocl_cpu(ctx.device)), variant.options()
    cpu = named_cpu(ctx.device)
    if cpu is not None:  # PoCL compiles for a CPU pyclray named (engine/opencl/pocl_cpu.py): a key of its own
        source = f"/* pyclray: PoCL's CPU named {cpu} */\n{source}"
    folder = cache_dir()
    path = folder / f"{_disk_key(source, options, ctx.device)}.bin" if folder else None
    if path is not None and path.is_file():
        try:
            with _quiet_compiler():
                program = cl.Program(ctx.context, [ctx.device], [path.read_bytes()]).build(options=options)
            stats["from_disk"] += 1
            return program
        except (cl.Error, OSError):
            pass  # a stale or foreign binary: build from source below
    try:
        with _quiet_compiler():
            program = cl.Program(ctx.context, source).build(options=options, devices=[ctx.device], cache_dir=False)
    except cl.RuntimeError as error:
        raise BuildError(f"the OpenCL compiler rejected pyclray's kernel for {variant}:\n{error}") from None
    stats["compiled"] += 1
    if path is not None:
        try:
            binary = program.get_info(cl.program_info.BINARIES)[0]
            path.parent.mkdir(parents=True, exist_ok=True)
            handle, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
            with os.fdopen(handle, "wb") as out:
                out.write(binary)
            os.replace(tmp, path)
        except OSError:
            pass  # an unwritable cache only costs time
    return program


def kernel_for(ctx: DeviceContext, variant: Variant) -> cl.Kernel:
    """The kernel of this variant on this device: built once, cached in memory and on disk."""
    key = (ctx.device.int_ptr, variant)
    with _lock:
        kernel = _programs.get(key)
        if kernel is not None:
            stats["from_memory"] += 1
            return kernel
        kernel = _programs[key] = cl.Kernel(_build(ctx, variant), variant.query)
        return kernel


def kernels_for(ctx: DeviceContext, variant: Variant) -> dict:
    """Every kernel of this variant's program by name (the per-view pass has one per shape type):
    built once, cached in memory and on disk."""
    key = (ctx.device.int_ptr, variant, "all")
    with _lock:
        kernels = _programs.get(key)
        if kernels is not None:
            stats["from_memory"] += 1
            return kernels
        program = _build(ctx, variant)
        kernels = _programs[key] = {kernel.function_name: kernel for kernel in program.all_kernels()}
        return kernels


def clear() -> None:
    """Forget the kernels built in this process (the disk cache keeps their programs): the next
    kernel_for of each variant loads or builds its program again, as a new process's first render."""
    with _lock:
        _programs.clear()
