/* The camera frame: world_from_camera has columns u (left), v (up) and w (forward). */

inline real3 world_from_frame(__global const Camera* camera, const real3 n)
{
    return n.x * camera->u.xyz + n.y * camera->v.xyz + n.z * camera->w.xyz;
}
