/* Plane: n . p + h = 0 in the space, n unit (normal.xyz) and h (normal.w) the signed distance of the
 * space's origin, both computed on the host in float64; exact: n and h in the world, float64 bits
 * (cast only, where the plane is tested from each ray's own origin). */

#if defined(PYCLRAY_REBASE) || defined(PYCLRAY_CAST)

/* The plane in the camera's space: its normal along the space's axes and the space origin's signed
 * distance n . origin + h, compensated (a far origin cancels); its world normal and exact bits. */
inline void plane_rebase(__global const PlaneWorld* world, PYCLRAY_REBASE_OUT Plane* out, const Space* space)
{
    const double4 n_h = world->normal;
    out->normal = (real4)(to_space(space, n_h.xyz), (real)dot2_4(n_h, (double4)(space->origin, 1.0)));
    out->normal_low = (real4)(to_space_low(space, n_h.xyz), 0);
    out->world_normal = (real4)(convert_real3(n_h.xyz), 0);
    out->exact = as_ulong4(n_h);
}

#endif

#if !defined(PYCLRAY_REBASE) && !defined(PYCLRAY_CLOSEST)  /* the ray tests (none in the closest-point query) */

/* a shadow ray leaving it on either side never meets it again (flat) */
#define PYCLRAY_FLAT_plane 1


inline realv plane_hit(SHAPE_SPACE const Plane* plane, const RayPacket* ray)
{
    const vec3v n = v3_splat(plane->normal);
    /* the signed distance of the ray's origin (the host's, for camera rays from the space's origin) */
    const realv h = FROM_EYE(ray) ? SPLAT(plane->normal.w) : SPLAT(plane->normal.w) + v3_dot(n, ray->origin);
    /* a ray parallel to the plane gives +-inf or NaN here: neither is a hit; n . d exact for camera rays */
    const realv s = -h / PIXEL_DOT(ray, plane->normal, plane->normal_low, v3_dot(n, ray->dir));
    return s > 0 ? s : SPLAT(MISS);
}

/* The plane's own normalized normal in world space (packed as is, not rotated back from the
 * camera's space, so an axis-aligned floor gives exactly (0, 1, 0)), never flipped toward the viewer. */
inline vec3v plane_normal(SHAPE_SPACE const Plane* plane, const RayPacket* ray, const Basis* basis)
{
    return v3_splat(plane->world_normal);
}

#ifdef PYCLRAY_ALL_HITS
/* every hit s > 0 along the ray (count_hits, all_hits: kernels/allhits.cl): a flat shape's one */
inline void plane_hits(SHAPE_SPACE const Plane* shape, const RayPacket* ray, realv* first, realv* second)
{
    *first = plane_hit(shape, ray);
    *second = SPLAT(MISS);
}
#endif

#endif

#ifdef PYCLRAY_CLOSEST
/* The plane's nearest point: the foot of p, p - s n with s = n.p + h (n unit); d2 = s^2, which is
 * better conditioned than |p - foot|^2. Inside: the half-space behind it (s <= 0: its surface too). */
inline ClosestPoint plane_closest(__global const PlaneWorld* world, const double3 p)
{
    const double3 n = world->normal.xyz;
    const double s = closest_dot(n, p) + world->normal.w;
    ClosestPoint c = closest_at(p, p - s * n, n);
    c.d2 = s * s;
    return c;
}

inline int plane_inside(__global const PlaneWorld* world, const double3 p)
{
    return closest_dot(world->normal.xyz, p) + world->normal.w <= 0.0;
}
#endif
