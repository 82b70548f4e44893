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
 * rays nor on the order of its visits. all_hits counts them too and writes the first hit_capacity
 * of them into the ray's rows (r * hit_capacity on), sorted there by distance (then kind, entry,
 * triangle: the same order at any batch); the host casts the rays with more hits again with room
 * for all (the same visits find the same hits) and gathers the rows. */

/* a hit at distance t (float64, from the ray's origin) of entry k of a kind (its triangle sub in
 * mesh instances, -1 elsewhere): counted, and stored where this is all_hits */
#ifdef PYCLRAY_STORE_HITS
#define ALLHITS_STORE(t, kind, k, sub)                                              \
    if (n_hits < hits_room) {                                                        \
        const size_t row = (size_t)(hits_at + n_hits);                                   \
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
        PYCLRAY_CAST_REBASED(Type, type, k, moved.world)                            \
        PYCLRAY_ALL_HITS_##type(&rebased, &moved, s0, KIND_##type, k)               \
    }
#undef PYCLRAY_CAST_LINEAR
#define PYCLRAY_CAST_LINEAR(Type, type)                                             \
    for (int q = 0; q < n_##type##s; ++q) {                                         \
        PYCLRAY_CAST_REBASED(Type, type, q, start.world)                            \
        PYCLRAY_ALL_HITS_##type(&rebased, &start, t_min, KIND_##type, q)            \
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

/* Each work-item's rays traverse the BVH together where leaves are blocks of triangles, a step of
 * each in turn (as cast's: kernels/cast.cl, whose reasons hold here, where no hit shortens a ray's
 * traversal): each ray's own steps are the same, in the same order, as one ray's traversal. A ray's
 * state (HitsRay) lives between its steps in the work-item's memory: hits_start sets it up (the ray,
 * its unbounded shapes, its box ray, the root pushed), hits_step is one step, hits_end sorts its rows
 * and writes its count. */
/* With PYCLRAY_AOV_SURFACE (count_hits for occupancy: engine/queries/closest.py), also whether the
 * count's parity is the point's inside (surface_out[r]: 0 it is; 3 undecided: a crossing within
 * rounding of the point, kernels/mesh_blocks.cl's MESH_BLOCK_DOUBT, or a triangle within
 * surface_band of it, or at distance 0 (on the surface, or a rounding off it), whose point the
 * host decides exactly; 2 not known here: the host asks the closest-point query's distance), and
 * the crossings signed, +1 out of a mesh and -1 into it, summed (surface_signed_out: a closed
 * mesh's winding number, sign="winding"). Only a point in the box of some leaf may: that leaf's box is entered at 0, as
 * box_ray's margin (2^-20 of the origin's size) makes it for every box that holds the float64
 * origin, or within the closest-point query's 4 times smaller margin of the same float boxes
 * (kernels/closest.cl). The traversal notes the first SURFACE_LEAVES such leaves as it reaches them
 * (their entry is the one it found: no box is tested for this), and tests their shapes as the
 * closest-point query's search does, for a squared distance within surface_band's square: the
 * same <type>_closest of the same float64 world entries (the closest-point query's leaf, surface_leaf_codes: per place of this
 * program's refs where a leaf starts, that leaf in the query's refs), a squared distance of 0,
 * unless the point lies beyond the leaf's slab (surface_slabs: engine/queries/closest.py's
 * leaf_slabs), where none of them is at 0 (most leaves of points near a surface: a dot product
 * instead of each triangle's nearest point). A
 * ray with more such leaves, or one that tests every bounded shape without the boxes, is not known
 * here (2: the host asks the closest-point query). */
#ifdef PYCLRAY_AOV_SURFACE
#define SURFACE_LEAVES 8
#undef PYCLRAY_LEAF_ENTERED
#define PYCLRAY_LEAF_ENTERED(entry)                                                 \
    if ((entry) == 0.0f) {                                                          \
        if (S->n_surface_ < SURFACE_LEAVES) S->surface_leaf_[S->n_surface_] = first; \
        S->n_surface_ += S->n_surface_ <= SURFACE_LEAVES;                           \
    }
#define HITS_SURFACE_STATE(X) X(int, n_surface) X(int, undecided) X(int, signed_count)
/* the signed count of the crossings (kernels/mesh_blocks.cl: +1 out, -1 in): surface_signed_out */
#define HITS_SIGNED(change) signed_count += (change);
/* a crossing whose sign of s the rounding may have turned (kernels/mesh_blocks.cl: MESH_BLOCK_DOUBT):
 * the point is undecided (3), whatever its count and surface */
#define HITS_UNDECIDED undecided = 1
#define HITS_VISIT_ALL(q) n_surface = SURFACE_LEAVES + 1; PYCLRAY_CAST_VISIT(q)
#define HITS_ON_SURFACE_KIND(Type, type)                                            \
    if (kind == KIND_##type && !(type##_closest(&type##_surface_worlds[k], p).d2 > reach * reach)) surface = 3;
#else
#define HITS_SURFACE_STATE(X)
#define HITS_VISIT_ALL(q) PYCLRAY_CAST_VISIT(q)
#endif
#define HITS_RAY_STATE(X) X(RayPacket, ray) X(double, t_max) X(double, t_min) X(int, r) X(real, ray_length) X(int, n_hits) \
    HITS_SURFACE_STATE(X)
#define HITS_TRAVERSAL_STATE(X) X(RayPacket, moved) X(double4, moved_anchor) X(double, s0) X(bool, near) \
    X(float3, o) X(float3, box_direction) X(BoxRay, box) X(float, limit)
#define HITS_STATE_FIELD(T, name) T name##_;
#define HITS_STATE_SAVE(T, name) S->name##_ = name;
typedef struct {
    HITS_RAY_STATE(HITS_STATE_FIELD)
#ifdef PYCLRAY_AOV_SURFACE
    int surface_leaf_[SURFACE_LEAVES];
#endif
#ifdef PYCLRAY_HAS_BOUNDED
    HITS_TRAVERSAL_STATE(HITS_STATE_FIELD)
    int top_;
    int stack_child_[BVH_STACK];
    float stack_entry_[BVH_STACK];
#endif
} HitsRay;

inline void hits_start(HitsRay* S, const int r, const CastDirection* direction, PYCLRAY_PARAMETERS)
{
    PYCLRAY_CAST_RAY
    int n_hits = 0;
#ifdef PYCLRAY_AOV_SURFACE
    int n_surface = 0, undecided = 0, signed_count = 0;
#endif
#ifdef PYCLRAY_STORE_HITS
    const long hits_at = (long)r * hit_capacity;
    const int hits_room = hit_capacity;
#endif
    PYCLRAY_UNBOUNDED(PYCLRAY_CAST_LINEAR)
#ifdef PYCLRAY_HAS_BOUNDED
    {
        PYCLRAY_CAST_BOX
        float limit = float_above_wide(t_max);
        S->top_ = 0;
        PYCLRAY_CAST_BOUNDED(HITS_VISIT_ALL, S->stack_child_[0] = 0; S->stack_entry_[0] = 0.0f; S->top_ = 1;)
        HITS_TRAVERSAL_STATE(HITS_STATE_SAVE)
    }
#endif
    HITS_RAY_STATE(HITS_STATE_SAVE)
}

#ifdef PYCLRAY_HAS_BOUNDED
/* the names the visit's macros use, bound to the state's (as in kernels/cast.cl), but for the stack
 * and its top, locals (a mesh instance's own traversal declares locals of those names in its block) */
#define ray (S->ray_)
#define t_max (S->t_max_)
#define t_min (S->t_min_)
#define ray_length (S->ray_length_)
#define n_hits (S->n_hits_)
#define moved (S->moved_)
#define moved_anchor (S->moved_anchor_)
#define s0 (S->s0_)
#define near (S->near_)
#define o (S->o_)
#define box_direction (S->box_direction_)
#define limit (S->limit_)
#ifdef PYCLRAY_AOV_SURFACE
#define undecided (S->undecided_)
#define signed_count (S->signed_count_)
#endif
inline void hits_step(HitsRay* S, PYCLRAY_PARAMETERS)
{
    int top = S->top_;
    int* stack_child = S->stack_child_;
    float* stack_entry = S->stack_entry_;
#ifdef PYCLRAY_STORE_HITS
    const long hits_at = (long)S->r_ * hit_capacity;
    const int hits_room = hit_capacity;
#endif
    PYCLRAY_TRAVERSE_STEP(nodes, S->box_, limit, stack_child, stack_entry, top, 0, PYCLRAY_CAST_LEAF_MASK, PYCLRAY_CAST_VISIT)
    S->top_ = top;
}
#undef ray
#undef t_max
#undef t_min
#undef ray_length
#undef n_hits
#undef moved
#undef moved_anchor
#undef s0
#undef near
#undef o
#undef box_direction
#undef limit
#ifdef PYCLRAY_AOV_SURFACE
#undef undecided
#undef signed_count
#endif
#endif

inline void hits_end(const HitsRay* S, PYCLRAY_PARAMETERS)
{
    const int r = S->r_, n_hits = S->n_hits_;
#ifdef PYCLRAY_STORE_HITS
    /* the ray's rows sorted, nearest first (insertion sort: a few hits a ray) */
    const long hits_at = (long)r * hit_capacity;
    const int n = n_hits < hit_capacity ? n_hits : hit_capacity;
    for (int i = 1; i < n; ++i) {
        for (int j = i; j > 0 && allhits_before(hit_t, hit_kind, hit_k, hit_sub, (size_t)(hits_at + j), (size_t)(hits_at + j - 1)); --j) {
            const size_t a = (size_t)(hits_at + j), b = (size_t)(hits_at + j - 1);
            const double t = hit_t[a]; hit_t[a] = hit_t[b]; hit_t[b] = t;
            const int kind = hit_kind[a]; hit_kind[a] = hit_kind[b]; hit_kind[b] = kind;
            const int k = hit_k[a]; hit_k[a] = hit_k[b]; hit_k[b] = k;
            const int sub = hit_sub[a]; hit_sub[a] = hit_sub[b]; hit_sub[b] = sub;
        }
    }
#endif
    hit_counts[r] = n_hits;
#ifdef PYCLRAY_AOV_SURFACE
    /* a point within surface_band of a triangle (of the leaves whose boxes hold it) is undecided
     * too: its count is exact on the corners as rounded relative to it, which may have moved the
     * surface across it (kernels/mesh_blocks.cl, MESH_BLOCK_DOUBT); and at distance 0 (even count)
     * on the surface, which the host confirms exactly */
    uchar surface = 0;
    if (S->undecided_) {
        surface = 3;
    } else if (S->n_surface_ > SURFACE_LEAVES) {
        surface = 2;
    } else {
        const double3 p = S->ray_.world;
        /* the band, and the closest-point test's own rounding (a few eps64 of the point's size) */
        const double reach = surface_band + 0x1p-50 * (fabs(p.x) + fabs(p.y) + fabs(p.z));
        for (int j = 0; j < S->n_surface_ && surface != 3; ++j) {
            /* the leaf's slab first (surface_slabs: its triangles' dot products with a unit
             * direction lie in [lo, hi], widened by the host over the rounding there and of the
             * closest-point test's nearest points): a point beyond it by more than the rounding of
             * its own dot product and the band is farther than the band from each of them */
            __global const double* slab = surface_slabs + 5 * (size_t)S->surface_leaf_[j];
            const double along = slab[0] * p.x + slab[1] * p.y + slab[2] * p.z;
            const double rounding = 0x1p-40 * (fabs(p.x) + fabs(p.y) + fabs(p.z)) + reach;  /* SLAB_SIZE_MARGIN */
            if (along < slab[3] - rounding || along > slab[4] + rounding) continue;
            const int code = surface_leaf_codes[S->surface_leaf_[j]];
            const int first = (~code) >> 3, count = (~code) & 7;
            for (int q = first; q < first + count && surface != 3; ++q) {
                const int ref = surface_refs[q], kind = ref & 15, k = ref >> 4;
                PYCLRAY_BOUNDED(HITS_ON_SURFACE_KIND)
            }
        }
    }
    surface_out[r] = surface;
    surface_signed_out[r] = S->signed_count_;
#endif
}

PYCLRAY_KERNELS_BEGIN
/* one work-item per group of CAST_GROUP places of the order, as cast's (kernels/rays.h:
 * PYCLRAY_GROUP_TRAVERSAL) */
PYCLRAY_WORK_ITEM_FUNCTION void hits_group(const int group, PYCLRAY_PARAMETERS)
{
    PYCLRAY_CAST_GROUP_SETUP
    PYCLRAY_GROUP_TRAVERSAL(HitsRay, hits_start, hits_step, hits_end)
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
