/* A batch of spheres (pyclray.Spheres): each entry is a Sphere, tested by sphere.cl's code (put
 * before this file); its primitive is its index in the batch. */

#ifdef PYCLRAY_REBASE

inline void spheres_rebase(__global const SphereWorld* world, __global Sphere* out, const Frame* frame)
{
    sphere_rebase(world, out, frame);
}

#else

inline realv spheres_hit(__global const Sphere* sphere, const RayPacket* ray) { return sphere_hit(sphere, ray); }

inline vec3v spheres_normal(__global const Sphere* sphere, const RayPacket* ray, __global const Camera* camera)
{
    return sphere_normal(sphere, ray, camera);
}

#endif
