/* pyclray: types and helpers shared by every shape and kernel.
 *
 * Precision: `real` is float (fp32) or double (fp64, -D PYCLRAY_FP64).
 * Frames: the render kernel works in the camera's frame (origin at the eye, axes u, v, w), the cast
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
#define convert_real3 convert_double3
#else
typedef float real;
typedef float3 real3;
typedef float4 real4;
#define convert_real3 convert_float3
#endif

#define MISS ((real)INFINITY)

#ifdef PYCLRAY_CAST
/* cast takes the differences of its rays' and shapes' world coordinates in float64 (kernels/pyclray.cl) */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#endif

/* A ray s -> origin + s * dir in the current frame; dir need not be unit, a = dot(dir, dir).
 * In cast, the frame of each shape is its own anchor (kernels/pyclray.cl), and the float64 fields
 * hold the ray as given (unbounded shapes, which have no anchor, read its world origin). */
typedef struct {
    real3 origin;
    real3 dir;
    real a;
#ifdef PYCLRAY_CAST
    double3 world;      /* the ray's origin in world coordinates */
    double3 dir_exact;  /* its unit direction, of which dir is the rounding */
#endif
} Ray;
