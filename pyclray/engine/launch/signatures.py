"""Each kernel's signature, declared once (as pyclray.model.layout declares each struct once).

A query's kernel (render, cast, occluded: one kernel file each, programs.QUERY_FILES) takes the
parameters listed here, in this order, each with its OpenCL C type and the conditions under which a
program variant has it (the shape types present and where a render reads them, the images asked for,
shadows, the BVH or tile lists). Both sides of a launch come from the one list:

- c_defines(variant): the C parameter list a program's source declares its kernel and work-item
  functions with (PYCLRAY_PARAMETERS) and the arguments those functions are called with
  (PYCLRAY_ARGUMENTS);
- arguments(variant, values): pyopencl's argument list, in that order, from a mapping name -> value;
  a name missing from the mapping, or one the variant's kernel does not take, is an error at once.

A parameter of a per-type group names the type through templates: {type} its name, {Type} its
struct (Shape.c_type), {World} its world struct, {Smooth} its shading normals' element; a type's
shared arrays (Shape.shared) are named {type}_{array}.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, Mapping

from ...model.shapes import KINDS


# -- conditions: each takes the variant and, in a per-type group, the type's name (None elsewhere) --
def _bounded(variant, _type=None) -> bool:
    """Some bounded type is present: the BVH's buffers are passed (cast and occluded always traverse it)."""
    return bool(variant.bounded_types())


def _through_bvh(variant, _type=None) -> bool:
    """A render through the BVH (every type's shapes counted: the unbounded ones are each tested)."""
    return variant.bvh


def _tiles(variant, _type=None) -> bool:
    """A render through tile lists (pyclray/engine/bvh/tiles.py), not the BVH."""
    return not variant.bvh


def _shadows(variant, _type=None) -> bool:
    """Shadow rays: the shaded image of a scene that casts shadows."""
    return variant.shadows and "shaded" in variant.aovs


def _wide(variant, _type=None) -> bool:
    """The BVH's wide nodes (a CPU's packets, cast's rays on a CPU), not its pair nodes."""
    return not variant.through_pairs()


def _pairs(variant, _type=None) -> bool:
    """The BVH's pair nodes: one ray per work-item (kernels/bvh_pairs.h: GPUs)."""
    return variant.through_pairs()


def _from_world(variant, _type=None) -> bool:
    """A render that rebases its shapes on the eye where it tests them (kernels/entries.h)."""
    return variant.from_world


def _camera_table(variant, _type=None) -> bool:
    """A render whose camera's rays are a table of directions (kernels/camera.h: camera_table_rays)."""
    return bool(variant.camera_table)


def _asked(aov: str) -> Callable:
    """The condition: the image aov is asked for."""
    return lambda variant, _type=None: aov in variant.aovs


def _mode(mode: str) -> Callable:
    """The condition, per type: a render reads the type's entries so (kernels/entries.h)."""
    return lambda variant, type_: variant.mode(type_) == mode


@dataclass(frozen=True)
class Parameter:
    """A kernel parameter: its name and OpenCL C type, present where every condition in `when` holds."""

    name: str
    c_type: str
    when: tuple = ()

    def present(self, variant, type_=None) -> bool:
        return all(condition(variant, type_) for condition in self.when)


@dataclass(frozen=True)
class SharedArrays:
    """A type's shared arrays (Shape.shared: mesh instances' triangles and BVHs), {type}_{array} each;
    where the program traverses pair nodes, a tree of BvhNode is its pair nodes (PreparedScene.shared_of)."""

    def resolve(self, type_: str, variant) -> list[tuple[str, str]]:
        pairs = variant.through_pairs()
        return [(f"__global const {'PairNode' if pairs and c_type == 'BvhNode' else c_type}*", f"{type_}_{array}")
                for array, c_type in KINDS[type_].shared]


@dataclass(frozen=True)
class EachType:
    """A group of parameters repeated for each of the variant's types that `types` picks, in order
    (by default every shape type present, the order of PYCLRAY_SHAPES)."""

    parameters: tuple
    types: Callable | None = None

    def of(self, variant) -> tuple[str, ...]:
        return variant.shape_types if self.types is None else self.types(variant)


def _smooth_types(variant) -> tuple[str, ...]:
    """The types lit by their own shading normals (a smooth mesh), in a program that shades."""
    return variant.smooth if "shaded" in variant.aovs else ()


def shared_arguments(type_: str, arrays) -> dict:
    """A type's shared arrays (in Shape.shared's order) by parameter name."""
    return {f"{type_}_{array}": value for (array, _), value in zip(KINDS[type_].shared, arrays, strict=True)}


def image_parameter(aov: str) -> str:
    """The parameter of an image's buffer (its AOV's name)."""
    return f"{aov}_out"


def _image(aov: str, c_type: str) -> Parameter:
    return Parameter(image_parameter(aov), c_type, (_asked(aov),))


_FROM_WORLD, _COPIED, _INDEXED = _mode("FROM_WORLD"), _mode("COPIED"), _mode("INDEXED")

RENDER = (
    Parameter("camera", "__global const Camera*"),
    # a lens's or a panorama's rays: per packet, the lanes' coordinates and in-field flags (kernels/camera.h)
    Parameter("camera_directions", "__global const real*", (_camera_table,)),
    # the window (col0, row0, cols, rows) and the tiles: 1 << tile_shift pixels square, tiles_x a row
    Parameter("col0", "const int"),
    Parameter("row0", "const int"),
    Parameter("cols", "const int"),
    Parameter("rows", "const int"),
    Parameter("tile_shift", "const int"),
    Parameter("tiles_x", "const int"),
    # a from-world render's eye space, float64: its origin and axes (kernels/entries.h)
    Parameter("space_origin", "const double4", (_from_world,)),
    Parameter("space_u", "const double4", (_from_world,)),
    Parameter("space_v", "const double4", (_from_world,)),
    Parameter("space_w", "const double4", (_from_world,)),
    # the wide BVH (camera packets: kernels/bvh_wide_packet.h), the binary one of the same boxes for
    # shadow rays (kernels/shading.h), or for one ray per work-item the pair nodes for both
    # (kernels/bvh_pairs.h), the leaves' refs
    Parameter("wide_nodes", "__global const WideNode*", (_through_bvh, _bounded, _wide)),
    Parameter("pair_nodes", "__global const PairNode*", (_through_bvh, _bounded, _pairs)),
    Parameter("nodes", "__global const BvhNode*", (_through_bvh, _bounded, _shadows, _wide)),
    Parameter("refs", "__global const int*", (_through_bvh, _bounded)),
    EachType((
        # its entries, where the render reads them (kernels/entries.h)
        Parameter("{type}_worlds", "__global const {World}*", (_FROM_WORLD,)),
        Parameter("{type}_ids", "__global const int*", (_FROM_WORLD,)),
        Parameter("{type}_primitives", "__global const int*", (_FROM_WORLD,)),
        Parameter("{type}s", "__global const {Type}*", (_COPIED,)),
        Parameter("{type}_faces", "__global const int4*", (_INDEXED,)),
        Parameter("{type}_vertices", "__global const real4*", (_INDEXED,)),
        Parameter("{type}_world_vertices", "__global const double4*", (_INDEXED,)),
        Parameter("{type}_ids", "__global const int*", (_INDEXED,)),
        SharedArrays(),
        # how many: through the BVH, and for shadow rays, which test every shape of the type
        Parameter("n_{type}s", "const int", (_through_bvh,)),
        # through tile lists: each tile's shapes, {type}_tile_list[{type}_tile_start[tile] ..
        # {type}_tile_start[tile + 1]] (pyclray/engine/bvh/tiles.py)
        Parameter("{type}_tile_start", "__global const int*", (_tiles,)),
        Parameter("{type}_tile_list", "__global const int*", (_tiles,)),
        Parameter("n_{type}s", "const int", (_tiles, _shadows)),
    )),
    # the images asked for (kernels/images.h), the position's eye as a float64 sum of two reals
    _image("depth", "__global real*"),
    _image("normal", "__global real*"),
    _image("id", "__global int*"),
    _image("zdepth", "__global real*"),
    Parameter("eye_high", "const real4", (_asked("position"),)),
    Parameter("eye_low", "const real4", (_asked("position"),)),
    _image("position", "__global real*"),
    # the shaded image's materials, lights in the camera's space, ambient, background and the smooth
    # types' shading normals (kernels/shading.h)
    Parameter("materials", "__global const Material*", (_asked("shaded"),)),
    Parameter("lights", "__global const Light*", (_asked("shaded"),)),
    Parameter("n_lights", "const int", (_asked("shaded"),)),
    Parameter("ambient", "const real4", (_asked("shaded"),)),
    Parameter("background", "const real4", (_asked("shaded"),)),
    EachType((Parameter("{type}_smooth", "__global const {Smooth}*"),), _smooth_types),
    _image("shaded", "__global real*"),
    _image("primitive", "__global int*"),
    _image("barycentric", "__global real*"),
)

# cast's and occluded's rays (kernels/rays.h): origins (3 doubles a ray, or one origin for every ray
# where origin_stride is 0), directions, limits (one for every ray where limit_stride is 0), the order
# they are traced in where ordered is 1, and the scene's anchor (w 1: too large for the box tests);
# the wide BVH around that anchor, its refs, per leaf position its shape's anchor and bounding radius
# (float64, and from the scene's anchor rounded to float: box_anchors) and the box of the root's
# children; per type its packed entries (ids), its float64 world entries, its shared arrays and count
RAYS = (
    Parameter("n_rays", "const int"),
    Parameter("order", "__global const int*"),
    Parameter("ordered", "const int"),
    Parameter("origins", "__global const double*"),
    Parameter("origin_stride", "const int"),
    Parameter("directions", "__global const double*"),
    Parameter("limits", "__global const double*"),
    Parameter("limit_stride", "const int"),
    Parameter("starts", "__global const double*"),  # tmin: hits beyond it (one for every ray where start_stride is 0)
    Parameter("start_stride", "const int"),
    Parameter("scene_anchor", "const double4"),
    Parameter("nodes", "__global const WideNode*", (_bounded, _wide)),
    Parameter("nodes", "__global const PairNode*", (_bounded, _pairs)),  # one ray per work-item (GPUs)
    Parameter("refs", "__global const int*", (_bounded,)),
    Parameter("anchors", "__global const double4*", (_bounded,)),
    Parameter("box_anchors", "__global const float4*", (_bounded,)),
    Parameter("root_box", "const float8", (_bounded,)),
    EachType((
        Parameter("{type}s", "__global const {Type}*"),
        Parameter("{type}_worlds", "__global const {World}*"),
        SharedArrays(),
        Parameter("n_{type}s", "const int"),
    )),
)

CAST = (
    *RAYS,
    _image("depth", "__global real*"),
    _image("normal", "__global real*"),
    _image("id", "__global int*"),
    _image("primitive", "__global int*"),
    _image("barycentric", "__global real*"),
)

OCCLUDED = (*RAYS, Parameter("occluded_out", "__global char*"))

# the closest-point query (kernels/closest.cl): the points (3 doubles each, in the order given, read
# in order where ordered is 1), the squared distance a surface point must be within (inf: the
# nearest; 0: only whether the point lies on a surface), the wide BVH (or its pair nodes) around the
# scene's anchor and its refs, per type its float64 world entries, ids, primitive indices and count; the winding
# number's expansions per wide child slot; the outputs asked for (distance alone, or with the
# nearest point's position, normal, id, primitive and barycentrics; inside an analytic solid; the
# meshes' winding number)
CLOSEST = (
    Parameter("n_points", "const int"),
    Parameter("order", "__global const int*"),
    Parameter("ordered", "const int"),
    Parameter("points", "__global const double*"),
    Parameter("within", "const double"),
    Parameter("scene_anchor", "const double4"),
    Parameter("nodes", "__global const WideNode*", (_bounded, _wide)),
    Parameter("nodes", "__global const PairNode*", (_bounded, _pairs)),  # one point per work-item (GPUs)
    Parameter("refs", "__global const int*", (_bounded,)),
    EachType((
        Parameter("{type}_worlds", "__global const {World}*"),
        Parameter("{type}_ids", "__global const int*"),
        Parameter("{type}_primitives", "__global const int*"),
        Parameter("n_{type}s", "const int"),
    )),
    Parameter("winding_slots", "__global const WindingSlot*", (_asked("winding"),)),
    Parameter("distance_out", "__global double*", (_asked("distance"),)),
    _image("position", "__global real*"),
    _image("normal", "__global real*"),
    _image("id", "__global int*"),
    _image("primitive", "__global int*"),
    _image("barycentric", "__global real*"),
    Parameter("inside_out", "__global uchar*", (_asked("inside"),)),
    Parameter("winding_out", "__global double*", (_asked("winding"),)),
)

# count_hits: each ray's number of hits; all_hits: that, and its first hit_capacity hits in its rows
# (r * hit_capacity on): distance (float64), kind, entry and triangle (kernels/allhits.cl)
COUNT_HITS = (
    *RAYS,
    Parameter("hit_counts", "__global int*"),
    # occupancy's rays from points (the aov "surface", kernels/allhits.cl): whether each point lies on
    # a surface, by the closest-point query's leaves (per leaf's first place in refs), refs and the
    # types' float64 world entries
    Parameter("surface_leaf_codes", "__global const int*", (_asked("surface"),)),
    Parameter("surface_refs", "__global const int*", (_asked("surface"),)),
    # per leaf (its first place in refs, 5 float64s each) the slab of a direction that holds its
    # triangles: the surface test's pre-test (kernels/allhits.cl, engine/queries/closest.py)
    Parameter("surface_slabs", "__global const double*", (_asked("surface"),)),
    EachType((Parameter("{type}_surface_worlds", "__global const {World}*", (_asked("surface"),)),)),
    # the distance from the surface within which a point's count may be off by the rounding of the
    # triangles' corners relative to it (engine/queries/closest.py: surface_band)
    Parameter("surface_band", "const double", (_asked("surface"),)),
    Parameter("surface_out", "__global uchar*", (_asked("surface"),)),
    # the rays' crossings signed, +1 out of a mesh and -1 into it, summed (kernels/mesh_blocks.cl)
    Parameter("surface_signed_out", "__global int*", (_asked("surface"),)),
)
ALL_HITS = (
    *RAYS,
    Parameter("hit_counts", "__global int*"),
    Parameter("hit_capacity", "const int"),
    Parameter("hit_t", "__global double*"),
    Parameter("hit_kind", "__global int*"),
    Parameter("hit_k", "__global int*"),
    Parameter("hit_sub", "__global int*"),
)

# each query's kernel (programs.QUERY_FILES) and its signature
SIGNATURES = {"render": RENDER, "cast": CAST, "occluded": OCCLUDED, "count_hits": COUNT_HITS, "all_hits": ALL_HITS,
              "closest": CLOSEST}


def _templates(variant, type_: str) -> dict:
    cls = KINDS[type_]
    # (a type with the smooth_shading capability has smooth_struct: pyclray.model.shapes.capabilities)
    smooth = "real4" if variant.mode(type_) == "INDEXED" else getattr(getattr(cls, "smooth_struct", None), "name", None)
    return {"type": type_, "Type": cls.c_type, "World": cls.world.name, "Smooth": smooth}


@lru_cache(maxsize=512)
def parameters(variant) -> tuple[tuple[str, str], ...]:
    """The (C type, name) of each parameter of the variant's kernel, in order."""
    out = []
    for item in SIGNATURES[variant.query]:
        if isinstance(item, EachType):
            for type_ in item.of(variant):
                names = _templates(variant, type_)
                for parameter in item.parameters:
                    if isinstance(parameter, SharedArrays):
                        out += parameter.resolve(type_, variant)
                    elif parameter.present(variant, type_):
                        out.append((parameter.c_type.format(**names), parameter.name.format(**names)))
        elif item.present(variant):
            out.append((item.c_type, item.name))
    names = [name for _, name in out]
    if len(set(names)) != len(names):
        raise ValueError(f"the {variant.query} kernel's signature names a parameter twice for {variant}: {names}")
    return tuple(out)


@lru_cache(maxsize=512)
def _names(variant) -> tuple[str, ...]:
    return tuple(name for _, name in parameters(variant))


def c_defines(variant) -> list[str]:
    """The program's PYCLRAY_PARAMETERS (the kernel's parameter list, which its work-item functions
    take too) and PYCLRAY_ARGUMENTS (the same names, to pass them on)."""
    listed = parameters(variant)
    return ["#define PYCLRAY_PARAMETERS \\\n    " + ", \\\n    ".join(f"{c_type} {name}" for c_type, name in listed),
            "#define PYCLRAY_ARGUMENTS \\\n    " + ", \\\n    ".join(name for _, name in listed)]


def arguments(variant, values: Mapping) -> list:
    """The kernel's arguments in its order, from values: parameter name -> value. A name the kernel
    takes that values lacks, or one of values that the kernel does not take, raises TypeError."""
    names = _names(variant)
    try:
        ordered = [values[name] for name in names]
    except KeyError:
        ordered = None
    if ordered is None or len(values) != len(names):
        missing = [name for name in names if name not in values]
        extra = [name for name in values if name not in names]
        raise TypeError(f"the {variant.query} kernel of {variant}: "
                        + "; ".join(([f"missing {', '.join(missing)}"] if missing else [])
                                    + ([f"does not take {', '.join(map(str, extra))}"] if extra else [])))
    return ordered
