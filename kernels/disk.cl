/* Disk: n . (p - C) = 0 and |p - C| <= r. In the frame, h = n . (origin - C) comes from the host in
 * float64 (normal.w); a ray origin + s D meets the disk's plane at s = -h / (n . D), the hit point
 * lies at s D - F from the centre (F = C - origin). */

inline realv disk_hit(__global const Disk* disk, const RayPacket* ray)
{
    const vec3v n = v3_splat(disk->normal);
#ifdef PYCLRAY_CAST
    const vec3v F = v3_sub(v3_splat(disk->center), ray->origin);
    const realv h = SPLAT(disk->normal.w) + v3_dot(n, ray->origin);
#else
    const vec3v F = v3_splat(disk->center);  /* the ray's origin is the frame's */
    const realv h = SPLAT(disk->normal.w);
#endif
    /* a ray parallel to the disk gives +-inf or NaN here: neither is a hit */
    const realv s = -h / v3_dot(n, ray->dir);
    const vec3v P = v3_sub(v3_scale(ray->dir, s), F);
    return (s > 0 && v3_dot(P, P) <= SPLAT(disk->center.w)) ? s : SPLAT(MISS);
}

/* The disk's own normalized normal in world space (packed as is), never flipped. */
inline vec3v disk_normal(__global const Disk* disk, const RayPacket* ray, __global const Camera* camera)
{
    return v3_splat(disk->world_normal);
}
