/* Plane: n . p + h = 0 in the frame, n unit (normal.xyz) and h (normal.w) the signed distance of the
 * frame's origin, both computed on the host in float64. */

inline realv plane_hit(__global const Plane* plane, const RayPacket* ray)
{
    const vec3v n = v3_splat(plane->normal);
    /* the signed distance of the ray's origin (the frame's origin's, from the host, for camera rays) */
    const realv h = FROM_EYE(ray) ? SPLAT(plane->normal.w) : SPLAT(plane->normal.w) + v3_dot(n, ray->origin);
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
