"""Each struct is declared once; the device's sizeof/offsetof must equal the numpy dtype's."""
import numpy as np
import pyopencl as cl
import pytest

from pyclray.engine.opencl.device import context_for, has_fp64
from pyclray.engine.launch.programs import kernel_dir
from pyclray.model.cameras import CAMERAS
from pyclray.model.layout import Struct, c_header, layout
from pyclray.model.shapes import KINDS

# each camera model's struct, each packed kind's frame struct and its world struct (float64 fields: the
# per-view pass's input; mesh instances' frame struct holds float64 fields too)
STRUCTS = list(dict.fromkeys([model.struct for model in CAMERAS.values()] + [cls.struct for cls in KINDS.values()] + [cls.world for cls in KINDS.values()]))


def measure_on_device(struct: Struct, precision: str) -> list[int]:
    """[sizeof, offsetof(field) ...] as the OpenCL compiler lays the struct out."""
    ctx = context_for()
    if precision == "fp64" and not has_fp64(ctx.device):
        pytest.skip("device lacks cl_khr_fp64")
    float64 = any(t.startswith("double") for _, t in struct.fields)
    if float64 and not has_fp64(ctx.device):
        pytest.skip("device lacks cl_khr_fp64 (world structs are float64: the host rebases instead)")
    prefix = "#define PYCLRAY_FP64 1\n" if precision == "fp64" else ""
    if float64:
        prefix = "#pragma OPENCL EXTENSION cl_khr_fp64 : enable\n" + prefix
    common = kernel_dir().joinpath("common.h").read_text()
    writes = [f"out[0] = sizeof({struct.name});"]
    writes += [f"out[{k + 1}] = __builtin_offsetof({struct.name}, {field});" for k, (field, _) in enumerate(struct.fields)]
    source = prefix + common + c_header([struct], precision) + "__kernel void measure(__global int* out) {" + "".join(writes) + "}"
    program = cl.Program(ctx.context, source).build()
    out = np.zeros(len(struct.fields) + 1, np.int32)
    buffer = cl.Buffer(ctx.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    program.measure(ctx.queue, (1,), None, buffer)
    cl.enqueue_copy(ctx.queue, out, buffer)
    return out.tolist()


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("struct", STRUCTS, ids=[s.name for s in STRUCTS])
def test_device_layout_equals_the_dtype(struct, precision):
    spec = layout(struct, precision)
    measured = measure_on_device(struct, precision)
    dtype_offsets = [spec.dtype.fields[name][1] for name, _ in struct.fields]
    assert measured == [spec.dtype.itemsize] + dtype_offsets


def test_float4_after_a_float_is_aligned_as_in_opencl():
    spec = layout(Struct("T", (("a", "float"), ("b", "real4"), ("c", "int"))), "fp32")
    assert spec.offsets == (0, 16, 32) and spec.itemsize == 48
    assert spec.dtype.itemsize == 48 and spec.dtype.fields["b"][1] == 16
    assert "float4 b;" in spec.c_typedef
    assert layout(Struct("T", (("a", "float"), ("b", "real4"))), "fp64").offsets == (0, 32)


def test_unknown_types_are_refused():
    with pytest.raises(ValueError):
        layout(Struct("T", (("a", "float3"),)), "fp32")
