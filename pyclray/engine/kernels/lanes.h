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

/* A render's fp32 pinhole camera rays carry their image-plane point as float pairs, for the flat
 * shapes' n . d (pixel_dot below) and mesh instances' object directions (kernels/instance.cl);
 * cast traces the caller's rays, a camera table's rays (a lens, a panorama: kernels/camera.h) come
 * rounded from the host, the closest-point query has no rays, and fp64 has the digits without it.
 * (bench/kernels_ab.py --without-pixel-exact compiles the define out to measure what it costs.) */
#if !defined(PYCLRAY_FP64) && !defined(PYCLRAY_CAST) && !defined(PYCLRAY_CAMERA_TABLE) && !defined(PYCLRAY_CLOSEST)
#define PYCLRAY_PIXEL_EXACT 1
#endif

#define PYCLRAY_CAT_(a, b) a##b
#define PYCLRAY_CAT(a, b) PYCLRAY_CAT_(a, b)

#if LANES == 1
typedef real realv;
typedef int intv;                       /* scalar comparisons give int, also for double */
typedef int intlane;
#define VSTORE(v, i, p) ((p)[(i)] = (v))
#define TO_REALV(x) ((real)(x))
#define TO_INT32V(x) ((int)(x))
#define LANE_INDEX 0
#define ANY(mask) ((mask) != 0)
#else
typedef PYCLRAY_CAT(PYCLRAY_REAL_NAME, LANES) realv;
typedef PYCLRAY_CAT(PYCLRAY_INT_NAME, LANES) intv;   /* int for float lanes, long for double lanes */
typedef PYCLRAY_INT_NAME intlane;
#define VSTORE(v, i, p) PYCLRAY_CAT(vstore, LANES)((v), (i), (p))
#define TO_REALV(x) PYCLRAY_CAT(PYCLRAY_CAT(convert_, PYCLRAY_REAL_NAME), LANES)(x)
#define TO_INT32V(x) PYCLRAY_CAT(convert_int, LANES)(x)
/* ANY: see the reductions below */
#if LANES == 2
#define LANE_INDEX ((intv)(0, 1))
#elif LANES == 4
#define LANE_INDEX ((intv)(0, 1, 2, 3))
#elif LANES == 8
#define LANE_INDEX ((intv)(0, 1, 2, 3, 4, 5, 6, 7))
#else
#error "PYCLRAY_LANES must be 1, 2, 4 or 8"
#endif
#endif

/* the same value in every lane */
#define SPLAT(x) ((realv)(x))
#define SPLAT_INT(x) ((intv)(x))

/* the lanes one by one: X(lane, component) for each; and F(x) of each lane, as a packet */
#if LANES == 1
#define PYCLRAY_LANEWISE(F, x) F(x)
#elif LANES == 2
#define PYCLRAY_EACH_LANE(X) X(0, s0) X(1, s1)
#define PYCLRAY_LANEWISE(F, x) ((realv)(F((x).s0), F((x).s1)))
#elif LANES == 4
#define PYCLRAY_EACH_LANE(X) X(0, s0) X(1, s1) X(2, s2) X(3, s3)
#define PYCLRAY_LANEWISE(F, x) ((realv)(F((x).s0), F((x).s1), F((x).s2), F((x).s3)))
#elif LANES == 8
#define PYCLRAY_EACH_LANE(X) X(0, s0) X(1, s1) X(2, s2) X(3, s3) X(4, s4) X(5, s5) X(6, s6) X(7, s7)
#define PYCLRAY_LANEWISE(F, x) \
    ((realv)(F((x).s0), F((x).s1), F((x).s2), F((x).s3), F((x).s4), F((x).s5), F((x).s6), F((x).s7)))
#endif

/* A whole packet stored at p (its first lane's element): on PoCL's CPU device one move instruction
 * through a vector type of the element's alignment (see v_sqrt), else vstoren. */
#if LANES > 1
#ifdef PYCLRAY_INLINE_BUILTINS
typedef realv realv_unaligned __attribute__((aligned(sizeof(real))));
typedef PYCLRAY_CAT(int, LANES) int32v_unaligned __attribute__((aligned(sizeof(int))));
#define STORE_REALS(v, p) (*(__global realv_unaligned*)(p) = (v))
#define STORE_INT32S(v, p) (*(__global int32v_unaligned*)(p) = (v))
#else
#define STORE_REALS(v, p) VSTORE((v), 0, (p))
#define STORE_INT32S(v, p) VSTORE((v), 0, (p))
#endif
#endif

/* -- reductions over the lanes, in registers: the two halves combined until one lane is left -----
 * (OpenCL's any() would be a call into PoCL's library: see v_sqrt) */
#define PYCLRAY_OR(a, b) ((a) | (b))
#define PYCLRAY_MIN(a, b) ((a) < (b) ? (a) : (b))
#define PYCLRAY_MAX(a, b) ((a) > (b) ? (a) : (b))
#if LANES == 1
#define PYCLRAY_REDUCE(scalar, v, OP) return (v);
#elif LANES == 2
#define PYCLRAY_REDUCE(scalar, v, OP) return (scalar)OP((v).s0, (v).s1);
#elif LANES == 4
#define PYCLRAY_REDUCE(scalar, v, OP)                                                  \
    const __typeof__((v).lo) h2 = OP((v).lo, (v).hi);                                   \
    return (scalar)OP(h2.s0, h2.s1);
#else
#define PYCLRAY_REDUCE(scalar, v, OP)                                                  \
    const __typeof__((v).lo) h4 = OP((v).lo, (v).hi);                                   \
    const __typeof__(h4.lo) h2 = OP(h4.lo, h4.hi);                                      \
    return (scalar)OP(h2.s0, h2.s1);
#endif
inline intlane lanes_or(const intv v) { PYCLRAY_REDUCE(intlane, v, PYCLRAY_OR) }
inline intlane lanes_max_int(const intv v) { PYCLRAY_REDUCE(intlane, v, PYCLRAY_MAX) }
/* the smallest and the largest lane of reals that are not NaN */
inline real lane_min(const realv v) { PYCLRAY_REDUCE(real, v, PYCLRAY_MIN) }
inline real lane_max(const realv v) { PYCLRAY_REDUCE(real, v, PYCLRAY_MAX) }
#if LANES > 1
/* whether any lane's mask is set (-1: the sign bit) */
#define ANY(mask) (lanes_or(mask) < 0)
#endif

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
 * option makes OpenCL's so on every device).
 * On PoCL's CPU device (PYCLRAY_INLINE_BUILTINS) every built-in of its library is a real call in
 * the kernel: the library is compiled for another CPU model than the kernel, and LLVM does not
 * inline across the mismatch (objdump of the kernel's .so shows the calls). The compiler's own
 * square root, one per lane, compiles to one vector instruction and is correctly rounded too, so
 * the bits are the same; the vector loads and stores below are written for the same reason. */
#ifdef PYCLRAY_INLINE_BUILTINS
#ifdef PYCLRAY_FP64
#define PYCLRAY_SQRT_LANE(x) __builtin_sqrt(x)
#else
#define PYCLRAY_SQRT_LANE(x) __builtin_sqrtf(x)
#endif
inline realv v_sqrt(const realv x) { return PYCLRAY_LANEWISE(PYCLRAY_SQRT_LANE, x); }
#else
inline realv v_sqrt(const realv x) { return sqrt(x); }
#endif
/* a b + c rounded once (a fused multiply-add, exact IEEE on every device: in hardware or emulated), lane
 * by lane; on PoCL's CPU device the compiler's own, as v_sqrt's (one vector instruction with FMA) */
#ifdef PYCLRAY_INLINE_BUILTINS
#ifdef PYCLRAY_FP64
#define PYCLRAY_FMA_LANE(a, b, c) __builtin_fma(a, b, c)
#else
#define PYCLRAY_FMA_LANE(a, b, c) __builtin_fmaf(a, b, c)
#endif
#if LANES == 1
inline realv v_fma(const realv a, const realv b, const realv c) { return PYCLRAY_FMA_LANE(a, b, c); }
#else
#define PYCLRAY_FMA_OF_LANE(l, s) r.s = PYCLRAY_FMA_LANE(a.s, b.s, c.s);
inline realv v_fma(const realv a, const realv b, const realv c)
{
    realv r;
    PYCLRAY_EACH_LANE(PYCLRAY_FMA_OF_LANE)
    return r;
}
#endif
#else
inline realv v_fma(const realv a, const realv b, const realv c) { return fma(a, b, c); }
#endif

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
inline vec3v v3_abs(const vec3v v) { return v3(v_abs(v.x), v_abs(v.y), v_abs(v.z)); }
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

/* A packet of rays s -> origin + s * dir in the current space; dir need not be unit, a = dir . dir.
 * cast traces one ray at a time (LANES 1; a work-item traces CAST_GROUP of them) from each shape's own anchor (kernels/rays.h) and
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
#ifdef PYCLRAY_PIXEL_EXACT
    /* a camera ray's point (sx, sy, 1) on the image plane as float pairs, sx = x + x_low (x an exact
     * product, x_low its rest: kernels/camera.h), the same in y; and the point's length |(sx, sy, 1)|
     * (dir is the point over it) */
    realv x, x_low, y, y_low, length;
#endif
} RayPacket;

/* SHAPE_SPACE: where the shape functions read a shape from: the kernel's buffers, or in cast the
 * private copy rebased on the ray's origin (kernels/cast.h), in a from-world render the one rebased on the
 * eye (kernels/entries.h) */
#if defined(PYCLRAY_CAST) || defined(PYCLRAY_FROM_WORLD)
#define SHAPE_SPACE
#else
#define SHAPE_SPACE __global
#endif

/* FROM_EYE(ray): whether the packet starts at the space's origin, the eye, where the terms the host
 * computed once in float64 for every camera ray hold (a sphere's c, a plane's h). A render's camera
 * rays always do, and its shadow rays (only compiled with shadows) never; cast rebases every shape on
 * its ray's origin first (kernels/cast.h), so its rays always do: a constant wherever the shape
 * functions are inlined into the kernel. */
#if defined(PYCLRAY_CAST)
#define FROM_EYE(ray) 1  /* each shape is rebased on the ray's own origin (kernels/cast.h) */
#elif defined(PYCLRAY_SHADOWS)
#define FROM_EYE(ray) ((ray)->from_eye)
#else
#define FROM_EYE(ray) 1
#endif

#ifdef PYCLRAY_PIXEL_EXACT
/* Error-free float arithmetic: a + b = s + e exactly, e from Knuth's two-sum (contraction is off,
 * so each rounding is the one written); a b = p + e exactly, e the fused multiply-add a b - p (the
 * rounding error of a product is a float, outside underflow and overflow). */
inline realv pixel_sum_error(const realv a, const realv b, const realv s)
{
    const realv z = s - a;
    return (a - (s - z)) + (b - z);
}

/* Below this |n . d| the fp32 dot product of the rounded space normal and pixel direction, whose
 * error is about eps / |n . d| relative, gives way to pixel_dot's (lane by lane); above it that
 * error is within the error model's flat law
 * (pyclray/reference/error_model.py: FLAT_COS). */
#define PIXEL_EXACT_COS 0.125f

/* n . dir of a camera ray, n = high + low (a shape's unit direction in the camera's space as a float
 * pair from float64: kernels/space.h's to_space and to_space_low), lane by lane: n . (sx, sy, 1)
 * with its two products (fused multiply-adds) and two sums error-free, their errors and the low
 * parts' terms added (small numbers: the pairs' rests, kernels/camera.h; their own roundings,
 * fused too, are far below what the result needs), over the point's length. Within a few roundings of the exact n . d
 * relative to itself, also where the terms cancel (a grazing ray: n . d near 0); that relative
 * error, times the distance, is a flat shape's depth error, where the plain dot product's
 * eps / |n . d| is one of a sideways move. */
inline realv pixel_dot_lanes(const RayPacket* ray, const vec3v high, const vec3v low)
{
    const realv px = high.x * ray->x, py = high.y * ray->y;
    const realv ex = v_fma(high.x, ray->x, -px), ey = v_fma(high.y, ray->y, -py);
    const realv s1 = px + py, s2 = s1 + high.z;
    const realv e1 = pixel_sum_error(px, py, s1), e2 = pixel_sum_error(s1, high.z, s2);
    const realv rest = v_fma(high.x, ray->x_low, v_fma(high.y, ray->y_low, v_fma(low.x, ray->x, v_fma(low.y, ray->y, low.z))));
    return (s2 + (((ex + ey) + (e1 + e2)) + rest)) / ray->length;
}

/* the same for one direction n = high + low (xyz) in every lane */
inline realv pixel_dot(const RayPacket* ray, const real4 high, const real4 low)
{
    return pixel_dot_lanes(ray, v3_splat(high), v3_splat(low));
}

/* n . dir: the plain dot product, or pixel_dot in the lanes of camera rays below PIXEL_EXACT_COS
 * (computed where a packet has any: a lane's bits never depend on the other lanes' rays) */
inline realv pixel_along(const RayPacket* ray, const real4 high, const real4 low, const realv plain)
{
    if (!FROM_EYE(ray)) return plain;
    const intv grazing = v_abs(plain) < SPLAT(PIXEL_EXACT_COS);
    return ANY(grazing) ? (grazing ? pixel_dot(ray, high, low) : plain) : plain;
}
#define PIXEL_DOT(ray, high, low, plain) pixel_along((ray), (high), (low), (plain))
#else
#define PIXEL_DOT(ray, high, low, plain) (plain)
#endif
