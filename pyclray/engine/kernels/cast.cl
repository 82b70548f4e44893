/* The cast query: the nearest hit of each ray of a batch given in world coordinates (origins,
 * directions and limits in float64), its distance, normal and id (pyclray/engine/queries/cast.py). The host
 * puts before this file common.h, lanes.h, the generated struct header, shapes.h, the BVH's headers,
 * cast.h, the file of each shape type present and rays.h. */

/* the nearest hit so far (float64 distance), on an exact tie the lowest id */
#ifdef PYCLRAY_TRACK_ID
/* The id of the shape of this kind at index k of its type's array (-1 for none): read only for the
 * winner and on exact ties, not at every nearer hit (a read of the packed entries that missed the
 * cache: a fifth of the kernel's time on 100,000 spheres). */
#define PYCLRAY_CAST_ID_OF(Type, type) \
    if (id_kind == KIND_##type) id_value = PYCLRAY_CAST_MODE(PYCLRAY_CAST_ID_, type)(type, id_k);
#define PYCLRAY_CAST_ID_ENTRY(type, k) type##s[k].id
#define PYCLRAY_CAST_ID(value, kind, k)                                             \
    {                                                                               \
        const int id_kind = (kind), id_k = (k);                                     \
        int id_value = -1;                                                          \
        PYCLRAY_SHAPES(PYCLRAY_CAST_ID_OF)                                          \
        value = id_value;                                                           \
    }
#define PYCLRAY_CAST_TAKE(t, id, kind, k, q)                                        \
    {                                                                               \
        /* t > t_min: a shape's s > 0 from the ray's start may still round t_min + s to t_min */ \
        bool take = (t) < best && (t) > t_min;                                      \
        if (!take && (t) == best && (t) < INFINITY && (t) > t_min) {                               \
            int best_id;                                                            \
            PYCLRAY_CAST_ID(best_id, best_kind, best_k)                             \
            take = (id) < best_id;                                                  \
        }                                                                           \
        if (take) { best = (t); best_kind = (kind); best_k = (k); best_q = (q); }   \
    }
/* The packed entry of a new nearest hit, asked for from memory: the traversal reads only the
 * world entries, and the id (and the normal's space) read from it at the end would otherwise miss
 * the cache (docs/benchmarks.md: PYCLRAY_CAST_PREFETCH_WINNER) */
#define PYCLRAY_CAST_PREFETCH_WINNER(Type, type, k)                                 \
    if (best_kind == KIND_##type && best_k == (k)) { CAST_PREFETCH(&type##s[k], sizeof(Type)) }
#else
#define PYCLRAY_CAST_TAKE(t, id, kind, k, q) best = (t) < best && (t) > t_min ? (t) : best;
#define PYCLRAY_CAST_PREFETCH_WINNER(Type, type, k)
#endif
#define PYCLRAY_CAST_LIMIT limit = float_above_wide(best);
#define PYCLRAY_CAST_REACH best  /* no hit of the shape precedes s0 */
#define PYCLRAY_CAST_NORMAL(Type, type)                                             \
    if (best_kind == KIND_##type) { PYCLRAY_CAST_MODE(PYCLRAY_CAST_NORMAL_, type)(Type, type) }
#define PYCLRAY_CAST_NORMAL_ENTRY(Type, type)                                       \
    {                                                                               \
        PYCLRAY_CAST_REBASED(Type, type, best_k, ray.world)                         \
        normal = PYCLRAY_NORMAL_##type(&rebased, &ray, &world_axes, MISS, 1);       \
    }
/* the winner's index within its shape (PYCLRAY_CAST_PRIMITIVE_OF_<type>: its packed entry's, or a
 * mesh instance's triangle); in blocks its key, -2 - key, which the host turns into the triangle's
 * index (engine/queries/cast.py: the block lanes' entries) */
#define PYCLRAY_CAST_PRIMITIVE(Type, type)                                          \
    if (best_kind == KIND_##type) { PYCLRAY_CAST_MODE(PYCLRAY_CAST_PRIMITIVE_, type)(Type, type) }
#define PYCLRAY_CAST_PRIMITIVE_ENTRY(Type, type)                                    \
    {                                                                               \
        PYCLRAY_CAST_REBASED(Type, type, best_k, ray.world)                         \
        primitive = PYCLRAY_CAST_PRIMITIVE_OF_##type(&rebased, &ray);               \
    }
#define PYCLRAY_CAST_PRIMITIVE_BLOCKS(Type, type) primitive = -2 - best_k;
/* the winner's barycentrics (a triangle's; 0, 0 for other shapes) */
#define PYCLRAY_CAST_BARYCENTRIC(Type, type)                                        \
    if (best_kind == KIND_##type) { PYCLRAY_CAST_MODE(PYCLRAY_CAST_BARYCENTRIC_, type)(Type, type) }
#define PYCLRAY_CAST_BARYCENTRIC_ENTRY(Type, type)                                  \
    {                                                                               \
        PYCLRAY_CAST_REBASED(Type, type, best_k, ray.world)                         \
        PYCLRAY_CAST_BARYCENTRIC_OF_##type(&rebased, &ray, &u, &v);                 \
    }
#define PYCLRAY_CAST_BARYCENTRIC_BLOCKS(Type, type)                                 \
    mesh_block_barycentric(MESH_BLOCKS(type) + 8 * (size_t)(best_k >> 3), best_k & 7, &ray, &u, &v);

/* Each work-item's rays (a group of CAST_GROUP) traverse the BVH together: a step of each in turn
 * (kernels/bvh_ray.h's PYCLRAY_TRAVERSE_STEP: a node's children pushed, or a leaf's shapes tested), so
 * that the misses of one ray's next node or leaf overlap the others' work and misses, where one ray
 * alone waits for each of its reads in turn (a node, its child, ..., a leaf's ref, its block: on a
 * mesh of 1,000,000 triangles, whose cast data is twice the L3 cache, most of the time). Each ray's
 * own steps are the same, in the same order, as one ray's traversal: no bit of any result depends
 * on the interleaving (docs/benchmarks.md, "Mesh cast's traversal"). A ray's state
 * (CastRay) lives between its steps in the work-item's memory: cast_start sets it up (the ray, its
 * unbounded shapes, its box ray, the root pushed), cast_step is one step, cast_end writes its
 * results. */
/* the state's parts, (type, name) each, kept as name_ and saved from cast_start's local of that name:
 * the ray's, and (with bounded shapes) its traversal's */
#define CAST_RAY_STATE(X) \
    X(RayPacket, ray) X(double, t_max) X(double, t_min) X(double, best) X(int, r) X(int, best_kind) X(int, best_k) X(int, best_q) X(real, ray_length)
#define CAST_TRAVERSAL_STATE(X) X(RayPacket, moved) X(double4, moved_anchor) X(double, s0) X(bool, near) \
    X(float3, o) X(float3, box_direction) X(BoxRay, box) X(float, limit)
#define CAST_STATE_FIELD(T, name) T name##_;
#define CAST_STATE_SAVE(T, name) S->name##_ = name;
typedef struct {
    CAST_RAY_STATE(CAST_STATE_FIELD)
#ifdef PYCLRAY_HAS_BOUNDED
    CAST_TRAVERSAL_STATE(CAST_STATE_FIELD)
    int top_;
    int stack_child_[BVH_STACK];
    float stack_entry_[BVH_STACK];
#endif
} CastRay;

/* (always inlined on PoCL's CPU device, as the functions above: a step is called per ray in the
 * interleaving loop) */
inline void cast_start(CastRay* S, const int r, const CastDirection* direction, PYCLRAY_PARAMETERS)
{
    PYCLRAY_CAST_RAY
    /* hits below t_max count (tmin < t < tmax, open at both ends): best starts at t_max, and a hit
     * replaces it only where nearer (an exact tie with t_max has no winner to beat: KIND_NONE's id) */
    double best = t_max;
    int best_kind = KIND_NONE, best_k = 0, best_q = -1;
    PYCLRAY_UNBOUNDED(PYCLRAY_CAST_LINEAR)
#ifdef PYCLRAY_HAS_BOUNDED
    {
        PYCLRAY_CAST_BOX
        float limit = float_above_wide(best);
        S->top_ = 0;
        PYCLRAY_CAST_BOUNDED(PYCLRAY_CAST_VISIT, S->stack_child_[0] = 0; S->stack_entry_[0] = 0.0f; S->top_ = 1;)
        CAST_TRAVERSAL_STATE(CAST_STATE_SAVE)
    }
#endif
    CAST_RAY_STATE(CAST_STATE_SAVE)
}

#ifdef PYCLRAY_HAS_BOUNDED
/* the names the visit's macros use (PYCLRAY_CAST_VISIT and what it expands to), bound to the state's
 * (none may be a shape type's name, which the macros paste: the box ray is passed as S->box_) */
#define ray (S->ray_)
#define t_min (S->t_min_)
#define ray_length (S->ray_length_)
#define best (S->best_)
#define best_kind (S->best_kind_)
#define best_k (S->best_k_)
#define best_q (S->best_q_)
#define moved (S->moved_)
#define moved_anchor (S->moved_anchor_)
#define s0 (S->s0_)
#define near (S->near_)
#define o (S->o_)
#define box_direction (S->box_direction_)
#define limit (S->limit_)
#define top (S->top_)
#define stack_child (S->stack_child_)
#define stack_entry (S->stack_entry_)
inline void cast_step(CastRay* S, PYCLRAY_PARAMETERS)
{
    PYCLRAY_TRAVERSE_STEP(nodes, S->box_, limit, stack_child, stack_entry, top, 1, PYCLRAY_CAST_LEAF_MASK, PYCLRAY_CAST_VISIT)
}
#undef ray
#undef t_min
#undef ray_length
#undef best
#undef best_kind
#undef best_k
#undef best_q
#undef moved
#undef moved_anchor
#undef s0
#undef near
#undef o
#undef box_direction
#undef limit
#undef top
#undef stack_child
#undef stack_entry
#endif

inline void cast_end(const CastRay* S, PYCLRAY_PARAMETERS)
{
    RayPacket ray = S->ray_;
    const double best = S->best_, t_max = S->t_max_;
    const int best_kind = S->best_kind_, best_k = S->best_k_, best_q = S->best_q_;
    const bool hit = best < t_max;  /* (t_max may be inf: a hit is finite) */
    const size_t index = (size_t)S->r_;
#ifdef PYCLRAY_AOV_DEPTH
    depth_out[index] = hit ? (real)best : MISS;
#endif
#if defined(PYCLRAY_AOV_NORMAL) || defined(PYCLRAY_AOV_PRIMITIVE) || defined(PYCLRAY_AOV_BARYCENTRIC)
    /* the winner's own ray, as it was tested */
#ifdef PYCLRAY_HAS_BOUNDED
    if (hit && best_q >= 0) {
        double s0;
        bool near;
        ray = moved_ray(&ray, anchors[best_q], S->t_min_, &s0, &near);
    } else
#endif
    if (hit && S->t_min_ > 0) {  /* an unbounded winner, tested from the ray's start */
        ray.world = ray.world + S->t_min_ * ray.dir_exact;
    }
#endif
#ifdef PYCLRAY_AOV_NORMAL
    {
        vec3v normal = v3(0, 0, 0);
        /* each shape is rebased on the world's axes (kernels/cast.h): its normal is turned by them */
        const Basis world_axes = {(real4)(1, 0, 0, 0), (real4)(0, 1, 0, 0), (real4)(0, 0, 1, 0)};
        if (hit) { PYCLRAY_SHAPES(PYCLRAY_CAST_NORMAL) }
        normal_out[3 * index] = normal.x;
        normal_out[3 * index + 1] = normal.y;
        normal_out[3 * index + 2] = normal.z;
    }
#endif
#ifdef PYCLRAY_AOV_PRIMITIVE
    {
        int primitive = -1;
        if (hit) { PYCLRAY_SHAPES(PYCLRAY_CAST_PRIMITIVE) }
        primitive_out[index] = primitive;
    }
#endif
#ifdef PYCLRAY_AOV_BARYCENTRIC
    {
        real u = 0, v = 0;
        if (hit) { PYCLRAY_SHAPES(PYCLRAY_CAST_BARYCENTRIC) }
        barycentric_out[2 * index] = u;
        barycentric_out[2 * index + 1] = v;
    }
#endif
#ifdef PYCLRAY_AOV_ID
    {
        int best_id;
        PYCLRAY_CAST_ID(best_id, hit ? best_kind : KIND_NONE, best_k)
        id_out[index] = best_id;
    }
#endif
}

PYCLRAY_KERNELS_BEGIN
/* one work-item per group of CAST_GROUP places of the order (kernels/rays.h: PYCLRAY_GROUP_TRAVERSAL) */
PYCLRAY_WORK_ITEM_FUNCTION void cast_group(const int group, PYCLRAY_PARAMETERS)
{
    PYCLRAY_CAST_GROUP_SETUP
    PYCLRAY_GROUP_TRAVERSAL(CastRay, cast_start, cast_step, cast_end)
}

__kernel void cast(PYCLRAY_PARAMETERS)
{
    const int group = get_global_id(0);
    if (group * CAST_GROUP < n_rays) cast_group(group, PYCLRAY_ARGUMENTS);
}
