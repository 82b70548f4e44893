"""Each kernel's signature, declared once (pyclray.engine.launch.signatures): the C parameter list a program
is built with agrees with what the built kernel reports, and the argument list pyopencl gets is
assembled from names, in that order, refusing a missing or an extra name at once."""
import warnings

import numpy as np
import pyopencl as cl
import pytest

from pyclray.engine.launch import signatures
from pyclray.engine.opencl.device import context_for, has_fp64, is_pocl_cpu
from pyclray.engine.launch.programs import Variant

ALL = ("plane", "sphere", "cylinder", "disk", "rectangle", "box", "spheres", "mesh", "instance")
IMAGES = ("depth", "normal", "id", "zdepth", "position", "shaded", "primitive", "barycentric")

# each query; with and without shadows, tile lists and the BVH, both precisions, several shape sets
# (meshes, mesh instances, unbounded planes alone), the from_world, copied and indexed entries, smooth types
VARIANTS = [
    Variant("render", ("plane", "sphere"), ("depth", "normal", "id"), "fp32", 8),
    Variant("render", ("plane", "sphere"), ("depth", "normal", "id"), "fp32", 8, bvh=True),
    Variant("render", ("plane",), ("depth",), "fp64", 4, bvh=True),
    Variant("render", ("sphere",), ("depth",), "fp32", 1),
    Variant("render", ("plane", "mesh"), IMAGES, "fp32", 8, shadows=True, smooth=("mesh",)),
    Variant("render", ("plane", "mesh"), IMAGES, "fp64", 4, shadows=True, bvh=True, smooth=("mesh",), indexed=True),
    Variant("render", ("plane", "sphere", "mesh"), ("shaded",), "fp32", 8, shadows=False, bvh=True, from_world=True,
            indexed=True),
    Variant("render", ("mesh", "instance"), IMAGES, "fp32", 8, shadows=True, bvh=True, smooth=("mesh", "instance")),
    Variant("render", ALL, ("depth", "normal", "id", "shaded"), "fp64", 4, shadows=True),
    Variant("cast", ("plane", "sphere"), ("depth", "normal", "id"), "fp32"),
    Variant("cast", ("plane",), ("depth",), "fp64"),
    Variant("cast", ("mesh", "instance"), ("id",), "fp32"),
    Variant("cast", ALL, ("depth", "normal", "id"), "fp64"),
    Variant("occluded", ("plane", "sphere"), (), "fp32"),
    Variant("occluded", ("box", "mesh", "instance"), (), "fp64"),
]

GLOBAL = cl.kernel_arg_address_qualifier.GLOBAL


def reported(variant: Variant) -> list[tuple[str, str, bool]]:
    """(name, type name, in global memory) of each argument of the variant's kernel, as the OpenCL
    compiler reports it for the program built from the variant's source with argument info."""
    ctx = context_for()
    source = variant.source(inline_builtins=is_pocl_cpu(ctx.device))
    with warnings.catch_warnings():  # PoCL's notes on a successful build
        warnings.simplefilter("ignore", cl.CompilerWarning)
        program = cl.Program(ctx.context, source).build(options=variant.options() + ["-cl-kernel-arg-info"])
    kernel = cl.Kernel(program, variant.query)
    info = cl.kernel_arg_info
    return [(kernel.get_arg_info(i, info.NAME), kernel.get_arg_info(i, info.TYPE_NAME),
             kernel.get_arg_info(i, info.ADDRESS_QUALIFIER) == GLOBAL) for i in range(kernel.num_args)]


def declared(variant: Variant) -> list[tuple[str, str, bool]]:
    """The same from the signature: the type without its qualifiers, as the compiler names it."""
    out = []
    for c_type, name in signatures.parameters(variant):
        words = c_type.split()
        out.append((name, " ".join(w for w in words if w not in ("__global", "const")), "__global" in words))
    return out


@pytest.mark.parametrize("variant", VARIANTS, ids=lambda v: f"{v.query}-{'-'.join(v.shape_types)}-{v.precision}"
                         f"{'-bvh' if v.bvh else ''}{'-shadows' if v.shadows else ''}{'-from_world' if v.from_world else ''}"
                         f"{'-indexed' if v.indexed else ''}-{len(v.aovs)}")
def test_the_declared_parameters_are_the_built_kernels(variant):
    if variant.precision == "fp64" and not has_fp64(context_for().device):
        pytest.skip("device lacks cl_khr_fp64")
    assert reported(variant) == declared(variant)


def test_the_program_declares_the_kernel_with_the_generated_list():
    variant = VARIANTS[4]
    source = variant.source()
    parameters, arguments = signatures.c_defines(variant)
    assert parameters in source and arguments in source
    assert "__kernel void render(PYCLRAY_PARAMETERS)" in source
    names = [name for _, name in signatures.parameters(variant)]
    assert names[:7] == ["camera", "col0", "row0", "cols", "rows", "tile_shift", "tiles_x"]
    assert names[-1] == "barycentric_out" and "mesh_smooth" in names and names.count("n_meshs") == 1


def test_what_each_condition_adds():
    """Shadows add each type's count (tile lists) or the binary tree (BVH); the BVH's buffers only
    with a bounded type; each image its buffer, the position its eye too."""
    def names(**changes):
        base = dict(query="render", shape_types=("plane", "sphere"), aovs=("shaded",), precision="fp32", lanes=8)
        return [name for _, name in signatures.parameters(Variant(**{**base, **changes}))]

    assert set(names(shadows=True)) - set(names()) == {"n_planes", "n_spheres"}
    assert set(names(shadows=True, bvh=True)) - set(names(bvh=True)) == {"nodes"}
    assert "wide_nodes" not in names(shape_types=("plane",), bvh=True)
    assert set(names(aovs=("shaded", "position"))) - set(names()) == {"eye_high", "eye_low", "position_out"}
    assert "sphere_worlds" in names(from_world=True) and "spheres" in names()


def test_arguments_come_in_the_signatures_order():
    variant = Variant("occluded", ("plane", "sphere"), (), "fp32")
    names = [name for _, name in signatures.parameters(variant)]
    values = {name: index for index, name in enumerate(names)}
    assert signatures.arguments(variant, dict(reversed(values.items()))) == list(range(len(names)))


def test_a_missing_or_extra_argument_is_an_error_naming_it():
    variant = Variant("cast", ("plane", "sphere"), ("depth",), "fp32")
    values = {name: np.int32(0) for _, name in signatures.parameters(variant)}
    missing = {k: v for k, v in values.items() if k != "n_spheres"}
    with pytest.raises(TypeError, match=r"missing n_spheres$"):
        signatures.arguments(variant, missing)
    with pytest.raises(TypeError, match=r"does not take normal_out$"):
        signatures.arguments(variant, {**values, "normal_out": None})
    with pytest.raises(TypeError, match=r"missing n_spheres; does not take wide_nodes$"):
        signatures.arguments(variant, {**missing, "wide_nodes": None})  # render's tree, not cast's
