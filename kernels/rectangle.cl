/* Rectangle: the points C + a u + b v with |a| <= 1 and |b| <= 1. In the frame, h = n . (origin - C)
 * comes from the host in float64 (normal.w), and a, b of a point P - C are its dot products with the
 * dual vectors of u and v (host-side float64: exact for sides that are orthogonal within 1e-6). */

inline real rectangle_hit(__global const Rectangle* rectangle, const Ray* ray)
{
    const real3 n = rectangle->normal.xyz;
    const real3 F = rectangle->center.xyz - ray->origin;
#ifdef PYCLRAY_CAST
    const real h = rectangle->normal.w + dot(n, ray->origin);
#else
    const real h = rectangle->normal.w;
#endif
    const real s = -h / dot(n, ray->dir);  /* +-inf or NaN for a parallel ray: not a hit */
    const real3 P = s * ray->dir - F;
    const real a = dot(P, rectangle->u_dual.xyz), b = dot(P, rectangle->v_dual.xyz);
    return (s > 0 && fabs(a) <= 1 && fabs(b) <= 1) ? s : MISS;
}

/* normalize(u x v) in world space (packed as is), never flipped. */
inline real3 rectangle_normal(__global const Rectangle* rectangle, const Ray* ray, __global const Camera* camera)
{
    return rectangle->world_normal.xyz;
}
