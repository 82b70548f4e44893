/* The hit counts: count_hits (how many times each ray of a batch given in world coordinates crosses
 * the shapes' surfaces between t_min and t_max) and all_hits (each of those hits: its distance and
 * what it hit, nearest first) (pyclray/engine/queries/hits.py). The host puts before this file
 * common.h, lanes.h, the generated struct header, shapes.h, the BVH's headers, cast.h, the file of
 * each shape type present (with PYCLRAY_ALL_HITS: each type's <type>_hits, every hit of one entry;
 * with PYCLRAY_TIE_RULE: kernels/mesh.cl's tie rule, so that a crossing through a shared edge or
 * vertex counts once) and rays.h, whose visit this file gives what a hit does.
 *
 * Every entry a ray may meet is visited (the traversal's limit stays at t_max: no hit ends it), each
 * tested from the ray moved to just before it (kernels/rays.h: moved_ray, never before t_min), and
 * each of its hits s > 0 there with t < t_max counted: a ray's count does not depend on the other
 * rays nor on the order of its visits. all_hits runs after count_hits on the same rays (the host
 * sums the counts into each ray's rows): the same visits find the same hits, written into the ray's
 * rows and sorted there by distance (then kind, entry, triangle: the same order at any batch). */

/* a hit at distance t (float64, from the ray's origin) of entry k of a kind (its triangle sub in
 * mesh instances, -1 elsewhere): counted, and stored where this is all_hits */
#ifdef PYCLRAY_STORE_HITS
#define ALLHITS_STORE(t, kind, k, sub)                                              \
    if (n_hits < capacity) {                                                        \
        const size_t row = (size_t)(at + n_hits);                                   \
        hit_t[row] = (t);                                                           \
        hit_kind[row] = (kind);                                                     \
        hit_k[row] = (k);                                                           \
        hit_sub[row] = (sub);                                                       \
    }
#else
#define ALLHITS_STORE(t, kind, k, sub)
#endif
#define ALLHITS_TAKE(t, kind, k, sub)                                               \
    if ((t) < t_max) {                                                              \
        ALLHITS_STORE(t, kind, k, sub)                                              \
        ++n_hits;                                                                   \
    }

/* kernels/rays.h's visit, for every hit: a leaf's block of triangles reports each lane hit (its key
 * k * 8 + lane), an entry each of its <type>_hits (PYCLRAY_ALL_HITS_<type>: programs.py, or the
 * type's own, kernels/instance.cl), the unbounded shapes theirs from the ray's start */
#define PYCLRAY_CAST_TAKE(t, id, kind, k, q) ALLHITS_TAKE(t, kind, k, -1)
#define PYCLRAY_CAST_LIMIT
#define PYCLRAY_CAST_REACH t_max
#define PYCLRAY_CAST_PREFETCH_WINNER(Type, type, k)
#undef PYCLRAY_CAST_TEST_ENTRY
#define PYCLRAY_CAST_TEST_ENTRY(Type, type)                                         \
    {                                                                               \
        PYCLRAY_CAST_FRAMED(Type, type, k, moved.world)                             \
        PYCLRAY_ALL_HITS_##type(&framed, &moved, s0, KIND_##type, k)                \
    }
#undef PYCLRAY_CAST_LINEAR
#define PYCLRAY_CAST_LINEAR(Type, type)                                             \
    for (int q = 0; q < n_##type##s; ++q) {                                         \
        PYCLRAY_CAST_FRAMED(Type, type, q, start.world)                             \
        PYCLRAY_ALL_HITS_##type(&framed, &start, t_min, KIND_##type, q)             \
    }
/* an entry's two candidates (<type>_hits: MISS where there is none), from the ray at distance from */
#define ALLHITS_TWO(type, shape, ray, from, kind, k)                                \
    {                                                                               \
        real first_, second_;                                                       \
        type##_hits(shape, ray, &first_, &second_);                                 \
        if (first_ < MISS) ALLHITS_TAKE((from) + (double)first_ * ray_length, kind, k, -1) \
        if (second_ < MISS) ALLHITS_TAKE((from) + (double)second_ * ray_length, kind, k, -1) \
    }

#ifdef PYCLRAY_STORE_HITS
/* whether hit row i goes before row j: nearer, then by kind, entry and triangle */
inline bool allhits_before(__global const double* hit_t, __global const int* hit_kind, __global const int* hit_k,
                           __global const int* hit_sub, const size_t i, const size_t j)
{
    if (hit_t[i] != hit_t[j]) return hit_t[i] < hit_t[j];
    if (hit_kind[i] != hit_kind[j]) return hit_kind[i] < hit_kind[j];
    if (hit_k[i] != hit_k[j]) return hit_k[i] < hit_k[j];
    return hit_sub[i] < hit_sub[j];
}
#endif

PYCLRAY_KERNELS_BEGIN
inline void hits_ray(const int r, const CastDirection* direction, PYCLRAY_PARAMETERS)
{
    PYCLRAY_CAST_RAY
    int n_hits = 0;
#ifdef PYCLRAY_STORE_HITS
    const long at = hit_offsets[r];
    const int capacity = (int)(hit_offsets[r + 1] - at);
#endif
    PYCLRAY_UNBOUNDED(PYCLRAY_CAST_LINEAR)
#ifdef PYCLRAY_HAS_BOUNDED
    {
        PYCLRAY_CAST_BOX
        float limit = float_above_wide(t_max);
        PYCLRAY_CAST_BOUNDED(PYCLRAY_CAST_VISIT, PYCLRAY_TRAVERSE(nodes, box, limit, 0, PYCLRAY_CAST_LEAF_MASK, PYCLRAY_CAST_VISIT))
    }
#endif
#ifdef PYCLRAY_STORE_HITS
    /* the ray's rows sorted, nearest first (insertion sort: a few hits a ray) */
    const int n = n_hits < capacity ? n_hits : capacity;
    for (int i = 1; i < n; ++i) {
        for (int j = i; j > 0 && allhits_before(hit_t, hit_kind, hit_k, hit_sub, (size_t)(at + j), (size_t)(at + j - 1)); --j) {
            const size_t a = (size_t)(at + j), b = (size_t)(at + j - 1);
            const double t = hit_t[a]; hit_t[a] = hit_t[b]; hit_t[b] = t;
            const int kind = hit_kind[a]; hit_kind[a] = hit_kind[b]; hit_kind[b] = kind;
            const int k = hit_k[a]; hit_k[a] = hit_k[b]; hit_k[b] = k;
            const int sub = hit_sub[a]; hit_sub[a] = hit_sub[b]; hit_sub[b] = sub;
        }
    }
#else
    hit_counts[r] = n_hits;
#endif
}

PYCLRAY_WORK_ITEM_FUNCTION void hits_group(const int group, PYCLRAY_PARAMETERS)
{
    PYCLRAY_CAST_GROUP_SETUP
    for (int l = 0; l < in_group; ++l)
        hits_ray(rays[l], &directions_of[l], PYCLRAY_ARGUMENTS);
}

#ifdef PYCLRAY_STORE_HITS
__kernel void all_hits(PYCLRAY_PARAMETERS)
#else
__kernel void count_hits(PYCLRAY_PARAMETERS)
#endif
{
    const int group = get_global_id(0);
    if (group * CAST_GROUP < n_rays) hits_group(group, PYCLRAY_ARGUMENTS);
}
