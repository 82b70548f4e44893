/* A batch of spheres (pyclray.Spheres): each entry is a Sphere, tested by sphere.cl's code (put
 * before this file); its primitive is its index in the batch. */

#if defined(PYCLRAY_REBASE) || defined(PYCLRAY_CAST)

inline void spheres_rebase(__global const SphereWorld* world, PYCLRAY_REBASE_OUT Sphere* out, const Space* space)
{
    sphere_rebase(world, out, space);
}

#endif

#if !defined(PYCLRAY_REBASE) && !defined(PYCLRAY_CLOSEST)  /* the ray tests (none in the closest-point query) */

#define PYCLRAY_FLAT_spheres 0  /* each primitive a sphere: convex */

inline realv spheres_hit(SHAPE_SPACE const Sphere* sphere, const RayPacket* ray) { return sphere_hit(sphere, ray); }

inline vec3v spheres_normal(SHAPE_SPACE const Sphere* sphere, const RayPacket* ray, const Basis* basis)
{
    return sphere_normal(sphere, ray, basis);
}

#ifdef PYCLRAY_ALL_HITS
inline void spheres_hits(SHAPE_SPACE const Sphere* sphere, const RayPacket* ray, realv* first, realv* second)
{
    sphere_hits(sphere, ray, first, second);
}
#endif

#endif

#ifdef PYCLRAY_CLOSEST
/* each primitive a sphere (sphere.cl's functions) */
inline ClosestPoint spheres_closest(__global const SphereWorld* world, const double3 p) { return sphere_closest(world, p); }
inline int spheres_inside(__global const SphereWorld* world, const double3 p) { return sphere_inside(world, p); }
#endif
