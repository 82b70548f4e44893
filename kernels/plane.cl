/* Plane: n . p + h = 0 in the frame, n unit (normal.xyz) and h (normal.w) the signed distance of the
 * frame's origin, both computed on the host in float64. */

inline real plane_hit(__global const Plane* plane, const Ray* ray)
{
    const real3 n = plane->normal.xyz;
#ifdef PYCLRAY_CAST
    const real h = plane->normal.w + dot(n, ray->origin);
#else
    const real h = plane->normal.w;
#endif
    /* a ray parallel to the plane gives +-inf or NaN here: neither is a hit */
    const real s = -h / dot(n, ray->dir);
    return s > 0 ? s : MISS;
}

/* The plane's own normalized normal in world space (packed as is, not rotated back from the
 * frame, so an axis-aligned floor gives exactly (0, 1, 0)), never flipped toward the viewer. */
inline real3 plane_normal(__global const Plane* plane, const Ray* ray, __global const Camera* camera)
{
    return plane->world_normal.xyz;
}
