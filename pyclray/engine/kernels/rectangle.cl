/* Rectangle: the points C + a u + b v with |a| <= 1 and |b| <= 1. In the space, h = n . (origin - C)
 * comes from the host in float64 (normal.w), and a, b of a point P - C are its dot products with the
 * dual vectors of u and v (host-side float64: exact for sides orthogonal within 1e-6). The hit
 * point from the centre is n x (D x F) / (n . D) rather than s D - F, which cancels far away (see
 * kernels/disk.cl). */

#if defined(PYCLRAY_REBASE) || defined(PYCLRAY_CAST)

/* The rectangle in the camera's space: its centre, normal and the origin's distance to its plane,
 * and the dual vectors of its sides along the space's axes. */
inline void rectangle_rebase(__global const RectangleWorld* world, PYCLRAY_REBASE_OUT Rectangle* out, const Space* space)
{
    const double3 F = world->center.xyz - space->origin, n = world->normal.xyz;
    out->center = (real4)(to_space(space, F), 0);
    out->normal = (real4)(to_space(space, n), (real)(-dot2_3(n, F)));
    out->normal_low = (real4)(to_space_low(space, n), 0);
    out->u_dual = (real4)(to_space(space, world->u_dual.xyz), 0);
    out->v_dual = (real4)(to_space(space, world->v_dual.xyz), 0);
    out->world_normal = (real4)(convert_real3(n), 0);
}

#endif

#if !defined(PYCLRAY_REBASE) && !defined(PYCLRAY_CLOSEST)  /* the ray tests (none in the closest-point query) */

/* a shadow ray leaving it on either side never meets it again (flat) */
#define PYCLRAY_FLAT_rectangle 1


inline realv rectangle_hit(SHAPE_SPACE const Rectangle* rectangle, const RayPacket* ray)
{
    const vec3v n = v3_splat(rectangle->normal);
    /* from the eye (the space's origin) the host's h; from elsewhere (cast, shadow rays) the origin's */
    const vec3v F = FROM_EYE(ray) ? v3_splat(rectangle->center) : v3_sub(v3_splat(rectangle->center), ray->origin);
    const realv h = FROM_EYE(ray) ? SPLAT(rectangle->normal.w) : SPLAT(rectangle->normal.w) + v3_dot(n, ray->origin);
    /* +-inf or NaN for a parallel ray: not a hit; n . d exact for camera rays */
    const realv along = PIXEL_DOT(ray, rectangle->normal, rectangle->normal_low, v3_dot(n, ray->dir));
    const realv s = -h / along;
    const vec3v P = v3_scale(v3_cross(n, v3_cross(ray->dir, F)), SPLAT(1) / along);
    const realv a = v3_dot(P, v3_splat(rectangle->u_dual)), b = v3_dot(P, v3_splat(rectangle->v_dual));
    return (s > 0 && v_abs(a) <= 1 && v_abs(b) <= 1) ? s : SPLAT(MISS);
}

/* normalize(u x v) in world space (packed as is), never flipped. */
inline vec3v rectangle_normal(SHAPE_SPACE const Rectangle* rectangle, const RayPacket* ray, const Basis* basis)
{
    return v3_splat(rectangle->world_normal);
}

#ifdef PYCLRAY_ALL_HITS
/* every hit s > 0 along the ray (count_hits, all_hits: kernels/allhits.cl): a flat shape's one */
inline void rectangle_hits(SHAPE_SPACE const Rectangle* shape, const RayPacket* ray, realv* first, realv* second)
{
    *first = rectangle_hit(shape, ray);
    *second = SPLAT(MISS);
}
#endif

#endif

#ifdef PYCLRAY_CLOSEST
/* The rectangle's nearest point: p's coordinates a, b along its half sides u, v (dot products with
 * their dual vectors) clamped to [-1, 1] (its sides are orthogonal, so clamping each is the nearest
 * point). A rectangle has no inside. */
inline ClosestPoint rectangle_closest(__global const RectangleWorld* world, const double3 p)
{
    const double3 F = p - world->center.xyz;
    double a = closest_dot(F, world->u_dual.xyz), b = closest_dot(F, world->v_dual.xyz);
    const bool over = fabs(a) <= 1.0 && fabs(b) <= 1.0;
    a = a < -1.0 ? -1.0 : (a > 1.0 ? 1.0 : a);
    b = b < -1.0 ? -1.0 : (b > 1.0 ? 1.0 : b);
    ClosestPoint c = closest_at(p, world->center.xyz + a * world->u.xyz + b * world->v.xyz, world->normal.xyz);
    if (over) {  /* over the rectangle: the plane's distance, better conditioned */
        const double s = closest_dot(F, world->normal.xyz);
        c.d2 = s * s;
    }
    return c;
}

inline int rectangle_inside(__global const RectangleWorld* world, const double3 p) { return 0; }
#endif
