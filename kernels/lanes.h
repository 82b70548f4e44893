/* Packets: the rays of one work-item in the lanes of a vector.
 *
 * On CPUs a work-item casts LANES rays at once in SIMD lanes (PoCL does not vectorize scalar or
 * float3 shape code across work-items, explicit lanes do); on GPUs LANES is 1 and a work-item is one
 * ray. Shape code is written once over these types and compiles at any width:
 *   realv   LANES reals (real when LANES is 1)
 *   intv    the integer vector of realv's comparisons: a lane's mask is -1 (true) or 0 (false) in a
 *           vector, 1 or 0 for a scalar; combine masks with &&, || and ! (both keep that meaning)
 *   vec3v   three realv: a packet of 3-vectors in structure-of-arrays form
 * `mask ? b : a` selects per lane (OpenCL C's vector ternary), so shape code has no per-lane branches.
 *
 * Rounding: contraction into fused multiply-adds is off in every kernel, so a lane's result is the
 * same at every width and on every device (the tests compare the scalar and the vector width bit for
 * bit), and the operation order of dot and cross below is that of the scalar code they replace.
 */
#pragma OPENCL FP_CONTRACT OFF

#ifndef PYCLRAY_LANES
#define PYCLRAY_LANES 1
#endif
#define LANES PYCLRAY_LANES

#define PYCLRAY_CAT_(a, b) a##b
#define PYCLRAY_CAT(a, b) PYCLRAY_CAT_(a, b)

#if LANES == 1
typedef real realv;
typedef int intv;                       /* scalar comparisons give int, also for double */
typedef int intlane;
#define VLOAD(i, p) ((p)[(i)])
#define VSTORE(v, i, p) ((p)[(i)] = (v))
#define TO_REALV(x) ((real)(x))
#define TO_INTV(x) ((int)(x))
#define TO_INT32V(x) ((int)(x))
#define LANE_INDEX 0
#define ANY(mask) ((mask) != 0)
#define ALL(mask) ((mask) != 0)
#else
typedef PYCLRAY_CAT(PYCLRAY_REAL_NAME, LANES) realv;
typedef PYCLRAY_CAT(PYCLRAY_INT_NAME, LANES) intv;   /* int for float lanes, long for double lanes */
typedef PYCLRAY_INT_NAME intlane;
#define VLOAD(i, p) PYCLRAY_CAT(vload, LANES)((i), (p))
#define VSTORE(v, i, p) PYCLRAY_CAT(vstore, LANES)((v), (i), (p))
#define TO_REALV(x) PYCLRAY_CAT(PYCLRAY_CAT(convert_, PYCLRAY_REAL_NAME), LANES)(x)
#define TO_INTV(x) PYCLRAY_CAT(PYCLRAY_CAT(convert_, PYCLRAY_INT_NAME), LANES)(x)
#define TO_INT32V(x) PYCLRAY_CAT(convert_int, LANES)(x)
#define ANY(mask) any(mask)
#define ALL(mask) all(mask)
#if LANES == 2
#define LANE_INDEX ((intv)(0, 1))
#elif LANES == 4
#define LANE_INDEX ((intv)(0, 1, 2, 3))
#elif LANES == 8
#define LANE_INDEX ((intv)(0, 1, 2, 3, 4, 5, 6, 7))
#elif LANES == 16
#define LANE_INDEX ((intv)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15))
#else
#error "PYCLRAY_LANES must be 1, 2, 4, 8 or 16"
#endif
#endif

/* the same value in every lane */
#define SPLAT(x) ((realv)(x))
#define SPLAT_INT(x) ((intv)(x))

/* -- lane-wise functions (exactly IEEE: no approximations) -------------------------------------- */
#ifdef PYCLRAY_FP64
#define PYCLRAY_SIGN_BIT 0x8000000000000000L
#else
#define PYCLRAY_SIGN_BIT 0x80000000
#endif
#if LANES == 1
#define PYCLRAY_AS_BITS(x) PYCLRAY_CAT(as_, PYCLRAY_UINT_NAME)(x)
#define PYCLRAY_AS_REAL(x) PYCLRAY_CAT(as_, PYCLRAY_REAL_NAME)(x)
#else
#define PYCLRAY_AS_BITS(x) PYCLRAY_CAT(PYCLRAY_CAT(as_, PYCLRAY_UINT_NAME), LANES)(x)
#define PYCLRAY_AS_REAL(x) PYCLRAY_CAT(PYCLRAY_CAT(as_, PYCLRAY_REAL_NAME), LANES)(x)
#endif

/* |x| and copysign by the sign bit, as IEEE defines them (also for -0 and NaN) */
inline realv v_abs(const realv x) { return PYCLRAY_AS_REAL(PYCLRAY_AS_BITS(x) & ~PYCLRAY_SIGN_BIT); }
inline realv v_copysign(const realv x, const realv sign)
{
    return PYCLRAY_AS_REAL((PYCLRAY_AS_BITS(x) & ~PYCLRAY_SIGN_BIT) | (PYCLRAY_AS_BITS(sign) & PYCLRAY_SIGN_BIT));
}
/* the smaller and the larger of two reals that are not NaN */
inline realv v_min(const realv a, const realv b) { return a < b ? a : b; }
inline realv v_max(const realv a, const realv b) { return a > b ? a : b; }
/* correctly rounded square root, lane by lane (the -cl-fp32-correctly-rounded-divide-sqrt build
 * option makes it so on every device) */
inline realv v_sqrt(const realv x) { return sqrt(x); }

/* -- packets of 3-vectors ------------------------------------------------------------------------ */
typedef struct {
    realv x, y, z;
} vec3v;

inline vec3v v3(const realv x, const realv y, const realv z)
{
    vec3v r;
    r.x = x;
    r.y = y;
    r.z = z;
    return r;
}
/* one point or direction (xyz of a packed real4) in every lane */
inline vec3v v3_splat(const real4 p) { return v3(SPLAT(p.x), SPLAT(p.y), SPLAT(p.z)); }
inline vec3v v3_add(const vec3v a, const vec3v b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
inline vec3v v3_sub(const vec3v a, const vec3v b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
inline vec3v v3_scale(const vec3v a, const realv s) { return v3(a.x * s, a.y * s, a.z * s); }
inline realv v3_dot(const vec3v a, const vec3v b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }
inline vec3v v3_cross(const vec3v a, const vec3v b)
{
    return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
/* per lane: b where mask, else a */
inline vec3v v3_select(const vec3v a, const vec3v b, const intv mask)
{
    return v3(mask ? b.x : a.x, mask ? b.y : a.y, mask ? b.z : a.z);
}

#ifdef PYCLRAY_FP64
#define PYCLRAY_TINY2 0x1p-1022     /* below it, dot(v, v) lost precision: scale v up */
#define PYCLRAY_UP 0x1p563
#define PYCLRAY_DOWN 0x1p-514
#else
#define PYCLRAY_TINY2 0x1p-126f
#define PYCLRAY_UP 0x1p86f
#define PYCLRAY_DOWN 0x1p-66f
#endif

/* v / |v|, scaled first where |v|^2 under- or overflows; a zero vector stays zero. The same result
 * as OpenCL's normalize on PoCL, lane by lane. */
inline vec3v v3_normalize(vec3v v)
{
    realv l2 = v3_dot(v, v);
    const intv tiny = l2 < PYCLRAY_TINY2, huge = l2 == INFINITY;
    if (ANY(tiny || huge)) {  /* rare: a separate path, so the usual one is a dot, a root and a division */
        const intv zero = v.x == 0 && v.y == 0 && v.z == 0;
        v = v3_scale(v, tiny ? SPLAT(PYCLRAY_UP) : (huge ? SPLAT(PYCLRAY_DOWN) : SPLAT(1)));
        l2 = v3_dot(v, v);
        const intv infinite = l2 == INFINITY;
        if (ANY(infinite)) {  /* infinite components: the unit vector along them */
            const vec3v along = v3(v_copysign(v_abs(v.x) == INFINITY ? SPLAT(1) : SPLAT(0), v.x),
                                   v_copysign(v_abs(v.y) == INFINITY ? SPLAT(1) : SPLAT(0), v.y),
                                   v_copysign(v_abs(v.z) == INFINITY ? SPLAT(1) : SPLAT(0), v.z));
            v = v3_select(v, along, infinite);
            l2 = v3_dot(v, v);
        }
        return v3_select(v3_scale(v, SPLAT(1) / v_sqrt(l2)), v, zero);
    }
    return v3_scale(v, SPLAT(1) / v_sqrt(l2));
}

/* A packet of rays s -> origin + s * dir in the current frame; dir need not be unit, a = dir . dir.
 * cast traces one ray per work-item (LANES 1) from each shape's own anchor (kernels/pyclray.cl) and
 * keeps the ray as given in float64: its world origin (unbounded shapes, which have no anchor, read
 * it) and its unit direction, of which dir is the rounding. */
typedef struct {
    vec3v origin;
    vec3v dir;
    realv a;
#ifdef PYCLRAY_CAST
    double3 world;
    double3 dir_exact;
#endif
#ifdef PYCLRAY_SHADOWS
    int from_eye;  /* 1: camera rays; 0: shadow rays, from points of the scene (kernels/shading.h) */
#endif
} RayPacket;

/* FROM_EYE(ray): whether the packet starts at the frame's origin, the eye, where the terms the host
 * computed once in float64 for every camera ray hold (a sphere's c, a plane's h). Cast's rays never
 * do; a render's camera rays always, and its shadow rays (only compiled with shadows) never: a
 * constant wherever the shape functions are inlined into the kernel. */
#if defined(PYCLRAY_CAST)
#define FROM_EYE(ray) 0
#elif defined(PYCLRAY_SHADOWS)
#define FROM_EYE(ray) ((ray)->from_eye)
#else
#define FROM_EYE(ray) 1
#endif
