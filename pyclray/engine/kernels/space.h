/* The space of a view (render) or of the per-view pass (kernels/rebase.cl): its origin, the eye, and
 * its axes, the camera's; and the float64 helpers that the shapes' <type>_rebase rebase a world entry
 * with (error-free products and sums, as pyclray.model.exact on the host). The host puts it before
 * the shapes' files with FP_CONTRACT OFF in force: each rounding is the one written, so that a shape
 * rebased here has the same bits as on the host (pyclray.model.shapes.base.in_space, exact.dot2). */

typedef struct {
    double3 origin;  /* the eye (render) */
    double3 u, v, w; /* the space's axes in world coordinates (rows of space_from_world) */
} Space;

/* a vector's coordinates along the space's axes, rounded to the kernel's precision: per axis
 * (u.x x.x + u.y x.y) + u.z x.z (pyclray.model.shapes.base.in_space), written by the space's columns,
 * three vector products and two sums with the same roundings (a from-world render rebases at each test) */
inline double3 space_coordinates(const Space* space, const double3 x)
{
    const double3 c0 = (double3)(space->u.x, space->v.x, space->w.x);
    const double3 c1 = (double3)(space->u.y, space->v.y, space->w.y);
    const double3 c2 = (double3)(space->u.z, space->v.z, space->w.z);
    return (c0 * x.x + c1 * x.y) + c2 * x.z;
}

inline real3 to_space(const Space* space, const double3 x) { return convert_real3(space_coordinates(space, x)); }

/* what to_space's rounding left out (its float64 coordinates minus their rounding, itself rounded):
 * with to_space, a unit direction of a flat shape as a float pair for the fp32 camera rays' exact
 * n . d (kernels/lanes.h: pixel_dot; pyclray.model.shapes.device.in_space_low); 0 in fp64 */
inline real3 to_space_low(const Space* space, const double3 x)
{
    const double3 f = space_coordinates(space, x);
    return convert_real3(f - convert_double3(convert_real3(f)));
}

/* a b = p + e exactly (pyclray.model.exact.two_prod): on PoCL's CPU device with the fused multiply-add
 * (clang's own: PoCL's library fma is a call, which LLVM does not inline there), else Dekker's
 * product with his splitter 2^27 + 1, the host's: the same e either way, exact, for every product
 * whose parts neither overflow nor underflow (a from-world render tests shapes with it at each visit,
 * where the fused form costs a fifth of Dekker's) */
inline double2 two_prod(const double a, const double b)
{
    const double p = a * b;
#ifdef PYCLRAY_INLINE_BUILTINS
    return (double2)(p, __builtin_fma(a, b, -p));
#else
    double t = 134217729.0 * a;
    const double a_hi = t - (t - a), a_lo = a - a_hi;
    t = 134217729.0 * b;
    const double b_hi = t - (t - b), b_lo = b - b_hi;
    return (double2)(p, ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo);
#endif
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
