/* The camera frame: world_from_camera has columns u (left), v (up) and w (forward). */

inline vec3v world_from_frame(__global const Camera* camera, const vec3v n)
{
    const real4 u = camera->u, v = camera->v, w = camera->w;
    return v3((n.x * u.x + n.y * v.x) + n.z * w.x,
              (n.x * u.y + n.y * v.y) + n.z * w.y,
              (n.x * u.z + n.y * v.z) + n.z * w.z);
}
