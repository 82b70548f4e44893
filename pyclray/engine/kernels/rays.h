/* A batch of rays given in world coordinates (the cast and any-hit queries: kernels/cast.cl,
 * kernels/anyhit.cl), traced one at a time: each ray's setup, its moves to the shapes' anchors, and
 * its visit of the BVH's leaves and of the unbounded shapes. The query's file defines what a hit does
 * (PYCLRAY_CAST_TAKE, PYCLRAY_CAST_LIMIT, PYCLRAY_CAST_REACH, PYCLRAY_CAST_PREFETCH_WINNER). */

#if LANES != 1
#error "cast traces one ray at a time (LANES 1)"
#endif

/* One ray at a time (CAST_GROUP of them per work-item, below), in world coordinates: origin
 * (float64), unit direction (float64), and the largest distance that counts (float64,
 * limits[r * limit_stride]). Where ordered is 1 the host has found a coherent order of the rays
 * (neighbouring rays then walk the same nodes): place i of the batch traces ray r = order[i], the
 * i-th of that order, read and written at its own place r (the rays stay where the caller put
 * them: gathering them on the host cost more than the kernel's scattered reads); else ray i.
 *
 * Exact and independent of the other rays: each shape is tested from a point of the ray just
 * before it, as a camera there would test it. For a bounded shape of anchor A and bounding radius
 * R, the ray's origin O moves along the unit direction D to O' = O + s0 D, s0 = max(0, (A - O).D - R),
 * which no point of the shape precedes (float64); the shape is then rebased on O' from its float64
 * world entry (kernels/cast.h: its coordinates relative to O' rounded once, and the terms O' decides,
 * such as a sphere's c = |C - O'|^2 - r^2, in float64) and tested from the space's origin. A ray
 * from 1e8 away thus meets a sphere of radius 1e-4 with errors relative to the sphere's size, and a
 * ray starting on a surface, or 1e-9 off it, knows which side it starts on; its distance is s0 + s
 * (s: the shape's own, from O'). Unbounded shapes (planes) are rebased on the ray's own origin. */
#define PYCLRAY_CAST_REBASED(Type, type, k, from)                                   \
    Type rebased = type##s[k];                                                      \
    {                                                                               \
        const Space space = {(from)};                                               \
        type##_rebase(&type##_worlds[k], &rebased, &space);                         \
    }
/* A type's entries are tested one by one (PYCLRAY_CAST_MODE_<type> ENTRY), or in blocks of a leaf's
 * entries that its kernel file tests at once (BLOCKS: a mesh's triangles, kernels/mesh.cl); the
 * mode also says where the winner's id and normal come from, and what a leaf's prefetch asks for */
#define PYCLRAY_CAST_MODE(what, type) PYCLRAY_CAT(what, PYCLRAY_CAST_MODE_##type)
#define PYCLRAY_CAST_VISIT_KIND(Type, type)                                         \
    if (kind == KIND_##type) { PYCLRAY_CAST_MODE(PYCLRAY_CAST_TEST_, type)(Type, type) }
#define PYCLRAY_CAST_TEST_ENTRY(Type, type)                                         \
    {                                                                               \
        PYCLRAY_CAST_REBASED(Type, type, k, moved.world)                            \
        const real s = PYCLRAY_HIT_##type(&rebased, &moved, MISS);                  \
        const double t = s < MISS ? s0 + (double)s * ray_length : INFINITY;         \
        PYCLRAY_CAST_TAKE(t, type##s[k].id, KIND_##type, k, q)                      \
        PYCLRAY_CAST_PREFETCH_WINNER(Type, type, k)                                 \
    }
/* The moved ray of the last anchor met is kept (PYCLRAY_CAST_MOVED): the triangles of a mesh share
 * their mesh's anchor, so that a ray moves once per mesh rather than once per triangle (the same
 * function of the same anchor: the same bits). An anchor of NaNs is never equal: the first is moved. */
#define PYCLRAY_CAST_MOVED                                                          \
    double4 moved_anchor = (double4)(NAN);                                          \
    double s0 = 0;                                                                  \
    bool near = false;                                                              \
    RayPacket moved = ray;
#define PYCLRAY_CAST_VISIT(q)                                                       \
    {                                                                               \
        const int ref = refs[q], kind = ref & 15, k = ref >> 4;                      \
        const double4 anchor = anchors[q];                                          \
        if (!(anchor.x == moved_anchor.x && anchor.y == moved_anchor.y && anchor.z == moved_anchor.z \
              && anchor.w == moved_anchor.w)) {                                     \
            moved = moved_ray(&ray, anchor, t_min, &s0, &near);                     \
            moved_anchor = anchor;                                                  \
        }                                                                           \
        if (near && s0 <= PYCLRAY_CAST_REACH) {                                     \
            PYCLRAY_BOUNDED(PYCLRAY_CAST_VISIT_KIND)                                \
            PYCLRAY_CAST_LIMIT                                                      \
        }                                                                           \
    }
/* a child wide node's boxes, or a leaf's anchors and its shapes' world entries, asked for as the
 * child is pushed (kernels/bvh_ray.h): the shapes of a type lie in leaf order in their arrays, so a
 * leaf's entries of its first shape's type follow that shape's */
#define PYCLRAY_CAST_PREFETCH_KIND(Type, type)                                      \
    if (leaf_kind == KIND_##type) { PYCLRAY_CAST_MODE(PYCLRAY_CAST_PREFETCH_, type)(Type, type) }
#define PYCLRAY_CAST_PREFETCH_ENTRY(Type, type) CAST_PREFETCH(&type##_worlds[leaf_k], count * sizeof(Type##World))
#define PYCLRAY_CHILD_PREFETCH(code)                                                \
    if ((code) >= 0) {                                                              \
        CAST_PREFETCH(&nodes[code], sizeof(WideNode))                               \
    } else {                                                                        \
        const int first = (~(code)) >> 3, count = (~(code)) & 7;                    \
        CAST_PREFETCH(&box_anchors[first], count * sizeof(float4))                  \
        CAST_PREFETCH(&anchors[first], count * sizeof(double4))                     \
        const int leaf_kind = refs[first] & 15, leaf_k = refs[first] >> 4;          \
        PYCLRAY_BOUNDED(PYCLRAY_CAST_PREFETCH_KIND)                                 \
    }
/* (unbounded shapes: rebased on the ray's start, O + t_min D, which is O itself where t_min is 0) */
#define PYCLRAY_CAST_LINEAR(Type, type)                                             \
    for (int q = 0; q < n_##type##s; ++q) {                                         \
        PYCLRAY_CAST_REBASED(Type, type, q, start.world)                            \
        const real s = PYCLRAY_HIT_##type(&rebased, &start, MISS);                  \
        const double t = s < MISS ? t_min + (double)s * ray_length : INFINITY;      \
        PYCLRAY_CAST_TAKE(t, type##s[q].id, KIND_##type, q, -1)                     \
    }

/* Each work-item traces CAST_GROUP rays (consecutive places of the order), one after the other
 * (interleaved where leaves are blocks: cast_group, below). Their setups come first, together: a
 * ray's unit direction and the length of its rounding are a chain of dependent divisions and
 * square roots, on which, one ray at a time, about a quarter of the perf
 * samples of occluded on bench/secondary.py's view rays sat (most of those rays end at their first
 * test, the ground); a group's four-ray vectors take one instruction per division or root (below).
 * The group's first rows are asked for from memory as it starts, and the next group's rows too
 * (origin, direction and limit: each may straddle two cache lines): the rays are read where the
 * caller put them, scattered in the coherent order, and PoCL runs a work-group's items one after
 * the other, which would otherwise wait for each ray's first read (a seventh of cast's time on a
 * mesh). Each ray's own computations are unchanged: no bit of any result depends on the grouping. */
/* CAST_GROUP (the host's, programs.ray_group): 8, or 1 where the program traverses the pair nodes (a
 * GPU's one ray per work-item: kernels/bvh_pairs.h; a warp's rays are its work-items) */
#ifndef CAST_GROUP
#error "the host defines CAST_GROUP"
#endif
#define CAST_PREFETCH_ROW(p) { CAST_PREFETCH(p, 1) CAST_PREFETCH((__global const char*)(p) + 23, 1) }
#define PYCLRAY_CAST_PREFETCH_GROUP(start)                                          \
    for (int ahead_i = (start); ahead_i < (start) + CAST_GROUP && ahead_i < n_rays; ++ahead_i) { \
        const size_t ahead = (size_t)(ordered ? order[ahead_i] : ahead_i);          \
        CAST_PREFETCH_ROW(&origins[3 * ahead * (size_t)origin_stride])              \
        CAST_PREFETCH_ROW(&directions[3 * ahead])                                   \
        CAST_PREFETCH(&limits[ahead * (size_t)limit_stride], 1)                     \
    }

/* The ray from O + s0 D, s0 = max(t_min, (A - O).D - R - m): see above (t_min, the ray's own start,
 * 0 unless the query asks for hits beyond some tmin: no point before it is tested). m = 2^-50
 * |A - O|_1 bounds the float64 rounding of (A - O).D, so that the new origin is never past the
 * shape's near side, however far O is (at 1e40 the rounding of (A - O).D alone exceeds a unit R).
 * near: whether the ray passes within R of A (|G x D| <= R, G = A - O - s0 D, in float64 without
 * cancellation); where it does not, it misses the shape by more than 2^-12 R, far more than the
 * shape's test, which rounds quantities of the size of G, could err by: the test is skipped. */
inline RayPacket moved_ray(const RayPacket* ray, const double4 anchor, const double t_min, double* s0, bool* near)
{
    const double3 O = ray->world, D = ray->dir_exact;
    const double3 F = anchor.xyz - O;
    const double size = (CAST_FABS(F.x) + CAST_FABS(F.y)) + CAST_FABS(F.z);
    const double along = (F.x * D.x + F.y * D.y) + F.z * D.z - anchor.w - 0x1p-50 * size;
    *s0 = along > t_min ? along : t_min;
    const double3 G = F - *s0 * D;
    const double3 GxD = (double3)(G.y * D.z - G.z * D.y, G.z * D.x - G.x * D.z, G.x * D.y - G.y * D.x);
    *near = (GxD.x * GxD.x + GxD.y * GxD.y) + GxD.z * GxD.z <= anchor.w * anchor.w;
    RayPacket moved = *ray;
    moved.world = O + *s0 * D;  /* where the shape is rebased */
    return moved;
}

/* Whether the ray (o, d: its origin from the scene's anchor and its unit direction, rounded to
 * float, the box tests' ray) may pass within R of a shape's anchor A (anchor: A - S and R, each
 * rounded once to float on the host, as a convert_float would: the pre-test reads 16 bytes per
 * shape, not the 32 of the float64 anchor, which only the shapes it keeps read). With g = A - o,
 * the ray's distance from A is |g x d|; rounding A - S (S the scene's anchor), o, g and d to float
 * and the cross product's products and sums err by a few eps32 (|A - S|_1 + |o|_1 + |g|_1): the
 * test widens R by 2^-16 (1 + that sum), hundreds of times more, and drops only a ray farther than
 * that from A, whose moved_ray would find it not near. Only where the box tests run (|o| < 2^100,
 * the scene within 2^100 of S): g is finite there; a square that overflows to inf is a distance
 * beyond 2^64, dropped only where the widened R is finite, below it. */
inline bool cast_may_pass(const float4 anchor, const float3 o, const float3 d)
{
    const float3 a = anchor.xyz;  /* the anchor from the scene's anchor, rounded once (host: cast_inputs) */
    const float3 g = a - o;
    const float3 gxd = (float3)(g.y * d.z - g.z * d.y, g.z * d.x - g.x * d.z, g.x * d.y - g.y * d.x);
    const float3 size = (a < (float3)(0.0f) ? -a : a) + (o < (float3)(0.0f) ? -o : o) + (g < (float3)(0.0f) ? -g : g);
    const float reach = anchor.w * (1.0f + 0x1p-16f) + 0x1p-16f * ((size.x + size.y) + size.z);
    return (gxd.x * gxd.x + gxd.y * gxd.y) + gxd.z * gxd.z <= reach * reach;
}

/* The shapes of a leaf (positions first .. first + count - 1) the ray may meet, as a mask (bit i:
 * position first + i; kernels/bvh_ray.h's LEAF_MASK), each by cast_may_pass: a ray looks at several
 * times the shapes it tests, and a branch per shape on its own pre-test went either way at random.
 * A leaf of one ref (a mesh's block of triangles, kernels/mesh.cl, whose anchor is the whole mesh's)
 * is visited as it is: moved_ray's own test of that anchor is all a pre-test would do
 * (docs/benchmarks.md: cast_leaf_mask). */
inline int cast_leaf_mask(__global const float4* box_anchors, const int first, const int count, const float3 o,
                          const float3 d)
{
    if (count == 1) return 1;
    int mask = 0;
    for (int i = 0; i < count; ++i) mask |= cast_may_pass(box_anchors[first + i], o, d) ? 1 << i : 0;
    return mask;
}

/* A ray's direction as its tests take it: D = d / |d| (float64), its rounding dir, |dir|^2 and |dir| */
typedef struct {
    double3 unit;
    vec3v dir;
    real a, ray_length;
} CastDirection;

/* The square root of each lane of a 4-vector: on PoCL's CPU device one vector instruction of the
 * compiler's own (OpenCL's sqrt is a call there: kernels/lanes.h's v_sqrt), correctly rounded either way */
#ifdef PYCLRAY_INLINE_BUILTINS
#define CAST_SQRT4(T, F, x) ((T)(F((x).s0), F((x).s1), F((x).s2), F((x).s3)))
#else
#define CAST_SQRT4(T, F, x) sqrt(x)
#endif
#ifdef PYCLRAY_FP64
#define CAST_REAL_SQRT4(x) CAST_SQRT4(double4, CAST_SQRT, x)
#define CAST_TO_REAL4(x) (x)
#else
#ifdef PYCLRAY_INLINE_BUILTINS
#define CAST_REAL_SQRT4(x) CAST_SQRT4(float4, __builtin_sqrtf, x)
#else
#define CAST_REAL_SQRT4(x) sqrt(x)
#endif
#define CAST_TO_REAL4(x) convert_float4(x)
#endif

/* Four rays' directions (their x, y and z components in the lanes of x, y, z), set up at once in
 * vector registers: their divisions and square roots are one vector instruction each (see CAST_GROUP).
 * Per lane D = d / |d| in float64, d scaled first by the power of two 2^-e of its largest
 * component m (m in [2^e, 2^(e+1)); at least 2^-1022, a normal number, for m beyond 2^1023;
 * 2^1023 for a subnormal m, whose exponent bits are 0): exact, and a multiplication where a
 * division by m cost one more division per ray; the largest scaled component lies in [2^-51, 4),
 * so neither a tiny nor a huge finite direction under- or overflows in the length. */
inline void cast_directions4(const double4 x, const double4 y, const double4 z, CastDirection* out)
{
    const double4 zero = (double4)(0.0);
    const double4 size_x = x < zero ? -x : x, size_y = y < zero ? -y : y, size_z = z < zero ? -z : z;
    const double4 largest_xy = size_x > size_y ? size_x : size_y;
    const double4 largest = size_z > largest_xy ? size_z : largest_xy;
    const long4 field = (long4)(2046) - (as_long4(largest) >> 52);  /* the exponent bits of 2^-e: 1023 - e */
    const double4 scale = as_double4((field < (long4)(1) ? (long4)(1) : field) << 52);
    const double4 sx = x * scale, sy = y * scale, sz = z * scale;
    const double4 root = CAST_SQRT4(double4, CAST_SQRT, (sx * sx + sy * sy) + sz * sz);
    const double4 ux = sx / root, uy = sy / root, uz = sz / root;
    const real4 dx = CAST_TO_REAL4(ux), dy = CAST_TO_REAL4(uy), dz = CAST_TO_REAL4(uz);
    const real4 a = (dx * dx + dy * dy) + dz * dz;
    const real4 ray_length = CAST_REAL_SQRT4(a);  /* |dir|: the shapes' s is along dir, not D */
#define CAST_DIRECTION_LANE(l, s)                                                   \
    out[l].unit = (double3)(ux.s, uy.s, uz.s);                                      \
    out[l].dir = v3(dx.s, dy.s, dz.s);                                              \
    out[l].a = a.s;                                                                 \
    out[l].ray_length = ray_length.s;
    CAST_DIRECTION_LANE(0, s0) CAST_DIRECTION_LANE(1, s1) CAST_DIRECTION_LANE(2, s2) CAST_DIRECTION_LANE(3, s3)
#undef CAST_DIRECTION_LANE
}

/* rays[l0 .. l0 + 3]'s directions, set up at once */
#define CAST_LOAD_DIRECTIONS4(l0)                                                   \
    {                                                                               \
        const double3 d0 = load_double3(directions, rays[(l0)]), d1 = load_double3(directions, rays[(l0) + 1]); \
        const double3 d2 = load_double3(directions, rays[(l0) + 2]), d3 = load_double3(directions, rays[(l0) + 3]); \
        cast_directions4((double4)(d0.x, d1.x, d2.x, d3.x), (double4)(d0.y, d1.y, d2.y, d3.y), \
                         (double4)(d0.z, d1.z, d2.z, d3.z), &directions_of[(l0)]);  \
    }

/* the group's directions: in vectors of four rays; a group of one, its ray in all four lanes (each
 * lane's operations are its own: lane 0 is that ray's, as in a group of 8) */
#if CAST_GROUP == 8
#define CAST_DIRECTIONS 8
#define CAST_LOAD_GROUP_DIRECTIONS CAST_LOAD_DIRECTIONS4(0) CAST_LOAD_DIRECTIONS4(4)
#elif CAST_GROUP == 1
#define CAST_DIRECTIONS 4
#define CAST_LOAD_GROUP_DIRECTIONS                                                  \
    {                                                                               \
        const double3 d0 = load_double3(directions, rays[0]);                       \
        cast_directions4((double4)(d0.x), (double4)(d0.y), (double4)(d0.z), directions_of); \
    }
#else
#error "CAST_GROUP must be 8 or 1"
#endif

/* The places i0 .. i0 + CAST_GROUP - 1 of the order (those below n_rays): each one's ray rays[l] and
 * its direction, set up together (see CAST_GROUP) */
#define PYCLRAY_CAST_GROUP_SETUP                                                    \
    const int i0 = group * CAST_GROUP;                                              \
    const int in_group = n_rays - i0 < CAST_GROUP ? n_rays - i0 : CAST_GROUP;       \
    int rays[CAST_GROUP];                                                           \
    CastDirection directions_of[CAST_DIRECTIONS];                                   \
    PYCLRAY_CAST_PREFETCH_GROUP(i0)                                                 \
    PYCLRAY_CAST_PREFETCH_GROUP(i0 + CAST_GROUP)                                    \
    /* all CAST_GROUP set up, four at once, the places past the batch's end as its last ray */ \
    for (int l = 0; l < CAST_GROUP; ++l) {                                          \
        const int i = l < in_group ? i0 + l : n_rays - 1;                           \
        rays[l] = ordered ? order[i] : i;                                           \
    }                                                                               \
    CAST_LOAD_GROUP_DIRECTIONS

/* A group's rays through one traversal (State: its per-ray state; start, step, end: its functions),
 * after PYCLRAY_CAST_GROUP_SETUP: interleaved, a step of each ray still traversing until none is,
 * where the program has a type whose leaves are blocks (PYCLRAY_CAST_INTERLEAVE: programs.py) on
 * PoCL's CPU device (PYCLRAY_INLINE_BUILTINS): a GPU hides a ray's misses behind its other
 * work-items', and the group's 8 states (17 KB with their stacks) would not fit its private memory;
 * else one ray after the other (spheres' short paths through data that the caches hold lose by
 * interleaving; docs/benchmarks.md, "Mesh cast's traversal"). Cast, occluded and the hit counts. */
#ifdef PYCLRAY_HAS_BOUNDED
#define PYCLRAY_TRAVERSE_ALL(one, step) while ((one).top_ > 0) step(&(one), PYCLRAY_ARGUMENTS);
#else
#define PYCLRAY_TRAVERSE_ALL(one, step)
#endif
#if defined(PYCLRAY_CAST_INTERLEAVE) && defined(PYCLRAY_HAS_BOUNDED) && defined(PYCLRAY_INLINE_BUILTINS)
#define PYCLRAY_GROUP_TRAVERSAL(State, start, step, end)                            \
    State state[CAST_GROUP];                                                        \
    for (int l = 0; l < in_group; ++l)                                              \
        start(&state[l], rays[l], &directions_of[l], PYCLRAY_ARGUMENTS);            \
    for (bool going = true; going;) {                                               \
        going = false;                                                              \
        for (int l = 0; l < in_group; ++l) {                                        \
            if (state[l].top_ > 0) {                                                \
                step(&state[l], PYCLRAY_ARGUMENTS);                                 \
                going = true;                                                       \
            }                                                                       \
        }                                                                           \
    }                                                                               \
    for (int l = 0; l < in_group; ++l)                                              \
        end(&state[l], PYCLRAY_ARGUMENTS);
#else
#define PYCLRAY_GROUP_TRAVERSAL(State, start, step, end)                            \
    for (int l = 0; l < in_group; ++l) {                                            \
        State one;                                                                  \
        start(&one, rays[l], &directions_of[l], PYCLRAY_ARGUMENTS);                 \
        PYCLRAY_TRAVERSE_ALL(one, step)                                             \
        end(&one, PYCLRAY_ARGUMENTS);                                               \
    }
#endif

/* the setup shared by cast, occluded and the hit counts: ray r (origins: 3 doubles per ray; one
 * origin for every ray where origin_stride is 0), its direction, set up by its group, and the
 * distances its hits lie between: t_min (starts, hits beyond it; 0: from the origin) and t_max */
#define PYCLRAY_CAST_RAY                                                            \
    RayPacket ray;                                                                  \
    ray.world = load_double3(origins, r * origin_stride);                           \
    ray.dir_exact = direction->unit;                                                \
    ray.dir = direction->dir;                                                       \
    ray.a = direction->a;                                                           \
    ray.origin = v3(0, 0, 0);  /* each shape is rebased on the ray's origin */      \
    const real ray_length = direction->ray_length;                                  \
    const double t_max = limits[(size_t)r * (size_t)limit_stride];                  \
    const double t_min = starts[(size_t)r * (size_t)start_stride];                  \
    RayPacket start = ray;  /* the ray from its start, O + t_min D (t_min >= 0) */  \
    if (t_min > 0) start.world = ray.world + t_min * ray.dir_exact;

/* its box ray around the scene's anchor, with a margin over the rounding of its origin */
#define PYCLRAY_CAST_BOX                                                            \
    PYCLRAY_CAST_MOVED                                                              \
    const double3 from_anchor = ray.world - scene_anchor.xyz;                       \
    const float3 o = convert_float3(from_anchor);                                   \
    const float3 size = o < (float3)(0.0f) ? -o : o;                                \
    const float margin = 0x1p-20f * ((size.x + size.y) + size.z);                   \
    const float3 box_direction = convert_float3(ray.dir_exact);                     \
    const BoxRay box = box_ray(o, box_direction, margin);

/* The box tests are in float: an origin beyond 2^100 from the scene's anchor (possible in fp64),
 * or a scene that large (scene_anchor.w != 0), would overflow them; such a ray tests every bounded
 * shape instead, one after the other (exactly as through the BVH, only slower). */
#define PYCLRAY_CAST_BOUNDED(VISIT, ENTERED)                                        \
    if (scene_anchor.w != 0 || !(CAST_FABS(from_anchor.x) < 0x1p100 && CAST_FABS(from_anchor.y) < 0x1p100 \
                                  && CAST_FABS(from_anchor.z) < 0x1p100)) {         \
        int n_bounded = 0;                                                          \
        PYCLRAY_BOUNDED(PYCLRAY_CAST_COUNT)                                         \
        for (int q = 0; q < n_bounded; ++q) { VISIT(q) }                            \
    } else if (box_entered(root_box, &box, limit)) {                                \
        ENTERED  /* the BVH's traversal (or its start, where cast interleaves rays) */ \
    }
#define PYCLRAY_CAST_COUNT(Type, type) n_bounded += n_##type##s;
#define PYCLRAY_CAST_LEAF_MASK(first, count) cast_leaf_mask(box_anchors, first, count, o, box_direction)
