/* cast's spaces (kernels/rays.h): each shape a ray visits is rebased on that ray's own origin by
 * its <type>_rebase, as the per-view pass rebases it on the eye (kernels/rebase.cl), so that the
 * terms a ray's origin decides (a sphere's c = |F|^2 - r^2, a plane's or a face's signed distance, a
 * cylinder's distance from its axis) come from the shape's float64 world entry and the float64
 * origin: which side of a surface a ray starts on, and how far from it, are then as exact as for an
 * eye there, even for an origin on the surface or 1e8 away. The space keeps the world's axes, and
 * its sums are plain float64 (a rounding of eps64 times their terms, below the kernel's own error
 * by 2^-29 in fp32, within the model's eps64 in fp64), not the per-view pass's error-free ones,
 * which would cost ten times more per visit. The rebased copy lives in private memory. */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable

#define PYCLRAY_REBASE_OUT

/* fabs and sqrt of doubles, and element i of an array of 3-vectors: on PoCL's CPU device the
 * compiler's own operations (the library's are calls there, which LLVM does not inline:
 * kernels/lanes.h's v_sqrt), with the same IEEE results */
#ifdef PYCLRAY_INLINE_BUILTINS
#define CAST_FABS(x) __builtin_fabs(x)
#define CAST_SQRT(x) __builtin_sqrt(x)
#else
#define CAST_FABS(x) fabs(x)
#define CAST_SQRT(x) sqrt(x)
#endif
/* a hint that the bytes [p, p + size) will be read soon (nothing where the compiler has no prefetch) */
#ifdef PYCLRAY_INLINE_BUILTINS
#define CAST_PREFETCH(p, size)                                                                   \
    for (int byte = 0; byte < (size); byte += 64) __builtin_prefetch((__global const char*)(p) + byte);
#else
#define CAST_PREFETCH(p, size) {}
#endif
inline double3 load_double3(__global const double* p, const int i)
{
    p += 3 * (size_t)i;
    return (double3)(p[0], p[1], p[2]);
}

typedef struct {
    double3 origin;  /* the ray's origin (where it starts testing this shape), world coordinates */
} Space;

/* the space has the world's axes: a vector's coordinates are its own, rounded */
inline real3 to_space(const Space* space, const double3 x) { return convert_real3(x); }

/* what to_space's rounding left out, rounded (kernels/space.h; cast's rays do not use it) */
inline real3 to_space_low(const Space* space, const double3 x) { return convert_real3(x - convert_double3(convert_real3(x))); }

inline double dot2_3(const double3 x, const double3 y) { return (x.x * y.x + x.y * y.y) + x.z * y.z; }

inline double dot2_4(const double4 x, const double4 y) { return ((x.x * y.x + x.y * y.y) + x.z * y.z) + x.w * y.w; }

/* |F x A|^2 - r^2 */
inline double cross_norm2_minus(const double3 F, const double3 A, const double r)
{
    const double3 FxA = (double3)(F.y * A.z - F.z * A.y, F.z * A.x - F.x * A.z, F.x * A.y - F.y * A.x);
    return ((FxA.x * FxA.x + FxA.y * FxA.y) + FxA.z * FxA.z) - r * r;
}
