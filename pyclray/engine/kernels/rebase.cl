/* The scene's per-view pass (pyclray/engine/prepared.py): the world's float64 entries rebased into the
 * frame of a camera, one work-item per entry, so that a moved camera uploads only itself and the
 * kernels keep testing shapes in the camera's frame. The host puts before this file common.h, the
 * generated struct header and each present shape type's file (with PYCLRAY_REBASE: their
 * <type>_rebase only), which use the helpers below; each type gets its kernel rebase_<type>.
 *
 * The differences of world coordinates are taken in float64 before anything is rounded to the
 * kernel's precision, and what every ray from the frame's origin shares (a sphere's c, a plane's
 * offset, a box's slab offsets) from error-free products and sums (Ogita, Rump and Oishi 2005), as
 * pyclray.model.exact does on the host: the same float64 numbers, bit for bit, as the host's
 * rebase (its two_prod is Dekker's, exact as fma's is). No contraction of a * b + c into an fma:
 * each rounding is the one written. */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

/* the per-view pass writes each frame entry to its buffer (cast frames into private copies: cast.h) */
#define PYCLRAY_FRAME_OUT __global

typedef struct {
    double3 origin;  /* the eye (render) */
    double3 u, v, w; /* the frame's axes in world coordinates (rows of frame_from_world) */
} Frame;

/* a vector's coordinates along the frame's axes, rounded to the kernel's precision */
inline real3 to_frame(const Frame* frame, const double3 x)
{
    return convert_real3((double3)((frame->u.x * x.x + frame->u.y * x.y) + frame->u.z * x.z,
                                   (frame->v.x * x.x + frame->v.y * x.y) + frame->v.z * x.z,
                                   (frame->w.x * x.x + frame->w.y * x.y) + frame->w.z * x.z));
}

/* a b = p + e exactly: Dekker's product, with his splitter 2^27 + 1 (pyclray.model.exact.two_prod;
 * fma(a, b, -p) gives the same e, but is a call into PoCL's library, which LLVM does not inline) */
inline double2 two_prod(const double a, const double b)
{
    const double p = a * b;
    double t = 134217729.0 * a;
    const double a_hi = t - (t - a), a_lo = a - a_hi;
    t = 134217729.0 * b;
    const double b_hi = t - (t - b), b_lo = b - b_hi;
    return (double2)(p, ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo);
}

/* a + b = s + e exactly */
inline double2 two_sum(const double a, const double b)
{
    const double s = a + b, z = s - a;
    return (double2)(s, (a - (s - z)) + (b - z));
}

/* sum x_k y_k as accurate as in twice float64's precision (pyclray.model.exact.dot2, term by term) */
#define PYCLRAY_DOT2_BEGIN(x0, y0) double2 acc = two_prod(x0, y0); double p = acc.x, s = acc.y;
#define PYCLRAY_DOT2_TERM(xk, yk) { const double2 h = two_prod(xk, yk); const double2 q = two_sum(p, h.x); p = q.x; s = s + (q.y + h.y); }

inline double dot2_3(const double3 x, const double3 y)
{
    PYCLRAY_DOT2_BEGIN(x.x, y.x)
    PYCLRAY_DOT2_TERM(x.y, y.y)
    PYCLRAY_DOT2_TERM(x.z, y.z)
    return p + s;
}

inline double dot2_4(const double4 x, const double4 y)
{
    PYCLRAY_DOT2_BEGIN(x.x, y.x)
    PYCLRAY_DOT2_TERM(x.y, y.y)
    PYCLRAY_DOT2_TERM(x.z, y.z)
    PYCLRAY_DOT2_TERM(x.w, y.w)
    return p + s;
}

/* |F x A|^2 - r^2 as accurate as in twice float64's precision (pyclray.model.exact.cross_norm2_minus):
 * each component of F x A is an exact sum of four terms (two error-free products); the sum of all
 * their pairwise products, component by component, and -r^2 goes through dot2, in the host's order */
inline double cross_norm2_minus(const double3 F, const double3 A, const double r)
{
    double terms[3][4];
    const double Fv[3] = {F.x, F.y, F.z}, Av[3] = {A.x, A.y, A.z};
    const int I[3] = {1, 2, 0}, J[3] = {2, 0, 1};
    for (int c = 0; c < 3; ++c) {
        const double2 t1 = two_prod(Fv[I[c]], Av[J[c]]), t2 = two_prod(Fv[J[c]], Av[I[c]]);
        terms[c][0] = t1.x;
        terms[c][1] = t1.y;
        terms[c][2] = -t2.x;
        terms[c][3] = -t2.y;
    }
    PYCLRAY_DOT2_BEGIN(terms[0][0], terms[0][0])
    for (int n = 1; n < 48; ++n) {
        const int c = n / 16, a = (n / 4) % 4, b = n % 4;
        PYCLRAY_DOT2_TERM(terms[c][a], terms[c][b])
    }
    PYCLRAY_DOT2_TERM(r, -r)
    return p + s;
}
