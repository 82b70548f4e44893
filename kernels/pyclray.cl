/* pyclray's kernels. The host puts before this file common.h, the generated struct header,
 * camera.h and the file of each shape type present, and selects what is compiled with -D options:
 *   PYCLRAY_FP64                        double precision
 *   PYCLRAY_CAST                        the batch-ray kernel instead of the camera kernel
 *   PYCLRAY_OCCLUDED                    (with PYCLRAY_CAST) the any-hit kernel instead
 *   PYCLRAY_BVH                         render: the bounded shapes through the BVH, not tile lists
 *   PYCLRAY_BOUNDED(X), PYCLRAY_UNBOUNDED(X)  the shape types present with and without bounds
 *   PYCLRAY_HAS_BOUNDED                 some bounded type is present (the BVH's buffers are passed)
 *   PYCLRAY_RAYS                        the kernel of the camera's rays (no shapes, no images)
 *   PYCLRAY_AOV_DEPTH/_NORMAL/_ID       which images are written (no buffer, no code for the others)
 *   PYCLRAY_SHAPES(X)                   X(Type, type) for each shape type present
 * Geometry and camera come in buffers, so moving a shape or the camera never recompiles.
 */

#if defined(PYCLRAY_AOV_NORMAL) || defined(PYCLRAY_AOV_ID)
#define PYCLRAY_TRACK_ID 1   /* the winner matters, not only its distance */
#endif

#if defined(PYCLRAY_CAST) || defined(PYCLRAY_BVH)
/* one argument pair per shape type present: the packed array and its length; the bounded types'
 * shapes are reached through the BVH's leaves, the others (planes) are each tested by every ray */
#define PYCLRAY_SHAPE_ARG(Type, type) , __global const Type* type##s, const int n_##type##s
#define PYCLRAY_FIRST(type) 0
#define PYCLRAY_END(type) n_##type##s
#define PYCLRAY_SHAPE_AT(type, q) (q)
#define PYCLRAY_LINEAR(X) PYCLRAY_UNBOUNDED(X)
#ifdef PYCLRAY_HAS_BOUNDED
#ifdef PYCLRAY_CAST
/* the BVH, and per leaf position its shape's anchor in world coordinates (xyz) and bounding radius (w) */
#define PYCLRAY_BVH_ARGS , __global const WideNode* nodes, __global const int* refs, __global const double4* anchors
#else
#define PYCLRAY_BVH_ARGS , __global const WideNode* nodes, __global const int* refs
#endif
#else
#define PYCLRAY_BVH_ARGS
#endif
#else
/* per shape type: the packed array, and for each tile of the image the shapes that can be seen
 * in it (type##_tile_list[type##_tile_start[tile] .. type##_tile_start[tile + 1]], increasing;
 * the host's conservative screen bounds, pyclray/culling.py): the others miss every ray there */
#define PYCLRAY_SHAPE_ARG(Type, type) \
    , __global const Type* type##s, __global const int* type##_tile_start, __global const int* type##_tile_list
#define PYCLRAY_FIRST(type) type##_tile_start[tile]
#define PYCLRAY_END(type) type##_tile_start[tile + 1]
#define PYCLRAY_SHAPE_AT(type, q) type##_tile_list[q]
#define PYCLRAY_LINEAR(X) PYCLRAY_SHAPES(X)
#define PYCLRAY_BVH_ARGS
#endif
#define PYCLRAY_KIND(Type, type) KIND_##Type,
enum { KIND_NONE = 0, PYCLRAY_SHAPES(PYCLRAY_KIND) KIND_COUNT };

/* Keep hit s of shape (id, kind, k) if it is the nearest so far; on an exact tie the lowest id
 * wins, whatever order the shapes are visited in (tiles, BVH). */
#ifdef PYCLRAY_TRACK_ID
#define PYCLRAY_CONSIDER(s, id, kind, k, q)                                          \
    if ((s) < best || ((s) == best && (s) < MISS && (id) < best_id)) {               \
        best = (s); best_id = (id); best_kind = (kind); best_k = (k); best_q = (q);  \
    }
#define PYCLRAY_BEST(start)                                                          \
    __typeof__(start) best = (start);                                                \
    int best_id = -1, best_kind = KIND_NONE, best_k = 0, best_q = -1;
#else
#define PYCLRAY_CONSIDER(s, id, kind, k, q) best = (s) < best ? (s) : best;
#define PYCLRAY_BEST(start) __typeof__(start) best = (start);
#endif

/* nearest hit with s > 0 over the shapes of one type that are tested one after the other */
#define PYCLRAY_NEAREST(Type, type)                                                 \
    for (int q = PYCLRAY_FIRST(type), end = PYCLRAY_END(type); q < end; ++q) {      \
        const int k = PYCLRAY_SHAPE_AT(type, q);                                    \
        const real s = type##_hit(&type##s[k], &ray);                               \
        PYCLRAY_CONSIDER(s, type##s[k].id, KIND_##Type, k, -1)                      \
    }
#define PYCLRAY_FIND_NEAREST                                                        \
    PYCLRAY_BEST(MISS)                                                              \
    PYCLRAY_LINEAR(PYCLRAY_NEAREST)

/* a leaf's shape at position q of the BVH (render): refs[q] = index * 8 + kind */
#define PYCLRAY_VISIT_KIND(Type, type)                                              \
    if (kind == KIND_##Type) {                                                      \
        const real s = type##_hit(&type##s[k], &ray);                               \
        PYCLRAY_CONSIDER(s, type##s[k].id, KIND_##Type, k, q)                       \
    }
#define PYCLRAY_VISIT(q)                                                            \
    {                                                                               \
        const int ref = refs[q], kind = ref & 7, k = ref >> 3;                      \
        PYCLRAY_BOUNDED(PYCLRAY_VISIT_KIND)                                         \
        limit = float_above(best);                                                  \
    }

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
                     PYCLRAY_BVH_ARGS PYCLRAY_SHAPES(PYCLRAY_SHAPE_ARG) PYCLRAY_OUTPUT_ARGS)
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
#if defined(PYCLRAY_BVH) && defined(PYCLRAY_HAS_BOUNDED)
    /* the bounded shapes through the BVH, whose boxes are in world axes around the eye */
    const BoxRay box = box_ray((float3)(0.0f), convert_float3(world_from_frame(camera, ray.dir)), 0.0f);
    float limit = float_above(best);
    PYCLRAY_TRAVERSE(nodes, box, limit, PYCLRAY_VISIT)
#endif
    PYCLRAY_WRITE(index)
}

#else

/* One work-item per ray, in world coordinates: origin (float64), unit direction (float64), and
 * the largest distance that counts (float64, limits[r * limit_stride]).
 *
 * Exact and independent of the other rays: each shape is tested from a point of the ray just
 * before it. For a bounded shape of anchor A and bounding radius R (its packed data is relative
 * to A), the ray's origin O moves along the unit direction D to O + s0 D, s0 = max(0, (A - O).D - R),
 * which no point of the shape precedes; the new origin relative to A, s0 D - (A - O), is taken in
 * float64 and rounded once. A ray from 1e8 away thus meets a sphere of radius 1e-4 with errors
 * relative to the sphere's size, as a camera next to it would; its distance is s0 + s (s: the
 * shape's own, from the new origin). Unbounded shapes (planes) take the world origin in float64. */
#define PYCLRAY_CAST_VISIT_KIND(Type, type)                                         \
    if (kind == KIND_##Type) {                                                      \
        const real s = type##_hit(&type##s[k], &moved);                             \
        const double t = s < MISS ? s0 + (double)s * length : INFINITY;             \
        PYCLRAY_CAST_TAKE(t, type##s[k].id, KIND_##Type, k, q)                      \
    }
#define PYCLRAY_CAST_VISIT(q)                                                       \
    {                                                                               \
        const int ref = refs[q], kind = ref & 7, k = ref >> 3;                      \
        double s0;                                                                  \
        const Ray moved = moved_ray(&ray, anchors[q], &s0);                         \
        PYCLRAY_BOUNDED(PYCLRAY_CAST_VISIT_KIND)                                    \
        PYCLRAY_CAST_LIMIT                                                          \
    }
#define PYCLRAY_CAST_LINEAR(Type, type)                                             \
    for (int q = 0; q < n_##type##s; ++q) {                                         \
        const real s = type##_hit(&type##s[q], &ray);                               \
        const double t = s < MISS ? (double)s * length : INFINITY;                  \
        PYCLRAY_CAST_TAKE(t, type##s[q].id, KIND_##Type, q, -1)                     \
    }

/* The ray from O + s0 D, s0 = max(0, (A - O).D - R), relative to anchor A: see above. */
inline Ray moved_ray(const Ray* ray, const double4 anchor, double* s0)
{
    const double3 O = ray->world, D = convert_double3(ray->dir_exact);
    const double3 F = anchor.xyz - O;
    const double along = (F.x * D.x + F.y * D.y) + F.z * D.z - anchor.w;
    *s0 = along > 0 ? along : 0;
    Ray moved = *ray;
    moved.origin = convert_real3(*s0 * D - F);
    return moved;
}

/* the setup shared by cast and occluded: the ray, and its box ray around the scene's anchor */
#define PYCLRAY_CAST_RAY                                                            \
    const int r = get_global_id(0);                                                 \
    if (r >= n_rays) return;                                                        \
    Ray ray;                                                                        \
    ray.world = origins[r].xyz;                                                     \
    ray.dir_exact = directions[r].xyz;                                              \
    ray.dir = convert_real3(ray.dir_exact);                                         \
    ray.a = dot(ray.dir, ray.dir);                                                  \
    ray.origin = convert_real3(ray.world);                                          \
    const real length = sqrt(ray.a);  /* |dir|: the shapes' s is along dir, not D */ \
    const double t_max = limits[(size_t)r * (size_t)limit_stride];

#define PYCLRAY_CAST_BOX                                                            \
    const double3 relative = ray.world - scene_anchor.xyz;                          \
    const float3 o = convert_float3(relative);                                      \
    /* o's rounding, with a wide margin */                                          \
    const float margin = 0x1p-20f * (fabs(o.x) + fabs(o.y) + fabs(o.z));              \
    const BoxRay box = box_ray(o, convert_float3(ray.dir_exact), margin);

#ifndef PYCLRAY_OCCLUDED

#define PYCLRAY_CAST_TAKE(t, id, kind, k, q) PYCLRAY_CONSIDER(t, id, kind, k, q)
#define PYCLRAY_CAST_LIMIT limit = float_above_wide(best);

__kernel void cast(__global const Camera* camera, const int n_rays,
                   __global const double4* origins, __global const double4* directions,
                   __global const double* limits, const int limit_stride, const double4 scene_anchor
                   PYCLRAY_BVH_ARGS PYCLRAY_SHAPES(PYCLRAY_SHAPE_ARG) PYCLRAY_OUTPUT_ARGS)
{
    PYCLRAY_CAST_RAY
    /* hits up to t_max count: best starts just above it */
    PYCLRAY_BEST(nextafter(t_max, (double)INFINITY))
    PYCLRAY_UNBOUNDED(PYCLRAY_CAST_LINEAR)
#ifdef PYCLRAY_HAS_BOUNDED
    {
        PYCLRAY_CAST_BOX
        float limit = float_above_wide(best);
        PYCLRAY_TRAVERSE(nodes, box, limit, PYCLRAY_CAST_VISIT)
    }
#endif
    const bool hit = best <= t_max && best < INFINITY;
    const size_t index = (size_t)r;
#ifdef PYCLRAY_AOV_DEPTH
    depth[index] = hit ? (real)best : MISS;
#endif
#ifdef PYCLRAY_AOV_NORMAL
    {
#ifdef PYCLRAY_HAS_BOUNDED
        if (hit && best_q >= 0) {  /* the winner's own ray, as it was tested */
            double s0;
            ray = moved_ray(&ray, anchors[best_q], &s0);
        }
#endif
        real3 normal = (real3)(0, 0, 0);
        if (hit) { PYCLRAY_SHAPES(PYCLRAY_NORMAL) }
        vstore3(normal, index, normal_out);
    }
#endif
#ifdef PYCLRAY_AOV_ID
    id_out[index] = hit ? best_id : -1;
#endif
}

#else

/* Whether any shape is hit at a distance up to t_max: the search stops at the first such hit. */
#define PYCLRAY_CAST_TAKE(t, id, kind, k, q) found = found || ((t) <= t_max && (t) < INFINITY);
#define PYCLRAY_CAST_LIMIT if (found) limit = -INFINITY;

__kernel void occluded(const int n_rays, __global const double4* origins, __global const double4* directions,
                       __global const double* limits, const int limit_stride, const double4 scene_anchor
                       PYCLRAY_BVH_ARGS PYCLRAY_SHAPES(PYCLRAY_SHAPE_ARG), __global char* occluded_out)
{
    PYCLRAY_CAST_RAY
    bool found = false;
    PYCLRAY_UNBOUNDED(PYCLRAY_CAST_LINEAR)
#ifdef PYCLRAY_HAS_BOUNDED
    if (!found) {
        PYCLRAY_CAST_BOX
        float limit = float_above_wide(t_max);
        PYCLRAY_TRAVERSE(nodes, box, limit, PYCLRAY_CAST_VISIT)
    }
#endif
    occluded_out[r] = found ? 1 : 0;
}

#endif

#endif
