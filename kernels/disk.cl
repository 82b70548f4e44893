/* Disk: n . (p - C) = 0 and |p - C| <= r. In the frame, h = n . (origin - C) comes from the host in
 * float64 (normal.w); a ray origin + s D meets the disk's plane at s = -h / (n . D). */

inline real disk_hit(__global const Disk* disk, const Ray* ray)
{
    const real3 n = disk->normal.xyz;
    const real3 F = disk->center.xyz - ray->origin;  /* the centre from the ray's origin */
#ifdef PYCLRAY_CAST
    const real h = disk->normal.w + dot(n, ray->origin);
#else
    const real h = disk->normal.w;
#endif
    /* a ray parallel to the disk gives +-inf or NaN here: neither is a hit */
    const real s = -h / dot(n, ray->dir);
    const real3 P = s * ray->dir - F;  /* the hit point from the centre */
    return (s > 0 && dot(P, P) <= disk->center.w) ? s : MISS;
}

/* The disk's own normalized normal in world space (packed as is), never flipped. */
inline real3 disk_normal(__global const Disk* disk, const Ray* ray, __global const Camera* camera)
{
    return disk->world_normal.xyz;
}
