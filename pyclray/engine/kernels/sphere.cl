/* Sphere: |p - C|^2 = r^2.
 *
 * With F = C - origin, the ray origin + s*D meets it where a s^2 - 2 b s + c = 0,
 * a = D.D, b = F.D, c = F.F - r^2. For camera rays the origin is the space's origin, so c is the
 * same for every pixel: the host computes it once in float64 with error-free products (it is the
 * eye's squared distance to the surface, exact even for a huge sphere just below the camera).
 */

#if defined(PYCLRAY_REBASE) || defined(PYCLRAY_CAST)

/* The sphere in the camera's space, from its world centre and radius: F = C - origin (float64),
 * its coordinates along the space's axes, r^2, and c = |F|^2 - r^2 from error-free sums. */
inline void sphere_rebase(__global const SphereWorld* world, PYCLRAY_REBASE_OUT Sphere* out, const Space* space)
{
    const double3 F = world->center.xyz - space->origin;
    const double r = world->center.w;
    out->center = (real4)(to_space(space, F), (real)(r * r));
    out->c = (real)dot2_4((double4)(F, r), (double4)(F, -r));
}

#endif

#if !defined(PYCLRAY_REBASE) && !defined(PYCLRAY_CLOSEST)  /* the ray tests (none in the closest-point query) */

/* a shadow ray leaving a sphere's outer side toward the light never meets it again (convex) */
#define PYCLRAY_FLAT_sphere 0


/* F (the centre from the ray's origin), c = |F|^2 - r^2, b = F.D and the discriminant b^2 - a c. */
typedef struct {
    vec3v F;
    realv c, b, disc;
} SphereTerms;

inline SphereTerms sphere_terms(SHAPE_SPACE const Sphere* sphere, const RayPacket* ray)
{
    SphereTerms t;
    const realv r2 = SPLAT(sphere->center.w);
    if (FROM_EYE(ray)) {  /* the ray's origin is the space's: c from the host, exact */
        t.F = v3_splat(sphere->center);
        t.c = SPLAT(sphere->c);
    } else {  /* a shadow ray from a point p of the scene */
        t.F = v3_sub(v3_splat(sphere->center), ray->origin);
        /* c = |F|^2 - r^2 taken directly rounds terms of size |F|^2 + r^2: eps r^2 for a huge
         * sphere, a position error of eps r (a unit at r = 1e6); moved from the eye's exact c,
         * c_eye - p.(C + F), it rounds terms of size |c_eye| + |p| |C + F|, a position error of
         * about eps |p| |C| / r (a huge sphere's). Each lane takes the form whose terms are smaller:
         * either way about eps (|p| + min(r, |p| |C| / r)) <= 2 eps |p| where |p| >= r. */
        const vec3v sum = v3_add(v3_splat(sphere->center), t.F);
        const realv moved = SPLAT(sphere->c) - v3_dot(ray->origin, sum);
        const realv direct = v3_dot(t.F, t.F) - r2;
        const realv moved_size = v_abs(SPLAT(sphere->c)) + v3_dot(v3_abs(ray->origin), v3_abs(sum));
        t.c = moved_size < v3_dot(t.F, t.F) + r2 ? moved : direct;
    }
    const vec3v D = ray->dir;
    const realv a = ray->a;
    t.b = v3_dot(t.F, D);
    const vec3v FxD = v3_cross(t.F, D);
    const realv perp2 = v3_dot(FxD, FxD);
    /* b^2 - a c = a r^2 - |F x D|^2 (Lagrange's identity). The first form cancels when the sphere
     * is small and far (b^2 ~ a c), the second when it is huge and near (a r^2 ~ |F x D|^2):
     * take the one whose rounding error bound, the size of its terms, is smaller. */
    const realv ac = a * t.c;
    const intv from_b = t.b * t.b + v_abs(ac) < a * r2 + perp2;
    t.disc = from_b ? t.b * t.b - ac : a * r2 - perp2;
    return t;
}

/* Nearest root s > 0 per lane, or MISS. */
inline realv sphere_hit(SHAPE_SPACE const Sphere* sphere, const RayPacket* ray)
{
#if !defined(PYCLRAY_FROM_WORLD) && !defined(PYCLRAY_CAST)
    /* From the eye with the per-view pass's entry, c is read, not computed: a packet whose b^2 - a c
     * < -2^-10 (b^2 + |a c|) in every lane misses (five products instead of the cross product's
     * twelve below; docs/benchmarks.md, "Why the engine does what it does"). sphere_terms takes b^2 - a c there (the
     * same b and a c, within a few eps (b^2 + |a c|) of a contraction into an fma), or a r^2 - |F x D|^2
     * only where its terms are smaller, a r^2 + |F x D|^2 < b^2 + |a c|: that form differs from b^2 - a c
     * (Lagrange's identity) by the roundings of F, c and its own, a few eps (a |F|^2 + a r^2) = a few
     * eps (b^2 + |F x D|^2 + a r^2) <= a few eps 2 (b^2 + |a c|). Either form is negative: a miss. */
    if (FROM_EYE(ray)) {
        const realv b = v3_dot(v3_splat(sphere->center), ray->dir);
        const realv b2 = b * b, ac = ray->a * SPLAT(sphere->c);
        if (!ANY(b2 - ac >= SPLAT(-0x1p-10) * (b2 + v_abs(ac)))) return SPLAT(MISS);
    } else
#endif
    /* A packet that passes far from the sphere misses it without c (a from-world render's costliest
     * term): where a r^2 - |F x D|^2 < -2^-10 (a r^2 + |F x D|^2 + b^2) in every lane, b^2 - a c,
     * the same quantity (Lagrange's identity) computed from c within rounding errors of a few eps
     * (a r^2 + a |F|^2) = a few eps (a r^2 + |F x D|^2 + b^2) (c's chosen form has terms of at most
     * |F|^2 + r^2, see sphere_terms), is negative too: both forms miss in every lane. */
    {
        const vec3v F = FROM_EYE(ray) ? v3_splat(sphere->center) : v3_sub(v3_splat(sphere->center), ray->origin);
        const realv a_r2 = ray->a * SPLAT(sphere->center.w);
        const vec3v FxD = v3_cross(F, ray->dir);
        const realv perp2 = v3_dot(FxD, FxD), b = v3_dot(F, ray->dir);
        if (!ANY(a_r2 - perp2 >= SPLAT(-0x1p-10) * ((a_r2 + perp2) + b * b))) return SPLAT(MISS);
    }
    const SphereTerms t = sphere_terms(sphere, ray);
    /* stable roots: q = b + sign(b) sqrt(disc) never cancels; the roots are c/q and q/a
     * (NaN in the lanes with disc < 0, which miss below) */
    const realv q = t.b + v_copysign(v_sqrt(t.disc), t.b);
    const realv s_q = q / ray->a, s_c = t.c / q;
    const realv near = v_min(s_q, s_c), far = v_max(s_q, s_c);
    const realv s = near > 0 ? near : (far > 0 ? far : SPLAT(MISS));
    /* q == 0: a tangent ray from a point on the surface */
    return (t.disc >= 0 && q != 0) ? s : SPLAT(MISS);
}

/* Outward unit world-space normal at the hit. p - C = s D - F is computed from the
 * perpendicular, a (p - C) = +-sqrt(disc) D - D x (F x D), which never subtracts two large
 * nearly equal vectors, so a far sphere's normal keeps its digits. The sign needs no root: from
 * outside (c > 0) a ray hits the near side, b - sqrt(disc); from inside or on the surface
 * (c <= 0) only the far root is positive, b + sqrt(disc). */
inline vec3v sphere_normal(SHAPE_SPACE const Sphere* sphere, const RayPacket* ray, const Basis* basis)
{
    const SphereTerms t = sphere_terms(sphere, ray);
    const vec3v D = ray->dir;
    const realv side = t.c > 0 ? SPLAT(-1) : SPLAT(1);
    const vec3v n = v3_sub(v3_scale(D, side * v_sqrt(t.disc)), v3_cross(D, v3_cross(t.F, D)));
    return world_from_basis(basis, v3_normalize(n));
}

#ifdef PYCLRAY_ALL_HITS
/* Every hit s > 0 along the ray (count_hits, all_hits: kernels/allhits.cl): both roots where the
 * ray crosses the sphere (disc > 0), none where it misses or only touches it (disc <= 0: a tangent
 * ray counts 0, never 1); a root <= 0 (behind the origin, or from inside) is MISS. */
inline void sphere_hits(SHAPE_SPACE const Sphere* sphere, const RayPacket* ray, realv* first, realv* second)
{
    const SphereTerms t = sphere_terms(sphere, ray);
    const realv q = t.b + v_copysign(v_sqrt(t.disc), t.b);
    const realv s_q = q / ray->a, s_c = t.c / q;
    const realv near = v_min(s_q, s_c), far = v_max(s_q, s_c);
    const intv crosses = t.disc > 0 && q != 0;
    *first = crosses && near > 0 ? near : SPLAT(MISS);
    *second = crosses && far > 0 ? far : SPLAT(MISS);
}
#endif

#endif

#ifdef PYCLRAY_CLOSEST
/* The sphere's nearest point: C + r (p - C) / |p - C| (the centre itself: any point, the pole
 * along +z); d2 = (|p - C| - r)^2, which rounds less than |p - q|^2 near the surface. */
inline ClosestPoint sphere_closest(__global const SphereWorld* world, const double3 p)
{
    const double3 F = p - world->center.xyz;
    const double r = world->center.w, length = sqrt(closest_norm2(F));
    const double3 n = length > 0.0 ? F / length : (double3)(0.0, 0.0, 1.0);
    ClosestPoint c = closest_at(p, world->center.xyz + r * n, n);
    c.d2 = (length - r) * (length - r);
    return c;
}

inline int sphere_inside(__global const SphereWorld* world, const double3 p)
{
    const double3 F = p - world->center.xyz;
    const double r = world->center.w;
    return closest_norm2(F) <= r * r;
}
#endif
