/* The scene's per-view pass (pyclray/engine/scene/prepared.py): the world's float64 entries rebased into the
 * space of a camera, one work-item per entry, so that a moved camera uploads only itself and the
 * kernels keep testing shapes in the camera's space. The host puts before this file common.h, the
 * generated struct header and each present shape type's file (with PYCLRAY_REBASE: their
 * <type>_rebase only), which use the helpers below; each type gets its kernel rebase_<type>.
 *
 * The differences of world coordinates are taken in float64 before anything is rounded to the
 * kernel's precision, and what every ray from the space's origin shares (a sphere's c, a plane's
 * offset, a box's slab offsets) from error-free products and sums (Ogita, Rump and Oishi 2005), as
 * pyclray.model.exact does on the host: the same float64 numbers, bit for bit, as the host's
 * rebase (its two_prod is Dekker's, exact as fma's is). No contraction of a * b + c into an fma:
 * each rounding is the one written. */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

/* the per-view pass writes each space entry to its buffer (cast rebases into private copies: cast.h) */
#define PYCLRAY_REBASE_OUT __global
