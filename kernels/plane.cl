/* Plane: n . p + h = 0 in the frame, n unit (normal.xyz) and h (normal.w) the signed distance of the
 * frame's origin, both computed on the host in float64; exact: n and h in the world, float64 bits
 * (cast only, where the plane is tested from each ray's own origin). */

inline real plane_hit(__global const Plane* plane, const Ray* ray)
{
    const real3 n = plane->normal.xyz;
#ifdef PYCLRAY_CAST
    /* the signed distance of the ray's world origin from the float64 normal and offset: an origin
     * far from the world's centre but near the plane keeps every digit of it */
    const double4 exact = as_double4(plane->exact);
    const real h = (real)((exact.x * ray->world.x + exact.y * ray->world.y) + exact.z * ray->world.z + exact.w);
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
