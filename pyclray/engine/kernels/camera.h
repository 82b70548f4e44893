/* The pinhole camera of a render (pyclray/model/camera.py; its struct, Camera, from the host): its space
 * (origin the eye, axes u (left), v (up) and w (forward): the columns of world_from_camera) and the
 * rays of a packet of its pixels. */

inline Basis camera_basis(__global const Camera* camera)
{
    Basis basis;
    basis.u = camera->u;
    basis.v = camera->v;
    basis.w = camera->w;
    return basis;
}

/* a direction of the camera's space in world coordinates */
inline vec3v world_from_space(__global const Camera* camera, const vec3v n)
{
    return world_from_axes(camera->u, camera->v, camera->w, n);
}

/* The camera rays of a packet: its PYCLRAY_PACKET_W x PYCLRAY_PACKET_H pixels from column i0 and
 * row j0 on (lane l: column i0 + l % W, row j0 + l / W), in the camera space. */
#if PYCLRAY_PACKET_H == 1
#define PYCLRAY_LANE_COLUMN LANE_INDEX
#define PYCLRAY_LANE_ROW SPLAT_INT(0)
#else
#define PYCLRAY_LANE_COLUMN (LANE_INDEX % SPLAT_INT(PYCLRAY_PACKET_W))
#define PYCLRAY_LANE_ROW (LANE_INDEX / SPLAT_INT(PYCLRAY_PACKET_W))
#endif
inline RayPacket camera_rays(__global const Camera* camera, const int i0, const int j0)
{
    const int width = camera->width, height = camera->height;
    const intv i = SPLAT_INT(i0) + PYCLRAY_LANE_COLUMN, j = SPLAT_INT(j0) + PYCLRAY_LANE_ROW;
    /* pixel centres on the image plane at distance 1 (pyclray/model/camera.py): the integer part of
     * the numerator 2 cx - 1 - 2 i is exact and its fraction (0 for a centred camera, whose numerator
     * is width - 1 - 2 i as ever) adds one rounding, so each coordinate carries three roundings (fp64;
     * fp32's is exact, below) and keeps its relative precision even for a tiny fov or next to the
     * principal point */
#ifdef PYCLRAY_PIXEL_EXACT
    /* fp32: sx = (tan_x / width) N as a float pair, N = 2 cx - 1 - 2 i = whole + fraction: tan_x / width
     * from the host as a high part of 11 bits and the rest (pixel_step), so that high x whole is
     * exact (|whole| < 2^13: an image up to 8192 pixels across about its principal point), and the
     * rest's product and the fraction's term (a camera constant, below a pixel's width) are small
     * numbers whose rounding is far below what n . d needs; alike in y. sx and sy are then the
     * float64 ray's to about eps^2 relative, as kernels/lanes.h's pixel_dot needs (a rounding of sx is
     * a direction error of eps |sx|: eps / |n . d| relative in a grazing n . d) */
    const real4 step = camera->pixel_step;
    RayPacket ray;
    const realv whole_x = TO_REALV(SPLAT_INT(camera->centre_x - 1) - 2 * i);
    const realv whole_y = TO_REALV(SPLAT_INT(camera->centre_y - 1) - 2 * j);
    ray.x = SPLAT(step.x) * whole_x;
    ray.x_low = SPLAT(step.y) * whole_x + SPLAT((step.x + step.y) * camera->centre_x_low);
    ray.y = SPLAT(step.z) * whole_y;
    ray.y_low = SPLAT(step.w) * whole_y + SPLAT((step.z + step.w) * camera->centre_y_low);
    const realv sx = ray.x + ray.x_low, sy = ray.y + ray.y_low;
#else
    const realv sx = SPLAT(camera->tan_x) * ((TO_REALV(SPLAT_INT(camera->centre_x - 1) - 2 * i) + SPLAT(camera->centre_x_low))
                                            / SPLAT((real)width));
    const realv sy = SPLAT(camera->tan_y) * ((TO_REALV(SPLAT_INT(camera->centre_y - 1) - 2 * j) + SPLAT(camera->centre_y_low))
                                            / SPLAT((real)height));
    RayPacket ray;
#endif
    /* normalized in the camera space, where each component is divided on its own: the tiny
     * lateral components of a narrow field of view keep their relative precision */
    const realv length = v_sqrt((sx * sx + sy * sy) + SPLAT(1));
    ray.origin = v3(SPLAT(0), SPLAT(0), SPLAT(0));
    ray.dir = v3(sx / length, sy / length, SPLAT(1) / length);
    ray.a = v3_dot(ray.dir, ray.dir);
#ifdef PYCLRAY_PIXEL_EXACT
    ray.length = length;
#endif
#ifdef PYCLRAY_SHADOWS
    ray.from_eye = 1;
#endif
    return ray;
}

#ifdef PYCLRAY_CAMERA_TABLE
/* The rays of a camera model whose pixels do not lie on a pinhole's image plane (a lens's distortion,
 * a fisheye, a panorama: pyclray/model/cameras/, CameraModel.space_directions): each pixel's ray in
 * the camera's space, solved on the host in float64 once per camera and image size and rounded once,
 * read here. The table is in packet order (engine/scene/views.py: packet_table), a packet's lanes
 * contiguous: per packet, the lanes' image-plane coordinates x / z, y / z (PYCLRAY_CAMERA_PLANE:
 * every ray ahead of the eye's plane, normalized here as a pinhole's) or unit x, y, z, then one
 * number whose bit l says lane l is in the model's field (else a miss: outside its field, beyond its
 * fold, past the image's edge). */
#if LANES == 1
#define PYCLRAY_TABLE_LANES(p) (*(p))
#else
#define PYCLRAY_TABLE_LANES(p) PYCLRAY_CAT(vload, LANES)(0, (p))
#endif
#ifdef PYCLRAY_CAMERA_PLANE
#define PYCLRAY_TABLE_COORDINATES 2
#else
#define PYCLRAY_TABLE_COORDINATES 3
#endif
inline RayPacket camera_table_rays(__global const Camera* camera, __global const real* table, const int i0,
                                   const int j0, intv* in_field)
{
    const int packets_x = (camera->width + PYCLRAY_PACKET_W - 1) / PYCLRAY_PACKET_W;
    __global const real* p = table + ((size_t)(j0 / PYCLRAY_PACKET_H) * (size_t)packets_x + (size_t)(i0 / PYCLRAY_PACKET_W))
                                         * (PYCLRAY_TABLE_COORDINATES * LANES + 1);
    RayPacket ray;
    ray.origin = v3(SPLAT(0), SPLAT(0), SPLAT(0));
#ifdef PYCLRAY_CAMERA_PLANE
    /* as camera_rays: normalized in the camera space, each component divided on its own */
    const realv sx = PYCLRAY_TABLE_LANES(p), sy = PYCLRAY_TABLE_LANES(p + LANES);
    const realv length = v_sqrt((sx * sx + sy * sy) + SPLAT(1));
    ray.dir = v3(sx / length, sy / length, SPLAT(1) / length);
#else
    ray.dir = v3(PYCLRAY_TABLE_LANES(p), PYCLRAY_TABLE_LANES(p + LANES), PYCLRAY_TABLE_LANES(p + 2 * LANES));
#endif
    ray.a = v3_dot(ray.dir, ray.dir);
    const int bits = (int)p[PYCLRAY_TABLE_COORDINATES * LANES];
    *in_field = ((SPLAT_INT(bits) >> LANE_INDEX) & SPLAT_INT(1)) != SPLAT_INT(0);
#ifdef PYCLRAY_SHADOWS
    ray.from_eye = 1;
#endif
    return ray;
}

/* A lane outside the model's field is a miss: its nearest hit forgotten before the images are written. */
#ifdef PYCLRAY_TRACK_ID
#define PYCLRAY_OUT_OF_FIELD(in_field)                                                \
    best = (in_field) ? best : SPLAT(MISS);                                           \
    best_id = (in_field) ? best_id : SPLAT_INT(-1);                                   \
    best_key = (in_field) ? best_key : SPLAT_INT(0);
#else
#define PYCLRAY_OUT_OF_FIELD(in_field) best = (in_field) ? best : SPLAT(MISS);
#endif
#endif
