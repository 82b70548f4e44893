/* Cylinder: the points within r of the segment p0-p1 (unit axis A, length H), closed by two caps
 * or open.
 *
 * Side. With F = p0 - origin, the ray origin + s D meets the infinite tube where
 * |s D_perp - F_perp|^2 = r^2 (perp: the part across the axis), a s^2 - 2 b s + c = 0 with
 * a = |D x A|^2, b = (F x A) . (D x A), c = |F x A|^2 - r^2: cross products instead of D - (D.A) A,
 * which cancels for rays along the axis. For camera rays c is the eye's squared distance from the
 * axis minus r^2, the same for every pixel: the host computes it once with error-free float64 sums.
 * The discriminant b^2 - a c equals a r^2 - (F . (D x A))^2 (Lagrange's identity across the axis);
 * as for the sphere, the kernel takes the form whose terms are smaller, and the stable roots c/q
 * and q/a with q = b + sign(b) sqrt(disc). A root is on the side where its axial coordinate
 * s (D . A) - d0 lies in [0, H], i.e. d0 <= s (D . A) <= d1, with d0, d1 = (p0 - o) . A, (p1 - o) . A
 * (exact from the host for camera rays).
 * Caps. The planes through p0 and p1 across the axis: s = d0 / (D . A) and d1 / (D . A); a hit
 * where the point's distance from the axis, |s (D x A) - F x A|, is at most r.
 * The nearest of the four candidates with s > 0 wins (from inside the solid: the far side). */

typedef struct {
    real3 FxA, DxA;
    real a, b, c, disc, triple, near, far, cap0, cap1;
} CylinderTerms;

inline CylinderTerms cylinder_terms(__global const Cylinder* cylinder, const Ray* ray)
{
    CylinderTerms t;
    const real3 A = cylinder->axis.xyz;
    const real3 F = cylinder->p0.xyz - ray->origin;
    const real3 D = ray->dir;
    const real r2 = cylinder->p0.w;
    t.FxA = cross(F, A);
    t.DxA = cross(D, A);
#ifdef PYCLRAY_CAST
    t.c = dot(t.FxA, t.FxA) - r2;
    const real d0 = dot(F, A), d1 = dot(cylinder->p1.xyz - ray->origin, A);
#else
    t.c = cylinder->axis.w;
    const real d0 = cylinder->world_axis.w, d1 = cylinder->d1;
#endif
    t.a = dot(t.DxA, t.DxA);
    t.b = dot(t.FxA, t.DxA);
    t.triple = dot(F, t.DxA);
    const real perp2 = t.triple * t.triple;
    const real ac = t.a * t.c;
    const bool from_b = t.b * t.b + fabs(ac) < t.a * r2 + perp2;
    t.disc = from_b ? t.b * t.b - ac : t.a * r2 - perp2;
    const real dA = dot(D, A);
    /* side: the stable roots, kept where they lie between the end planes */
    const real q = t.b + copysign(sqrt(t.disc), t.b);
    const real s_q = q / t.a, s_c = t.c / q;
    const real near = fmin(s_q, s_c), far = fmax(s_q, s_c);
    const bool side = t.disc >= 0;
    t.near = (side && d0 <= near * dA && near * dA <= d1) ? near : MISS;
    t.far = (side && d0 <= far * dA && far * dA <= d1) ? far : MISS;
    /* caps: the end planes, kept within r of the axis */
    const real s0 = d0 / dA, s1 = d1 / dA;
    const real3 R0 = s0 * t.DxA - t.FxA, R1 = s1 * t.DxA - t.FxA;
    t.cap0 = (cylinder->caps && dot(R0, R0) <= r2) ? s0 : MISS;
    t.cap1 = (cylinder->caps && dot(R1, R1) <= r2) ? s1 : MISS;
    return t;
}

/* which candidate wins: 0 none, 1 side (near root), 2 side (far root), 3 cap p0, 4 cap p1 */
inline int cylinder_winner(const CylinderTerms* t, real* best)
{
    int kind = 0;
    *best = MISS;
    /* NaN (0 / 0 of a ray along the axis, or in a cap plane) and +-inf are never below MISS */
    if (t->near > 0 && t->near < *best) { *best = t->near; kind = 1; }
    if (t->far > 0 && t->far < *best) { *best = t->far; kind = 2; }
    if (t->cap0 > 0 && t->cap0 < *best) { *best = t->cap0; kind = 3; }
    if (t->cap1 > 0 && t->cap1 < *best) { *best = t->cap1; kind = 4; }
    return kind;
}

inline real cylinder_hit(__global const Cylinder* cylinder, const Ray* ray)
{
    const CylinderTerms t = cylinder_terms(cylinder, ray);
    real best;
    cylinder_winner(&t, &best);
    return best;
}

/* The outward unit normal in world space. On a cap: the axis out of the solid (packed in world
 * space, exact). On the side: the hit's offset from the axis R, from the perpendicular without
 * subtracting large nearly equal vectors, as for the sphere: a R = -+sqrt(disc) D_perp - triple (D x A)
 * (near root: -, far root: +), D_perp = A x (D x A); the open tube's inner side has the same
 * outward normal. */
inline real3 cylinder_normal(__global const Cylinder* cylinder, const Ray* ray, __global const Camera* camera)
{
    const CylinderTerms t = cylinder_terms(cylinder, ray);
    real best;
    const int kind = cylinder_winner(&t, &best);
    if (kind >= 3) return (kind == 3 ? (real)-1 : (real)1) * cylinder->world_axis.xyz;
    const real side = kind == 1 ? (real)-1 : (real)1;
    const real3 D_perp = cross(cylinder->axis.xyz, t.DxA);
    return world_from_frame(camera, normalize(side * sqrt(t.disc) * D_perp - t.triple * t.DxA));
}
