/* pyclray: types and helpers shared by every shape and kernel.
 *
 * Precision: `real` is float (fp32) or double (fp64, -D PYCLRAY_FP64).
 * Spaces: the render kernel works in the camera's space (origin at the eye, axes u, v, w), the cast
 * kernel in the world's axes around each shape's own anchor. The host subtracts that origin in
 * float64 before packing (and cast subtracts its rays' origins in float64 on the device), so no
 * large coordinate ever reaches a shape's test: far or translated scenes keep float32's full
 * relative precision.
 */
#ifdef PYCLRAY_FP64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double real;
typedef double3 real3;
typedef double4 real4;
#define PYCLRAY_REAL_NAME double
#define PYCLRAY_INT_NAME long      /* the integer type of a real's size: a vector comparison's lanes */
#define PYCLRAY_UINT_NAME ulong
#define convert_real3 convert_double3
#else
typedef float real;
typedef float3 real3;
typedef float4 real4;
#define PYCLRAY_REAL_NAME float
#define PYCLRAY_INT_NAME int
#define PYCLRAY_UINT_NAME uint
#define convert_real3 convert_float3
#endif

#define MISS ((real)INFINITY)

#if defined(PYCLRAY_CAST) || defined(PYCLRAY_FROM_WORLD) || defined(PYCLRAY_INDEXED)
/* cast takes the differences of its rays' and shapes' world coordinates in float64 (kernels/rays.h),
 * a from-world render rebases each shape on the eye from its float64 world entry, and an indexed mesh's
 * winner has its world normal from its float64 vertices (kernels/mesh.cl) */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#endif

/* On PoCL's CPU device every function before a query's kernels is always inlined (pyclray/engine/launch/programs.py),
 * the kernels themselves not: each query's file starts its kernels with PYCLRAY_KERNELS_BEGIN. */
#ifdef PYCLRAY_INLINE_BUILTINS
#define PYCLRAY_KERNELS_BEGIN _Pragma("clang attribute pop")
#else
#define PYCLRAY_KERNELS_BEGIN
#endif

/* Each kernel calls one function per work-item (a packet, or cast's ray). On PoCL's CPU device that
 * function is not inlined into the kernel: PoCL copies a kernel's body into each of the three
 * functions it makes of it (the work-item loops and two launchers), and the compile time of a first
 * render grows with that code (docs/benchmarks.md: PYCLRAY_WORK_ITEM_FUNCTION); a call per
 * work-item costs nothing measurable. Elsewhere it is inlined as usual. */
#ifdef PYCLRAY_INLINE_BUILTINS
#define PYCLRAY_WORK_ITEM_FUNCTION __attribute__((noinline))
#else
#define PYCLRAY_WORK_ITEM_FUNCTION inline
#endif
