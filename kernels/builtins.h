/* Inline copies of the OpenCL built-ins the kernels call (dot, cross, normalize, sqrt, fabs,
 * copysign, fmin, fmax), used on PoCL's CPU device only, where the host selects them.
 *
 * Why: PoCL's distro build links its built-in library compiled for another CPU model than the
 * kernel (haswell vs the host's), and LLVM then refuses to inline across the mismatch: every
 * dot() or sqrt() is a real function call in the per-pixel loop. These copies compute exactly what
 * PoCL's library computes, operation for operation and without contraction into FMAs, so the
 * images are bit-identical; they only let the compiler inline them.
 */
#ifdef PYCLRAY_FP64
#define PYCLRAY_TINY2 0x1p-1022     /* below it, dot(v, v) lost precision: scale v up */
#define PYCLRAY_UP 0x1p563
#define PYCLRAY_DOWN 0x1p-514
#define PYCLRAY_BUILTIN_SQRT __builtin_sqrt
#define PYCLRAY_BUILTIN_FABS __builtin_fabs
#define PYCLRAY_BUILTIN_COPYSIGN __builtin_copysign
#else
#define PYCLRAY_TINY2 0x1p-126f
#define PYCLRAY_UP 0x1p86f
#define PYCLRAY_DOWN 0x1p-66f
#define PYCLRAY_BUILTIN_SQRT __builtin_sqrtf
#define PYCLRAY_BUILTIN_FABS __builtin_fabsf
#define PYCLRAY_BUILTIN_COPYSIGN __builtin_copysignf
#endif

inline real pyclray_dot(const real3 a, const real3 b)
{
#pragma OPENCL FP_CONTRACT OFF
    return (a.x * b.x + a.y * b.y) + a.z * b.z;
}

inline real3 pyclray_cross(const real3 a, const real3 b)
{
#pragma OPENCL FP_CONTRACT OFF
    return (real3)(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}

/* as PoCL: the first argument unless it is not less than the second, or the second is NaN */
inline real pyclray_fmin(const real a, const real b) { return (b != b || a < b) ? a : b; }
inline real pyclray_fmax(const real a, const real b) { return (b != b || a > b) ? a : b; }
inline real pyclray_sqrt(const real a) { return PYCLRAY_BUILTIN_SQRT(a); }
inline real pyclray_fabs(const real a) { return PYCLRAY_BUILTIN_FABS(a); }
inline real pyclray_copysign(const real a, const real b) { return PYCLRAY_BUILTIN_COPYSIGN(a, b); }

/* v / |v|, scaled first when |v|^2 under- or overflows; a zero vector is returned as is */
inline real3 pyclray_normalize(real3 v)
{
#pragma OPENCL FP_CONTRACT OFF
    if (v.x == 0 && v.y == 0 && v.z == 0) return v;
    real l2 = pyclray_dot(v, v);
    if (l2 < PYCLRAY_TINY2) {
        v = v * PYCLRAY_UP;
        l2 = pyclray_dot(v, v);
    } else if (l2 == INFINITY) {
        v = v * PYCLRAY_DOWN;
        l2 = pyclray_dot(v, v);
        if (l2 == INFINITY) {  /* infinite components: the unit vector along them */
            v = (real3)(PYCLRAY_BUILTIN_COPYSIGN(PYCLRAY_BUILTIN_FABS(v.x) == INFINITY ? 1 : 0, v.x),
                        PYCLRAY_BUILTIN_COPYSIGN(PYCLRAY_BUILTIN_FABS(v.y) == INFINITY ? 1 : 0, v.y),
                        PYCLRAY_BUILTIN_COPYSIGN(PYCLRAY_BUILTIN_FABS(v.z) == INFINITY ? 1 : 0, v.z));
            l2 = pyclray_dot(v, v);
        }
    }
    return v * ((real)1 / PYCLRAY_BUILTIN_SQRT(l2));
}

#undef dot
#undef cross
#undef fmin
#undef fmax
#undef sqrt
#undef fabs
#undef copysign
#undef normalize
#define dot(a, b) pyclray_dot(a, b)
#define cross(a, b) pyclray_cross(a, b)
#define fmin(a, b) pyclray_fmin(a, b)
#define fmax(a, b) pyclray_fmax(a, b)
#define sqrt(a) pyclray_sqrt(a)
#define fabs(a) pyclray_fabs(a)
#define copysign(a, b) pyclray_copysign(a, b)
#define normalize(a) pyclray_normalize(a)

inline void pyclray_vstore3(const real3 v, const size_t index, __global real* out)
{
    out[3 * index] = v.x;
    out[3 * index + 1] = v.y;
    out[3 * index + 2] = v.z;
}
#undef vstore3
#define vstore3(v, index, out) pyclray_vstore3(v, index, out)
