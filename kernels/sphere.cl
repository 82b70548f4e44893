/* Sphere: |p - C|^2 = r^2.
 *
 * With F = C - origin, the ray origin + s*D meets it where a s^2 - 2 b s + c = 0,
 * a = D.D, b = F.D, c = F.F - r^2. For camera rays the origin is the frame's origin, so c is the
 * same for every pixel: the host computes it once in float64 with error-free products (it is the
 * eye's squared distance to the surface, exact even for a huge sphere just below the camera).
 */

/* F (the centre from the ray's origin), c = |F|^2 - r^2, b = F.D and the discriminant b^2 - a c. */
typedef struct {
    real3 F;
    real c, b, disc;
} SphereTerms;

inline SphereTerms sphere_terms(__global const Sphere* sphere, const Ray* ray)
{
    SphereTerms t;
    t.F = sphere->center.xyz - ray->origin;
    const real r2 = sphere->center.w;
#ifdef PYCLRAY_CAST
    t.c = dot(t.F, t.F) - r2;
#else
    t.c = sphere->c;
#endif
    const real3 D = ray->dir;
    const real a = ray->a;
    t.b = dot(t.F, D);
    const real3 FxD = cross(t.F, D);
    const real perp2 = dot(FxD, FxD);
    /* b^2 - a c = a r^2 - |F x D|^2 (Lagrange's identity). The first form cancels when the sphere
     * is small and far (b^2 ~ a c), the second when it is huge and near (a r^2 ~ |F x D|^2):
     * take the one whose rounding error bound, the size of its terms, is smaller. */
    const real ac = a * t.c;
    const bool from_b = t.b * t.b + fabs(ac) < a * r2 + perp2;
    t.disc = from_b ? t.b * t.b - ac : a * r2 - perp2;
    return t;
}

/* Nearest root s > 0, or MISS. */
inline real sphere_hit(__global const Sphere* sphere, const Ray* ray)
{
    const SphereTerms t = sphere_terms(sphere, ray);
    if (!(t.disc >= 0)) return MISS;
    /* stable roots: q = b + sign(b) sqrt(disc) never cancels; the roots are c/q and q/a */
    const real q = t.b + copysign(sqrt(t.disc), t.b);
    if (q == 0) return MISS;  /* tangent ray from a point on the surface */
    const real s_q = q / ray->a, s_c = t.c / q;
    const real near = fmin(s_q, s_c), far = fmax(s_q, s_c);
    return near > 0 ? near : (far > 0 ? far : MISS);
}

/* Outward unit world-space normal at the hit. p - C = s D - F is computed from the
 * perpendicular, a (p - C) = +-sqrt(disc) D - D x (F x D), which never subtracts two large
 * nearly equal vectors, so a far sphere's normal keeps its digits. The sign needs no root: from
 * outside (c > 0) a ray hits the near side, b - sqrt(disc); from inside or on the surface
 * (c <= 0) only the far root is positive, b + sqrt(disc). */
inline real3 sphere_normal(__global const Sphere* sphere, const Ray* ray, __global const Camera* camera)
{
    const SphereTerms t = sphere_terms(sphere, ray);
    const real3 D = ray->dir;
    const real side = t.c > 0 ? (real)-1 : (real)1;
    return world_from_frame(camera, normalize(side * sqrt(t.disc) * D - cross(D, cross(t.F, D))));
}
