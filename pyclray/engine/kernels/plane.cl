/* Plane: n . p + h = 0 in the frame, n unit (normal.xyz) and h (normal.w) the signed distance of the
 * frame's origin, both computed on the host in float64; exact: n and h in the world, float64 bits
 * (cast only, where the plane is tested from each ray's own origin). */

inline realv plane_hit(__global const Plane* plane, const RayPacket* ray)
{
    const vec3v n = v3_splat(plane->normal);
#ifdef PYCLRAY_CAST
    /* the signed distance of the ray's world origin from the float64 normal and offset (cast's rays
     * are single: LANES 1): an origin far from the world's centre but near the plane keeps every
     * digit of it */
    const double4 exact = as_double4(plane->exact);
    const realv h = (real)((exact.x * ray->world.x + exact.y * ray->world.y) + exact.z * ray->world.z + exact.w);
#else
    /* the signed distance of the ray's origin (the host's, for camera rays from the frame's origin) */
    const realv h = FROM_EYE(ray) ? SPLAT(plane->normal.w) : SPLAT(plane->normal.w) + v3_dot(n, ray->origin);
#endif
    /* a ray parallel to the plane gives +-inf or NaN here: neither is a hit */
    const realv s = -h / v3_dot(n, ray->dir);
    return s > 0 ? s : SPLAT(MISS);
}

/* The plane's own normalized normal in world space (packed as is, not rotated back from the
 * frame, so an axis-aligned floor gives exactly (0, 1, 0)), never flipped toward the viewer. */
inline vec3v plane_normal(__global const Plane* plane, const RayPacket* ray, __global const Camera* camera)
{
    return v3_splat(plane->world_normal);
}
