/* One ray through the wide tree (cast and any-hit: kernels/cast.cl, kernels/anyhit.cl), its box tests
 * in float against the nodes' boxes in the box space (world axes around the scene's anchor). */

/* A ray for box tests: per axis, the entry and exit distances of a slab are
 * (face - origin -+ margin) * inverse (+ exit_add): see box_ray. */
typedef struct {
    float3 near_origin, far_origin;   /* origin moved by the margin toward each slab's near and far face */
    float3 near_inverse, far_inverse; /* sign / (|d| + widen) and sign / (|d| - widen) (0 where |d| <= widen) */
    float3 far_add;                    /* +inf where |d| <= widen: the cone never leaves that slab */
    float3 flat_inverse;               /* sign / (|d| - widen) where |d| <= widen (see box_ray), else 0 */
    int3 negative;                     /* direction component < 0: the near face is hi */
    int flat;                          /* some |d| <= widen: flat_inverse's entries are taken too */
} BoxRay;

/* The box ray of origin o and direction d (unit or nearly) in the box space, with an absolute
 * margin (the rounding of o). With s = sign(d_k), a point o + t d lies within margin + BVH_WIDEN t
 * of the slab [near, far] (in s's direction) when
 *   t (|d_k| + BVH_WIDEN) >= s (near - o) - margin   and   t (|d_k| - BVH_WIDEN) <= s (far - o) + margin.
 * Where |d_k| <= BVH_WIDEN (a ray along or nearly along the other axes) the cone widens faster than
 * it moves on axis k: it never leaves the slab, and the second condition is an entry as well,
 * t >= (s (far - o) + margin) / (|d_k| - BVH_WIDEN), the cone reaching the slab from beyond its far
 * face (without it, every box on that side of an axis-aligned ray was entered at 0: issue 38's
 * 200x slower casts; docs/benchmarks.md). The divisor is kept at most -FLT_MIN (|d_k| = BVH_WIDEN:
 * a finite, later entry than the exact one, never infinite times 0). */
inline BoxRay box_ray(const float3 o, const float3 d, const float margin)
{
    BoxRay b;
    b.negative = d < (float3)(0.0f);
    /* selects written as the vector ?: (the same operation: OpenCL's select is a call into PoCL's
     * library on its CPU device, which LLVM does not inline there, kernels/lanes.h) */
    const float3 s = b.negative ? (float3)(-1.0f) : (float3)(1.0f);
    const float3 size = s * d;
    b.near_origin = o + s * margin;
    b.far_origin = o - s * margin;
    b.near_inverse = s / (size + BVH_WIDEN);
    const int3 steep = size > (float3)(BVH_WIDEN);
    b.far_inverse = steep ? s / (size - BVH_WIDEN) : (float3)(0.0f);
    b.far_add = steep ? (float3)(0.0f) : (float3)(INFINITY);
    const float3 flat_rise = size - BVH_WIDEN;  /* <= 0 where not steep */
    b.flat_inverse = steep ? (float3)(0.0f) : s / (flat_rise < (float3)(-FLT_MIN) ? flat_rise : (float3)(-FLT_MIN));
    b.flat = !(steep.x && steep.y && steep.z);
    return b;
}

/* The smallest float not below x >= 0 (a box test's limit never cuts below the nearest hit): f
 * rounded to nearest, or where that is below x, the next float up, one unit in its bits (f >= 0
 * and finite there: nextafter(f, inf) without the call into PoCL's library) */
inline float float_above_wide(const double x)
{
    const float f = (float)x;
    return (double)f < x ? as_float(as_int(f) + 1) : f;
}

/* The children of a wide node the ray enters before limit: their entry distances, +inf for the
 * others (one float8 test of all eight boxes). */
inline float8 wide_entries(__global const WideNode* node, const BoxRay* b, const float limit)
{
    const float8 near_x = b->negative.x ? node->hi_x : node->lo_x, far_x = b->negative.x ? node->lo_x : node->hi_x;
    const float8 near_y = b->negative.y ? node->hi_y : node->lo_y, far_y = b->negative.y ? node->lo_y : node->hi_y;
    const float8 near_z = b->negative.z ? node->hi_z : node->lo_z, far_z = b->negative.z ? node->lo_z : node->hi_z;
    float8 enter_x = (near_x - b->near_origin.x) * b->near_inverse.x;
    float8 enter_y = (near_y - b->near_origin.y) * b->near_inverse.y;
    float8 enter_z = (near_z - b->near_origin.z) * b->near_inverse.z;
    if (b->flat) {  /* the far faces' entries of the flat axes (0 on the others: box_ray) */
        const float8 flat_x = (far_x - b->far_origin.x) * b->flat_inverse.x;
        const float8 flat_y = (far_y - b->far_origin.y) * b->flat_inverse.y;
        const float8 flat_z = (far_z - b->far_origin.z) * b->flat_inverse.z;
        enter_x = flat_x > enter_x ? flat_x : enter_x;
        enter_y = flat_y > enter_y ? flat_y : enter_y;
        enter_z = flat_z > enter_z ? flat_z : enter_z;
    }
    const float8 leave_x = (far_x - b->far_origin.x) * b->far_inverse.x + b->far_add.x;
    const float8 leave_y = (far_y - b->far_origin.y) * b->far_inverse.y + b->far_add.y;
    const float8 leave_z = (far_z - b->far_origin.z) * b->far_inverse.z + b->far_add.z;
    return wide_slabs(enter_x, enter_y, enter_z, leave_x, leave_y, leave_z, limit);
}

/* Whether the ray enters the box (lo, hi) before limit, its entry distance in *entry_out: wide_entries'
 * test of one box, in the same operations (box_entered: a wide node's box.s012, box.s345; the pair
 * nodes' pair_entry, kernels/bvh_pairs.h). cast tests the box of the root's children first: most
 * of bench/secondary.py's view rays (from near the camera, many of them ending on the ground
 * around the spheres' field or going up) enter no child, and this costs less than the root's visit
 * (a float8 test of eight boxes and the stack). A child's box lies inside it, and a box that
 * contains another is entered no later and left no earlier: a child entered is within it. */
inline bool box_span(const float3 lo, const float3 hi, const BoxRay* b, const float limit, float* entry_out)
{
    const float3 near = b->negative ? hi : lo, far = b->negative ? lo : hi;
    float3 enter = (near - b->near_origin) * b->near_inverse;
    if (b->flat) {
        const float3 flat = (far - b->far_origin) * b->flat_inverse;
        enter = flat > enter ? flat : enter;
    }
    const float3 leave = (far - b->far_origin) * b->far_inverse + b->far_add;
    float entry = enter.y > enter.x ? enter.y : enter.x;
    entry = enter.z > entry ? enter.z : entry;
    entry = entry < 0.0f ? 0.0f : entry;
    float exit = leave.y < leave.x ? leave.y : leave.x;
    exit = leave.z < exit ? leave.z : exit;
    exit = (limit < exit ? limit : exit) * BVH_GAMMA3_2;
    *entry_out = entry;
    return entry <= exit;
}

inline bool box_entered(const float8 box, const BoxRay* b, const float limit)
{
    float entry;
    return box_span(box.s012, box.s345, b, limit, &entry);
}

/* Visit every leaf position q whose box the ray enters before limit, nearest box first where
 * NEAREST_FIRST is 1 (a nearest-hit query, whose limit falls with each hit), in any order where it
 * is 0 (an any-hit query, which stops at the first hit) (limit: a float
 * variable that VISIT may lower; below 0, as occluded's -inf once it has found a hit, it ends the
 * search within the leaf too): VISIT(q) runs for each shape of each such leaf that LEAF_MASK(first,
 * count) keeps (bit i for position first + i: the kernel's pre-test of all the leaf's shapes at
 * once, whose mask's set bits are then visited in order, rather than a branch per shape on its own
 * test that goes either way at random). Each child
 * entered is asked for from memory as it is pushed, PYCLRAY_CHILD_PREFETCH(code) (defined by the
 * kernel: a wide node's boxes, or a leaf's entries: rather than one miss after the other when
 * they are reached, the misses of a node's entered children overlap each other and the
 * nearer children's work). The stack holds
 * children codes (kernels' WideNode.child) and their entry distances; a wide node's hit children
 * go on it farthest first, so that the nearest is visited next. */
#define PYCLRAY_TRAVERSE(nodes, box, limit, NEAREST_FIRST, LEAF_MASK, VISIT)            \
    {                                                                                   \
        int stack_child[BVH_STACK];                                                     \
        float stack_entry[BVH_STACK];                                                   \
        int top = 0;                                                                    \
        stack_child[top] = 0;                                                           \
        stack_entry[top++] = 0.0f;                                                      \
        while (top > 0 && !(limit < 0.0f))                                              \
            PYCLRAY_TRAVERSE_STEP(nodes, box, limit, stack_child, stack_entry, top, NEAREST_FIRST, LEAF_MASK, VISIT) \
    }

/* What a query does as a leaf is reached, given the distance at which its ray enters the leaf's box
 * (0: the box holds the ray's origin, within the box ray's margin): nothing, unless the query's file
 * says otherwise (kernels/allhits.cl: whether a point may lie on a surface) */
#define PYCLRAY_LEAF_ENTERED(entry)

/* One step of PYCLRAY_TRAVERSE (top > 0): the nearest waiting child popped, and where the ray still
 * enters it before limit, a leaf's shapes visited or a node's entered children pushed. Its own
 * macro so that a caller can interleave several rays' traversals, a step of each in turn
 * (kernels/cast.cl): each ray's steps are the same, in the same order. */
#define PYCLRAY_TRAVERSE_STEP(nodes, box, limit, stack_child, stack_entry, top, NEAREST_FIRST, LEAF_MASK, VISIT) \
    {                                                                                   \
        --top;                                                                          \
        if (stack_entry[top] <= limit) {                                                \
            const int code = stack_child[top];                                          \
            if (code < 0) {                                                             \
                const int first = (~code) >> 3, count = (~code) & 7;                    \
                PYCLRAY_LEAF_ENTERED(stack_entry[top])                                  \
                for (int leaf_mask = LEAF_MASK(first, count); leaf_mask != 0 && !(limit < 0.0f); \
                     leaf_mask &= leaf_mask - 1) {                                      \
                    const int q = first + BVH_LOWEST_BIT(leaf_mask);                    \
                    VISIT(q)                                                            \
                }                                                                       \
            } else {                                                                    \
                union { float8 v; float a[8]; } entries;  /* no vstore8: a library call */ \
                entries.v = wide_entries(&nodes[code], &box, limit);                    \
                const int bottom = top;                                                 \
                /* the children entered (bvh_lane_bits), nearest popped first where \
                 * NEAREST_FIRST is 1 (any order for an any-hit query: 0) */             \
                for (int mask = bvh_lane_bits(entries.v < (float8)(INFINITY)); mask != 0; mask &= mask - 1) { \
                    const int slot = BVH_LOWEST_BIT(mask);                              \
                    const float entry = entries.a[slot];                                \
                    const int child = nodes[code].child[slot];                          \
                    BVH_STACK_PUSH(NEAREST_FIRST, entry, child)                         \
                    PYCLRAY_CHILD_PREFETCH(child)                                       \
                }                                                                       \
            }                                                                           \
        }                                                                               \
    }
