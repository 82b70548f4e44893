/* Cylinder: the points within r of the segment p0-p1 (unit axis A), closed by two caps or open.
 *
 * Side. With F = p0 - origin, the ray origin + s D meets the infinite tube where
 * |s D_perp - F_perp|^2 = r^2 (perp: the part across the axis), a s^2 - 2 b s + c = 0 with
 * a = |D x A|^2, b = (F x A) . (D x A), c = |F x A|^2 - r^2: cross products instead of D - (D.A) A,
 * which cancels for rays along the axis. For camera rays c is the eye's squared distance from the
 * axis minus r^2, the same for every pixel: the host computes it once with error-free float64 sums.
 * The discriminant b^2 - a c equals a r^2 - (F . (D x A))^2 (Lagrange's identity across the axis);
 * as for the sphere, the kernel takes the form whose terms are smaller, and the stable roots c/q
 * and q/a with q = b + sign(b) sqrt(disc). A root is on the side where its axial coordinate lies
 * in [0, |p1 - p0|].
 * Caps. The planes through p0 and p1 across the axis: s = d0 / (D . A) and d1 / (D . A), with
 * d0, d1 = (p0 - o) . A, (p1 - o) . A exact from the host for camera rays; a hit where the point is
 * within r of the cap's centre.
 * The nearest of the four candidates with s > 0 wins (from inside the solid: the far side). */

#if defined(PYCLRAY_REBASE) || defined(PYCLRAY_CAST)

/* The cylinder in the camera's space: both ends and the axis along the space's axes, and what every
 * ray from the space's origin shares, from error-free products and sums: c = |(p0 - o) x A|^2 - r^2,
 * d0 = (p0 - o) . A and d1 = (p1 - o) . A. */
inline void cylinder_rebase(__global const CylinderWorld* world, PYCLRAY_REBASE_OUT Cylinder* out, const Space* space)
{
    const double3 p0 = world->p0.xyz - space->origin, p1 = world->p1.xyz - space->origin, A = world->axis.xyz;
    const double r = world->p0.w;
    out->p0 = (real4)(to_space(space, p0), (real)(r * r));
    out->p1 = (real4)(to_space(space, p1), (real)world->p1.w);
    out->axis = (real4)(to_space(space, A), (real)cross_norm2_minus(p0, A, r));
    out->axis_low = (real4)(to_space_low(space, A), 0);
    out->world_axis = (real4)(convert_real3(A), (real)dot2_3(p0, A));
    out->d1 = (real)dot2_3(p1, A);
    out->caps = world->caps;
}

#endif

#if !defined(PYCLRAY_REBASE) && !defined(PYCLRAY_CLOSEST)  /* the ray tests (none in the closest-point query) */

/* leaving the outer side of the tube or a cap toward the light never meets it again (convex);
 * its inner side may (the opposite wall) */
#define PYCLRAY_FLAT_cylinder 0


typedef struct {
    vec3v DxA;
    realv disc, triple;
    realv best, best_key;
    intv kind;  /* the winner: 0 none, 1 side (near root), 2 side (far root), 3 cap p0, 4 cap p1 */
} CylinderHit;

/* a candidate s, kept where it is a hit ahead and nearer than the best so far by its key (the
 * first on a tie; NaN, of a ray along the axis or in a cap's plane, and +-inf never are) */
inline void cylinder_candidate(CylinderHit* hit, const realv s, const realv key, const intv on_surface, const int kind)
{
    const intv nearer = on_surface && s > 0 && s < MISS && key < hit->best_key;
    hit->best = nearer ? s : hit->best;
    hit->best_key = nearer ? key : hit->best_key;
    hit->kind = nearer ? SPLAT_INT(kind) : hit->kind;
}

inline CylinderHit cylinder_intersect(SHAPE_SPACE const Cylinder* cylinder, const RayPacket* ray)
{
    CylinderHit hit;
    const vec3v A = v3_splat(cylinder->axis);
    const vec3v D = ray->dir;
    const realv r2 = SPLAT(cylinder->p0.w);
    vec3v F, FxA;
    realv c, d0, d1;
    if (FROM_EYE(ray)) {  /* the ray's origin is the space's: the host's terms */
        F = v3_splat(cylinder->p0);
        FxA = v3_cross(F, A);
        c = SPLAT(cylinder->axis.w);
        d0 = SPLAT(cylinder->world_axis.w);
        d1 = SPLAT(cylinder->d1);
    } else {  /* shadow rays, from a point p of the scene */
        F = v3_sub(v3_splat(cylinder->p0), ray->origin);
        FxA = v3_cross(F, A);
        /* c = |F x A|^2 - r^2 directly, or moved from the eye's exact c, c_eye - (p x A).(p0 x A + F x A):
         * the form whose terms are smaller, as for the sphere (kernels/sphere.cl) */
        const vec3v pxA = v3_cross(ray->origin, A), sum = v3_add(v3_cross(v3_splat(cylinder->p0), A), FxA);
        const realv moved = SPLAT(cylinder->axis.w) - v3_dot(pxA, sum);
        const realv moved_size = v_abs(SPLAT(cylinder->axis.w)) + v3_dot(v3_abs(pxA), v3_abs(sum));
        c = moved_size < v3_dot(FxA, FxA) + r2 ? moved : v3_dot(FxA, FxA) - r2;
        d0 = v3_dot(F, A);
        d1 = v3_dot(v3_sub(v3_splat(cylinder->p1), ray->origin), A);
    }
    hit.DxA = v3_cross(D, A);
    const realv a = v3_dot(hit.DxA, hit.DxA);
    const realv b = v3_dot(FxA, hit.DxA);
    hit.triple = v3_dot(F, hit.DxA);
    const realv perp2 = hit.triple * hit.triple;
    const realv ac = a * c;
    const intv from_b = b * b + v_abs(ac) < a * r2 + perp2;
    hit.disc = from_b ? b * b - ac : a * r2 - perp2;
    const realv dA = PIXEL_DOT(ray, cylinder->axis, cylinder->axis_low, v3_dot(D, A));  /* exact for camera rays: a grazing cap */
    hit.best = hit.best_key = SPLAT(MISS);
    hit.kind = SPLAT_INT(0);
    /* side: the stable roots (NaN where disc < 0), kept between the end planes. A root's axial
     * coordinate from p0, s (D . A) - d0, cancels for a far cylinder (both terms large); from the
     * ray's point nearest the axis it is z* -+ sqrt(disc) (D . A) / a, z* = -A . (D x (F x D)) / a,
     * whose cross products keep the camera space's digits, but which cancels for a ray along the
     * axis (a small). Each lane takes the form whose terms are smaller. */
    const realv q = b + v_copysign(v_sqrt(hit.disc), b);
    const realv s_q = q / a, s_c = c / q;
    const realv near = s_q < s_c ? s_q : s_c, far = s_q < s_c ? s_c : s_q;
    const realv z_star = -v3_dot(A, v3_cross(D, v3_cross(F, D))) / a;
    const realv spread = v_sqrt(hit.disc) * dA / a;
    const realv length = SPLAT(cylinder->p1.w);
    const intv from_nearest = v_abs(z_star) + v_abs(spread) < v_abs(near * dA) + v_abs(d0);
    const realv z_near = from_nearest ? z_star - spread : near * dA - d0;
    const realv z_far = from_nearest ? z_star + spread : far * dA - d0;
    const intv tube = hit.disc >= 0;
    /* Which candidate is nearest is decided, where z* is well conditioned, on their offsets from
     * the ray's point nearest the axis (small numbers: -+sqrt(disc) / a for the side,
     * -z* / (D . A) and (length - z*) / (D . A) for the caps), not on their distances, which for a
     * far cylinder are large numbers whose rounding would mix up a cap and the side near the rim. */
    const realv root_offset = v_sqrt(hit.disc) / a;
    cylinder_candidate(&hit, near, from_nearest ? -root_offset : near, tube && z_near >= 0 && z_near <= length, 1);
    cylinder_candidate(&hit, far, from_nearest ? root_offset : far, tube && z_far >= 0 && z_far <= length, 2);
    /* caps: the end planes, kept where the hit point is within r of the cap's centre; that point
     * is A x (D x F_end) / (A . D) from it (see kernels/disk.cl), not s D - F_end */
    if (cylinder->caps) {
        const vec3v F1 = FROM_EYE(ray) ? v3_splat(cylinder->p1) : v3_sub(v3_splat(cylinder->p1), ray->origin);
        const realv s0 = d0 / dA, s1 = d1 / dA;
        const vec3v R0 = v3_cross(A, v3_cross(D, F)), R1 = v3_cross(A, v3_cross(D, F1));
        cylinder_candidate(&hit, s0, from_nearest ? -z_star / dA : s0, v3_dot(R0, R0) <= r2 * dA * dA, 3);
        cylinder_candidate(&hit, s1, from_nearest ? (length - z_star) / dA : s1, v3_dot(R1, R1) <= r2 * dA * dA, 4);
    }
    return hit;
}

inline realv cylinder_hit(SHAPE_SPACE const Cylinder* cylinder, const RayPacket* ray)
{
    return cylinder_intersect(cylinder, ray).best;
}

/* The outward unit normal in world space. On a cap: the axis out of the solid (packed in world
 * space, exact). On the side: the hit's offset from the axis R, from the perpendicular without
 * subtracting large nearly equal vectors, as for the sphere: a R = -+sqrt(disc) D_perp - triple (D x A)
 * (near root: -, far root: +), D_perp = A x (D x A); the open tube's inner side has the same
 * outward normal. */
inline vec3v cylinder_normal(SHAPE_SPACE const Cylinder* cylinder, const RayPacket* ray, const Basis* basis)
{
    const CylinderHit hit = cylinder_intersect(cylinder, ray);
    const realv side = hit.kind == SPLAT_INT(1) ? SPLAT(-1) : SPLAT(1);
    const vec3v D_perp = v3_cross(v3_splat(cylinder->axis), hit.DxA);
    const vec3v radial = v3_sub(v3_scale(D_perp, side * v_sqrt(hit.disc)), v3_scale(hit.DxA, hit.triple));
    const vec3v outward = world_from_basis(basis, v3_normalize(radial));
    const vec3v axis = v3_splat(cylinder->world_axis);
    const vec3v cap = v3_scale(axis, hit.kind == SPLAT_INT(3) ? SPLAT(-1) : SPLAT(1));
    return v3_select(outward, cap, hit.kind >= SPLAT_INT(3));
}

#ifdef PYCLRAY_ALL_HITS
/* Every hit s > 0 along the ray (count_hits, all_hits: kernels/allhits.cl), from the ray's origin
 * (cast's space: FROM_EYE). Capped: the solid is convex, the points within r of the axis (between
 * the side's roots, everywhere for a ray along the axis inside it) and between the end planes (the
 * caps' distances, everywhere for a ray parallel to them between them): the entry and exit of
 * those two intervals' overlap where entry < exit, else none (a ray grazing the side or a rim
 * counts 0, never 1). Open tube: each side root whose point lies between the end planes. */
inline void cylinder_hits(SHAPE_SPACE const Cylinder* cylinder, const RayPacket* ray, realv* first, realv* second)
{
    const CylinderHit hit = cylinder_intersect(cylinder, ray);
    const vec3v A = v3_splat(cylinder->axis), D = ray->dir;
    const realv c = SPLAT(cylinder->axis.w);
    const realv d0 = SPLAT(cylinder->world_axis.w), d1 = SPLAT(cylinder->d1);
    const realv a = v3_dot(hit.DxA, hit.DxA);
    const realv b = v3_dot(v3_cross(v3_splat(cylinder->p0), A), hit.DxA);
    const realv root = v_sqrt(hit.disc);
    const realv q = b + v_copysign(root, b);
    const realv s_q = q / a, s_c = c / q;
    const realv dA = v3_dot(D, A);
    *first = *second = SPLAT(MISS);
    if (cylinder->caps) {
        /* the side's interval (a ray along the axis: all of it inside, none outside) */
        const intv along_axis = a == 0;
        const realv side_lo = along_axis ? (c < 0 ? SPLAT(-INFINITY) : SPLAT(INFINITY)) : v_min(s_q, s_c);
        const realv side_hi = along_axis ? (c < 0 ? SPLAT(INFINITY) : SPLAT(-INFINITY)) : v_max(s_q, s_c);
        const intv side = along_axis || hit.disc > 0;
        /* the end planes' interval: p0's plane at d0 / dA, p1's at d1 / dA (parallel: between them or not) */
        const intv parallel = dA == 0;
        const realv e0 = d0 / dA, e1 = d1 / dA;
        const intv between = d0 <= 0 && d1 >= 0;
        const realv cap_lo = parallel ? (between ? SPLAT(-INFINITY) : SPLAT(INFINITY)) : v_min(e0, e1);
        const realv cap_hi = parallel ? (between ? SPLAT(INFINITY) : SPLAT(-INFINITY)) : v_max(e0, e1);
        const realv entry = v_max(side_lo, cap_lo), exit = v_min(side_hi, cap_hi);
        const intv crosses = side && entry < exit;
        *first = crosses && entry > 0 && entry < MISS ? entry : SPLAT(MISS);
        *second = crosses && exit > 0 && exit < MISS ? exit : SPLAT(MISS);
    } else {
        const realv near = v_min(s_q, s_c), far = v_max(s_q, s_c);
        const realv length = SPLAT(cylinder->p1.w);
        const realv z_near = near * dA - d0, z_far = far * dA - d0;
        const intv crosses = hit.disc > 0 && a > 0;
        *first = crosses && near > 0 && z_near >= 0 && z_near <= length ? near : SPLAT(MISS);
        *second = crosses && far > 0 && z_far >= 0 && z_far <= length ? far : SPLAT(MISS);
    }
}
#endif

#endif

#ifdef PYCLRAY_CLOSEST
/* The cylinder's nearest point: along the axis, h = (p - p0).a and the radial part rho of p - p0;
 * the side's nearest point (h clamped to [0, L], at radius r along rho) and, where it is capped,
 * each cap's (the disk of radius r at h = 0 and h = L, rho clamped to r): the nearest of them, the
 * side first, then the cap at p0, then the one at p1, on an exact tie. A point on the axis has every
 * radial direction equally near: closest_perpendicular picks one. */
inline ClosestPoint cylinder_closest(__global const CylinderWorld* world, const double3 p)
{
    const double3 a = world->axis.xyz, p0 = world->p0.xyz;
    const double r = world->p0.w, L = world->p1.w;
    const double3 F = p - p0;
    const double h = closest_dot(F, a);
    const double3 rho = F - h * a;
    const double radial = sqrt(closest_norm2(rho));
    const double3 out = radial > 0.0 ? rho / radial : closest_perpendicular(a);
    const double along = h < 0.0 ? 0.0 : (h > L ? L : h);
    ClosestPoint best = closest_at(p, p0 + along * a + r * out, out);
    if (world->caps) {
        const double3 on_cap = (radial < r ? radial : r) * out;
        const ClosestPoint bottom = closest_at(p, p0 + on_cap, -a);
        if (bottom.d2 < best.d2) best = bottom;
        const ClosestPoint top = closest_at(p, world->p1.xyz + on_cap, a);
        if (top.d2 < best.d2) best = top;
    }
    return best;
}

/* a capped cylinder's solid: 0 <= h <= L and |rho| <= r; an open tube has no inside */
inline int cylinder_inside(__global const CylinderWorld* world, const double3 p)
{
    const double3 a = world->axis.xyz, F = p - world->p0.xyz;
    const double r = world->p0.w, h = closest_dot(F, a);
    return world->caps && h >= 0.0 && h <= world->p1.w && closest_norm2(F - h * a) <= r * r;
}
#endif
