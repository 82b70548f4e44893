/* pyclray's kernels. The host puts before this file common.h, the generated struct header,
 * camera.h and the file of each shape type present, and selects what is compiled with -D options:
 *   PYCLRAY_FP64                        double precision
 *   PYCLRAY_CAST                        the batch-ray kernel instead of the camera kernel
 *   PYCLRAY_RAYS                        the kernel of the camera's rays (no shapes, no images)
 *   PYCLRAY_AOV_DEPTH/_NORMAL/_ID       which images are written (no buffer, no code for the others)
 *   PYCLRAY_SHAPES(X)                   X(Type, type) for each shape type present
 * Geometry and camera come in buffers, so moving a shape or the camera never recompiles.
 */

#if defined(PYCLRAY_AOV_NORMAL) || defined(PYCLRAY_AOV_ID)
#define PYCLRAY_TRACK_ID 1   /* the winner matters, not only its distance */
#endif

#ifdef PYCLRAY_CAST
/* one argument pair per shape type present: the packed array and its length */
#define PYCLRAY_SHAPE_ARG(Type, type) , __global const Type* type##s, const int n_##type##s
/* every shape of the type, in order */
#define PYCLRAY_FIRST(type) 0
#define PYCLRAY_END(type) n_##type##s
#define PYCLRAY_SHAPE_AT(type, q) (q)
#else
/* per shape type: the packed array, and for each tile of the image the shapes that can be seen
 * in it (type##_tile_list[type##_tile_start[tile] .. type##_tile_start[tile + 1]], increasing;
 * the host's conservative screen bounds, pyclray/culling.py): the others miss every ray there */
#define PYCLRAY_SHAPE_ARG(Type, type) \
    , __global const Type* type##s, __global const int* type##_tile_start, __global const int* type##_tile_list
#define PYCLRAY_FIRST(type) type##_tile_start[tile]
#define PYCLRAY_END(type) type##_tile_start[tile + 1]
#define PYCLRAY_SHAPE_AT(type, q) type##_tile_list[q]
#endif
#define PYCLRAY_KIND(Type, type) KIND_##Type,
enum { KIND_NONE = 0, PYCLRAY_SHAPES(PYCLRAY_KIND) KIND_COUNT };

/* nearest hit with s > 0 over every shape of one type; on an exact tie the lowest id wins */
#ifdef PYCLRAY_TRACK_ID
#define PYCLRAY_NEAREST(Type, type)                                                 \
    for (int q = PYCLRAY_FIRST(type), end = PYCLRAY_END(type); q < end; ++q) {      \
        const int k = PYCLRAY_SHAPE_AT(type, q);                                    \
        const real s = type##_hit(&type##s[k], &ray);                               \
        if (s < best || (s == best && s < MISS && type##s[k].id < best_id)) {       \
            best = s; best_id = type##s[k].id; best_kind = KIND_##Type; best_k = k; \
        }                                                                           \
    }
#define PYCLRAY_FIND_NEAREST                                                        \
    real best = MISS;                                                               \
    int best_id = -1, best_kind = KIND_NONE, best_k = 0;                            \
    PYCLRAY_SHAPES(PYCLRAY_NEAREST)
#else
#define PYCLRAY_NEAREST(Type, type)                                                 \
    for (int q = PYCLRAY_FIRST(type), end = PYCLRAY_END(type); q < end; ++q)        \
        best = fmin(best, type##_hit(&type##s[PYCLRAY_SHAPE_AT(type, q)], &ray));
#define PYCLRAY_FIND_NEAREST                                                        \
    real best = MISS;                                                               \
    PYCLRAY_SHAPES(PYCLRAY_NEAREST)
#endif

/* the images: distance along the unit ray, world normal of the winner only, id;
 * MISS (+inf), (0, 0, 0) and -1 on a miss */
#ifdef PYCLRAY_AOV_DEPTH
#define PYCLRAY_DEPTH_ARG , __global real* depth
#define PYCLRAY_WRITE_DEPTH(index) depth[index] = best < MISS ? best * sqrt(ray.a) : MISS;
#else
#define PYCLRAY_DEPTH_ARG
#define PYCLRAY_WRITE_DEPTH(index)
#endif

#ifdef PYCLRAY_AOV_NORMAL
#define PYCLRAY_NORMAL_ARG , __global real* normal_out
#define PYCLRAY_NORMAL(Type, type) \
    if (best_kind == KIND_##Type) normal = type##_normal(&type##s[best_k], &ray, camera);
#define PYCLRAY_WRITE_NORMAL(index)                                                 \
    {                                                                               \
        real3 normal = (real3)(0, 0, 0);                                            \
        PYCLRAY_SHAPES(PYCLRAY_NORMAL)                                              \
        vstore3(normal, index, normal_out);                                         \
    }
#else
#define PYCLRAY_NORMAL_ARG
#define PYCLRAY_WRITE_NORMAL(index)
#endif

#ifdef PYCLRAY_AOV_ID
#define PYCLRAY_ID_ARG , __global int* id_out
#define PYCLRAY_WRITE_ID(index) id_out[index] = best_id;
#else
#define PYCLRAY_ID_ARG
#define PYCLRAY_WRITE_ID(index)
#endif

#define PYCLRAY_OUTPUT_ARGS PYCLRAY_DEPTH_ARG PYCLRAY_NORMAL_ARG PYCLRAY_ID_ARG
#define PYCLRAY_WRITE(index) PYCLRAY_WRITE_DEPTH(index) PYCLRAY_WRITE_NORMAL(index) PYCLRAY_WRITE_ID(index)

#ifdef PYCLRAY_RAYS

/* The camera ray of pixel (column i from the left, row j from the top), in the camera frame. */
inline Ray camera_ray(__global const Camera* camera, const int i, const int j)
{
    const int width = camera->width, height = camera->height;
    /* pixel centre on the image plane at distance 1: the integer numerators are exact, so each
     * coordinate carries two roundings and keeps its relative precision even for a tiny fov */
    const real sx = camera->tan_x * ((real)(width - 2 * i - 1) / (real)width);
    const real sy = camera->tan_y * ((real)(height - 2 * j - 1) / (real)height);
    /* normalized in the camera frame, where each component is divided on its own: the tiny
     * lateral components of a narrow field of view keep their relative precision */
    const real3 D = (real3)(sx, sy, (real)1);
    Ray ray;
    ray.origin = (real3)(0, 0, 0);
    ray.dir = D / sqrt(dot(D, D));
    ray.a = dot(ray.dir, ray.dir);
    return ray;
}

/* Every pixel's ray (dir.xyz, a), once per camera and image size: renders of the same view share
 * them (the host keeps the buffer), so the divisions and the square root are not on every render's
 * path. */
__kernel void rays(__global const Camera* camera, __global real4* rays)
{
    const int i = get_global_id(0), j = get_global_id(1);
    const int width = camera->width, height = camera->height;
    if (i >= width || j >= height) return;
    const Ray ray = camera_ray(camera, i, j);
    rays[(size_t)j * (size_t)width + (size_t)i] = (real4)(ray.dir, ray.a);
}

#elif !defined(PYCLRAY_CAST)

/* One work-item per pixel: i is the column from the left, j the row from the top; its ray from the
 * rays kernel. Tiles are 1 << tile_shift pixels square, tiles_x per row (and the work-groups where the
 * device allows). */
__kernel void render(__global const Camera* camera, __global const real4* rays, const int tile_shift, const int tiles_x
                     PYCLRAY_SHAPES(PYCLRAY_SHAPE_ARG) PYCLRAY_OUTPUT_ARGS)
{
    const int i = get_global_id(0), j = get_global_id(1);
    const int width = camera->width, height = camera->height;
    if (i >= width || j >= height) return;
    const int tile = (j >> tile_shift) * tiles_x + (i >> tile_shift);  /* shifts: no division per pixel */
    const size_t index = (size_t)j * (size_t)width + (size_t)i;
    const real4 packed = rays[index];
    Ray ray;
    ray.origin = (real3)(0, 0, 0);
    ray.dir = packed.xyz;
    ray.a = packed.w;

    PYCLRAY_FIND_NEAREST
    PYCLRAY_WRITE(index)
}

#else

/* One work-item per ray: origin relative to the frame's reference point, unit direction. */
__kernel void cast(__global const Camera* camera, const int n_rays,
                   __global const real4* origins, __global const real4* directions
                   PYCLRAY_SHAPES(PYCLRAY_SHAPE_ARG) PYCLRAY_OUTPUT_ARGS)
{
    const int r = get_global_id(0);
    if (r >= n_rays) return;
    Ray ray;
    ray.origin = origins[r].xyz;
    ray.dir = directions[r].xyz;
    ray.a = dot(ray.dir, ray.dir);

    PYCLRAY_FIND_NEAREST
    PYCLRAY_WRITE((size_t)r)
}

#endif
