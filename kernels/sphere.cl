/* Sphere: |p - C|^2 = r^2.
 *
 * With F = C - origin, the ray origin + s*D meets it where a s^2 - 2 b s + c = 0,
 * a = D.D, b = F.D, c = F.F - r^2. For camera rays the origin is the frame's origin, so c is the
 * same for every pixel: the host computes it once in float64 with error-free products (it is the
 * eye's squared distance to the surface, exact even for a huge sphere just below the camera).
 */

/* Nearest root s > 0 (or MISS) and which root it is: side = -1 near, +1 far. */
inline real sphere_solve(__global const Sphere* sphere, const Ray* ray, real* root_sign, real* discriminant)
{
    const real3 F = sphere->center.xyz - ray->origin;
    const real r2 = sphere->center.w;
#ifdef PYCLRAY_CAST
    const real c = dot(F, F) - r2;
#else
    const real c = sphere->c;
#endif
    const real3 D = ray->dir;
    const real a = ray->a;
    const real b = dot(F, D);
    const real3 FxD = cross(F, D);
    const real perp2 = dot(FxD, FxD);
    /* b^2 - a c = a r^2 - |F x D|^2 (Lagrange's identity). The first form cancels when the sphere
     * is small and far (b^2 ~ a c), the second when it is huge and near (a r^2 ~ |F x D|^2):
     * take the one whose rounding error bound, the size of its terms, is smaller. */
    const real ac = a * c;
    const bool from_b = b * b + fabs(ac) < a * r2 + perp2;
    const real disc = from_b ? b * b - ac : a * r2 - perp2;
    *discriminant = disc;
    if (!(disc >= 0)) return MISS;
    /* stable roots: q = b + sign(b) sqrt(disc) never cancels; the roots are c/q and q/a */
    const real q = b + copysign(sqrt(disc), b);
    if (q == 0) return MISS;  /* tangent ray from a point on the surface */
    const real s_q = q / a, s_c = c / q;
    const real near = fmin(s_q, s_c), far = fmax(s_q, s_c);
    /* the near root is b - sqrt(disc) over a, the far one b + sqrt(disc) over a */
    if (near > 0) { *root_sign = -1; return near; }
    if (far > 0) { *root_sign = 1; return far; }
    return MISS;
}

inline real sphere_hit(__global const Sphere* sphere, const Ray* ray)
{
    real side, disc;
    return sphere_solve(sphere, ray, &side, &disc);
}

/* Outward unit world-space normal at the hit. p - C = s D - F is computed from the
 * perpendicular, a (p - C) = +-sqrt(disc) D - D x (F x D), which never subtracts two large
 * nearly equal vectors, so a far sphere's normal keeps its digits. */
inline real3 sphere_normal(__global const Sphere* sphere, const Ray* ray, __global const Camera* camera)
{
    real side, disc;
    sphere_solve(sphere, ray, &side, &disc);
    const real3 F = sphere->center.xyz - ray->origin;
    const real3 D = ray->dir;
    return world_from_frame(camera, normalize(side * sqrt(disc) * D - cross(D, cross(F, D))));
}
