/* Disk: n . (p - C) = 0 and |p - C| <= r. In the space, h = n . (origin - C) comes from the host in
 * float64 (normal.w); a ray origin + s D meets the disk's plane at s = -h / (n . D). The hit point
 * from the centre, s D - F (F = C - origin), cancels for a far disk (s D and F are large, their
 * difference small); it equals n x (D x F) / (n . D), whose cross product keeps the digits of the
 * small sideways offsets of the camera space, so the border is as sharp far away as near. */

#if defined(PYCLRAY_REBASE) || defined(PYCLRAY_CAST)

/* The disk in the camera's space (rebase_flat: its centre, normal and the origin's distance to its
 * plane), and r^2. */
inline void disk_rebase(__global const DiskWorld* world, PYCLRAY_REBASE_OUT Disk* out, const Space* space)
{
    const double3 F = world->center.xyz - space->origin, n = world->normal.xyz;
    const double r = world->center.w;
    out->center = (real4)(to_space(space, F), (real)(r * r));
    out->normal = (real4)(to_space(space, n), (real)(-dot2_3(n, F)));
    out->normal_low = (real4)(to_space_low(space, n), 0);
    out->world_normal = (real4)(convert_real3(n), 0);
}

#endif

#if !defined(PYCLRAY_REBASE) && !defined(PYCLRAY_CLOSEST)  /* the ray tests (none in the closest-point query) */

/* a shadow ray leaving it on either side never meets it again (flat) */
#define PYCLRAY_FLAT_disk 1


inline realv disk_hit(SHAPE_SPACE const Disk* disk, const RayPacket* ray)
{
    const vec3v n = v3_splat(disk->normal);
    /* from the eye (the space's origin) the host's h; from elsewhere (cast, shadow rays) the origin's */
    const vec3v F = FROM_EYE(ray) ? v3_splat(disk->center) : v3_sub(v3_splat(disk->center), ray->origin);
    const realv h = FROM_EYE(ray) ? SPLAT(disk->normal.w) : SPLAT(disk->normal.w) + v3_dot(n, ray->origin);
    /* a ray parallel to the disk gives +-inf or NaN here: neither is a hit; n . d exact for camera rays */
    const realv along = PIXEL_DOT(ray, disk->normal, disk->normal_low, v3_dot(n, ray->dir));
    const realv s = -h / along;
    const vec3v P = v3_scale(v3_cross(n, v3_cross(ray->dir, F)), SPLAT(1) / along);
    return (s > 0 && v3_dot(P, P) <= SPLAT(disk->center.w)) ? s : SPLAT(MISS);
}

/* The disk's own normalized normal in world space (packed as is), never flipped. */
inline vec3v disk_normal(SHAPE_SPACE const Disk* disk, const RayPacket* ray, const Basis* basis)
{
    return v3_splat(disk->world_normal);
}

#ifdef PYCLRAY_ALL_HITS
/* every hit s > 0 along the ray (count_hits, all_hits: kernels/allhits.cl): a flat shape's one */
inline void disk_hits(SHAPE_SPACE const Disk* shape, const RayPacket* ray, realv* first, realv* second)
{
    *first = disk_hit(shape, ray);
    *second = SPLAT(MISS);
}
#endif

#endif

#ifdef PYCLRAY_CLOSEST
/* The disk's nearest point: p's foot on its plane, pulled in to the rim where it lies beyond (the
 * radial part rho of p - C, clamped to r). A disk has no inside. */
inline ClosestPoint disk_closest(__global const DiskWorld* world, const double3 p)
{
    const double3 n = world->normal.xyz, F = p - world->center.xyz;
    const double r = world->center.w, s = closest_dot(F, n);
    const double3 rho = F - s * n;
    const double radial = sqrt(closest_norm2(rho));
    const double3 in_plane = radial > r ? rho * (r / radial) : rho;
    ClosestPoint c = closest_at(p, world->center.xyz + in_plane, n);
    if (radial <= r) c.d2 = s * s;  /* over the disk: the plane's distance, better conditioned */
    return c;
}

inline int disk_inside(__global const DiskWorld* world, const double3 p) { return 0; }
#endif
