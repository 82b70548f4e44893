/* The BVH's traversal (pyclray/engine/bvh.py builds it, pyclray/engine/prepared.py packs it).
 *
 * Two trees of the same boxes: render's packets of camera rays traverse the wide tree (a node's 8
 * children against the packet's lanes at once, PYCLRAY_TRAVERSE_PACKET_WIDE), as do cast's single
 * rays; shadow rays and mesh instances' own trees the binary one (a node's box against all the
 * packet's lanes at once).
 *
 * A binary node: its box lo.xyz .. hi.xyz (float, as below); first = as_int(lo.w), count =
 * as_int(hi.w): a leaf of count shapes at positions first .. first + count - 1 of refs, else an
 * internal node with children first and first + 1.
 *
 * A wide node holds up to 8 children's boxes (float, rounded outward from float64 and kept
 * within the float range, so that no test meets inf - inf or 0 * inf; an empty slot has lo > hi)
 * in the box frame (world axes around the scene's anchor),
 * and their codes: a wide node's index, or ~(first * 8 + count) for a leaf of count shapes at
 * positions first .. first + count - 1 of refs (ref = index in its type's array * 8 + kind). All
 * eight boxes are tested at once, in float8 lanes.
 *
 * A box test must never drop a shape that the shape's own test would hit: the shape tests round,
 * so a hit may lie a little outside the exact shape. Each shape's box is widened on the host by
 * BVH_WIDEN times its size, and here the ray is widened into a cone: a point at distance t along
 * the ray matches a box that it misses by up to BVH_WIDEN t on each axis. BVH_WIDEN = 2^-12 is 4096
 * float32 ulps, far above the few ulps of t (and of the shape's size) a shape test errs by, and it
 * also covers the rounding of the box test itself (the 1 + 2 gamma(3) widening of pbrt-v4 / Ize's
 * "Robust BVH ray traversal" is applied to the exit distance as well, for the record). The cone
 * costs little: 2.4e-4 of the distance is a fraction of a pixel at any usual field of view.
 */
#define BVH_WIDEN 0x1p-12f
#define BVH_GAMMA3_2 (1.0f + 2.0f * (3.0f * 0x1p-24f) / (1.0f - 3.0f * 0x1p-24f))
#define BVH_STACK 256  /* 7 entries per level of the wide tree at most: the host checks its depth */
#define BVH_BINARY_STACK 64  /* one per level of the binary tree, at most its keys' 63 bits deep */

/* A ray for box tests: per axis, the entry and exit distances of a slab are
 * (face - origin -+ margin) * inverse (+ exit_add): see box_ray. */
typedef struct {
    float3 near_origin, far_origin;   /* origin moved by the margin toward each slab's near and far face */
    float3 near_inverse, far_inverse; /* sign / (|d| + widen) and sign / (|d| - widen) (0 where |d| <= widen) */
    float3 far_add;                    /* +inf where |d| <= widen: the cone never leaves that slab */
    int3 negative;                     /* direction component < 0: the near face is hi */
} BoxRay;

/* The box ray of origin o and direction d (unit or nearly) in the box frame, with an absolute
 * margin (the rounding of o). With s = sign(d_k), a point o + t d lies within margin + BVH_WIDEN t
 * of the slab [near, far] (in s's direction) when
 *   t (|d_k| + BVH_WIDEN) >= s (near - o) - margin   and   t (|d_k| - BVH_WIDEN) <= s (far - o) + margin. */
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
    return b;
}

inline float bvh_max(const float a, const float b) { return a > b ? a : b; }
inline float bvh_min(const float a, const float b) { return a < b ? a : b; }

#ifdef PYCLRAY_CAST
/* The smallest float not below x >= 0 (a box test's limit never cuts below the nearest hit): f
 * rounded to nearest, or where that is below x, the next float up, one unit in its bits (f >= 0
 * and finite there: nextafter(f, inf) without the call into PoCL's library) */
inline float float_above_wide(const double x)
{
    const float f = (float)x;
    return (double)f < x ? as_float(as_int(f) + 1) : f;
}
#endif

/* Per child of a wide node, the slab test's end: the entry (the axes' latest, from 0) where it is no
 * later than the exit (the axes' earliest, limit at most, widened by 1 + 2 gamma(3): the products'
 * rounding), else +inf. Max and min by comparison: no NaN reaches here (the box frame above). */
inline float8 wide_slabs(const float8 enter_x, const float8 enter_y, const float8 enter_z, const float8 leave_x,
                         const float8 leave_y, const float8 leave_z, const float limit)
{
    float8 enter = enter_y > enter_x ? enter_y : enter_x;
    enter = enter_z > enter ? enter_z : enter;
    enter = enter < (float8)(0.0f) ? (float8)(0.0f) : enter;
    float8 leave = leave_y < leave_x ? leave_y : leave_x;
    leave = leave_z < leave ? leave_z : leave;
    leave = ((float8)(limit) < leave ? (float8)(limit) : leave) * BVH_GAMMA3_2;
    return enter <= leave ? enter : (float8)(INFINITY);
}

/* The children of a wide node the ray enters before limit: their entry distances, +inf for the
 * others (one float8 test of all eight boxes). */
inline float8 wide_entries(__global const WideNode* node, const BoxRay* b, const float limit)
{
    const float8 near_x = b->negative.x ? node->hi_x : node->lo_x, far_x = b->negative.x ? node->lo_x : node->hi_x;
    const float8 near_y = b->negative.y ? node->hi_y : node->lo_y, far_y = b->negative.y ? node->lo_y : node->hi_y;
    const float8 near_z = b->negative.z ? node->hi_z : node->lo_z, far_z = b->negative.z ? node->lo_z : node->hi_z;
    const float8 enter_x = (near_x - b->near_origin.x) * b->near_inverse.x;
    const float8 enter_y = (near_y - b->near_origin.y) * b->near_inverse.y;
    const float8 enter_z = (near_z - b->near_origin.z) * b->near_inverse.z;
    const float8 leave_x = (far_x - b->far_origin.x) * b->far_inverse.x + b->far_add.x;
    const float8 leave_y = (far_y - b->far_origin.y) * b->far_inverse.y + b->far_add.y;
    const float8 leave_z = (far_z - b->far_origin.z) * b->far_inverse.z + b->far_add.z;
    return wide_slabs(enter_x, enter_y, enter_z, leave_x, leave_y, leave_z, limit);
}

/* Whether the ray enters the box (lo xyz, hi xyz in box.s012, box.s345) before limit: wide_entries'
 * test of one box, in the same operations. cast tests the box of the root's children first: most
 * of bench/secondary.py's view rays (from near the camera, many of them ending on the ground
 * around the spheres' field or going up) enter no child, and this costs less than the root's visit
 * (a float8 test of eight boxes and the stack). A child's box lies inside it, and a box that
 * contains another is entered no later and left no earlier: a child entered is within it. */
inline bool box_entered(const float8 box, const BoxRay* b, const float limit)
{
    const float3 lo = box.s012, hi = box.s345;
    const float3 near = b->negative ? hi : lo, far = b->negative ? lo : hi;
    const float3 enter = (near - b->near_origin) * b->near_inverse;
    const float3 leave = (far - b->far_origin) * b->far_inverse + b->far_add;
    float entry = enter.y > enter.x ? enter.y : enter.x;
    entry = enter.z > entry ? enter.z : entry;
    entry = entry < 0.0f ? 0.0f : entry;
    float exit = leave.y < leave.x ? leave.y : leave.x;
    exit = leave.z < exit ? leave.z : exit;
    exit = (limit < exit ? limit : exit) * BVH_GAMMA3_2;
    return entry <= exit;
}

/* the index of the lowest set bit of a non-zero mask (ctz: OpenCL 2.0's, or a call into PoCL's
 * library: clang's own on PoCL's CPU device, else from clz, which OpenCL 1.2 has) */
#ifdef PYCLRAY_INLINE_BUILTINS
#define BVH_LOWEST_BIT(mask) __builtin_ctz(mask)
#else
#define BVH_LOWEST_BIT(mask) (31 - clz((mask) & -(mask)))
#endif
/* cast visits the nearest child first (its limit falls with each hit); occluded stops at any hit */
#ifdef PYCLRAY_OCCLUDED
#define BVH_NEAREST_FIRST 0
#else
#define BVH_NEAREST_FIRST 1
#endif

/* The set lanes of an int8 comparison's result (-1 or 0 each) as the bits of an int: a wide node's
 * children entered, visited by their set bits (no branch per empty slot). */
inline int bvh_lane_bits(const int8 set)
{
    const int8 bits = set & (int8)(1, 2, 4, 8, 16, 32, 64, 128);
    const int4 four = bits.lo | bits.hi;
    const int2 two = four.lo | four.hi;
    return two.x | two.y;
}

/* Push value with its entry onto a wide traversal's stack (stack_entry, stack_child, top), among
 * the children of the node being visited (those above bottom) farthest deepest, so that the nearest
 * is popped first; unsorted where sorted is 0 (an any-hit query). */
#define BVH_STACK_PUSH(sorted, entry, value)                                            \
    {                                                                                   \
        int at = top++;                                                                 \
        while ((sorted) && at > bottom && stack_entry[at - 1] < (entry)) {              \
            stack_entry[at] = stack_entry[at - 1];                                      \
            stack_child[at] = stack_child[at - 1];                                      \
            --at;                                                                       \
        }                                                                               \
        stack_entry[at] = (entry);                                                      \
        stack_child[at] = (value);                                                      \
    }

/* Visit, nearest box first, every leaf position q whose box the ray enters before limit (a float
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
#define PYCLRAY_TRAVERSE(nodes, box, limit, LEAF_MASK, VISIT)                           \
    {                                                                                   \
        int stack_child[BVH_STACK];                                                     \
        float stack_entry[BVH_STACK];                                                   \
        int top = 0;                                                                    \
        stack_child[top] = 0;                                                           \
        stack_entry[top++] = 0.0f;                                                      \
        while (top > 0 && !(limit < 0.0f))                                              \
            PYCLRAY_TRAVERSE_STEP(nodes, box, limit, stack_child, stack_entry, top, LEAF_MASK, VISIT) \
    }

/* One step of PYCLRAY_TRAVERSE (top > 0): the nearest waiting child popped, and where the ray still
 * enters it before limit, a leaf's shapes visited or a node's entered children pushed. Its own
 * macro so that a caller can interleave several rays' traversals, a step of each in turn
 * (kernels/pyclray.cl's cast): each ray's steps are the same, in the same order. */
#define PYCLRAY_TRAVERSE_STEP(nodes, box, limit, stack_child, stack_entry, top, LEAF_MASK, VISIT) \
    {                                                                                   \
        --top;                                                                          \
        if (stack_entry[top] <= limit) {                                                \
            const int code = stack_child[top];                                          \
            if (code < 0) {                                                             \
                const int first = (~code) >> 3, count = (~code) & 7;                    \
                for (int leaf_mask = LEAF_MASK(first, count); leaf_mask != 0 && !(limit < 0.0f); \
                     leaf_mask &= leaf_mask - 1) {                                      \
                    const int q = first + BVH_LOWEST_BIT(leaf_mask);                    \
                    VISIT(q)                                                            \
                }                                                                       \
            } else {                                                                    \
                union { float8 v; float a[8]; } entries;  /* no vstore8: a library call */ \
                entries.v = wide_entries(&nodes[code], &box, limit);                    \
                const int bottom = top;                                                 \
                /* the children entered (bvh_lane_bits), nearest popped first (any order \
                 * for an any-hit query) */                                             \
                for (int mask = bvh_lane_bits(entries.v < (float8)(INFINITY)); mask != 0; mask &= mask - 1) { \
                    const int slot = BVH_LOWEST_BIT(mask);                              \
                    const float entry = entries.a[slot];                                \
                    const int child = nodes[code].child[slot];                          \
                    BVH_STACK_PUSH(BVH_NEAREST_FIRST, entry, child)                     \
                    PYCLRAY_CHILD_PREFETCH(child)                                       \
                }                                                                       \
            }                                                                           \
        }                                                                               \
    }


/* -- packets (render): the binary tree, one box against all the lanes ---------------------------- */

/* A packet's rays from one origin (the eye), per axis: sign / (|d| + widen), sign / (|d| - widen)
 * or 0, and +inf where |d| <= widen (see box_ray); and that origin in the box frame (xyz: the eye
 * from the scene's anchor, rounded to float) with a margin over its rounding (w). */
typedef struct {
    vec3v near_inverse, far_inverse, far_add;
    intv negative_x, negative_y, negative_z;
    float4 from;
    /* whether the lanes' direction signs agree on every axis (a camera packet's almost always do),
     * and then those signs (-1: negative): each node's near and far faces are chosen once for all
     * lanes (box_entries) */
    int same_signs;
    int3 negative;
    /* whether also no lane runs flat along an axis (|d| <= widen: far_add is 0 in every lane) */
    int steep;
    /* the origin moved by the margin, toward -inf (for the boxes' low faces) and +inf (high faces) */
    float3 from_low, from_high;
} BoxPacket;

inline void box_axis(const realv d, realv* near_inverse, realv* far_inverse, realv* far_add, intv* negative)
{
    *negative = d < SPLAT(0);
    const realv s = *negative ? SPLAT(-1) : SPLAT(1);
    const realv size = v_abs(d);
    const intv steep = size > SPLAT(BVH_WIDEN);
    *near_inverse = s / (size + SPLAT(BVH_WIDEN));
    *far_inverse = steep ? s / (size - SPLAT(BVH_WIDEN)) : SPLAT(0);
    *far_add = steep ? SPLAT(0) : SPLAT(INFINITY);
}

inline BoxPacket box_packet(const vec3v d, const float4 from)
{
    BoxPacket b;
    b.from = from;
    box_axis(d.x, &b.near_inverse.x, &b.far_inverse.x, &b.far_add.x, &b.negative_x);
    box_axis(d.y, &b.near_inverse.y, &b.far_inverse.y, &b.far_add.y, &b.negative_y);
    box_axis(d.z, &b.near_inverse.z, &b.far_inverse.z, &b.far_add.z, &b.negative_z);
    const bool all_x = !ANY(!b.negative_x), all_y = !ANY(!b.negative_y), all_z = !ANY(!b.negative_z);
    b.same_signs = (all_x || !ANY(b.negative_x)) && (all_y || !ANY(b.negative_y)) && (all_z || !ANY(b.negative_z));
    b.negative = (int3)(all_x ? -1 : 0, all_y ? -1 : 0, all_z ? -1 : 0);
    b.steep = b.same_signs && !ANY(b.far_add.x > SPLAT(0) || b.far_add.y > SPLAT(0) || b.far_add.z > SPLAT(0));
    /* o + m and o - m round by at most an ulp of o, under 2^-4 m (m = 2^-20 |o|_1 >= 2^-20 |o_k|):
     * the faces stay widened by more than the rounding of o (see box_entries) */
    b.from_low = from.xyz + from.w;
    b.from_high = from.xyz - from.w;
    return b;
}

/* x kept within the float range (a face beyond it is as good as there; a box test then never
 * meets inf - inf or 0 * inf) */
inline float3 finite3(const float3 x)
{
    /* as the vector ?: (select is a call into PoCL's library on its CPU device: see box_ray) */
    const float3 above = x < (float3)(-FLT_MAX) ? (float3)(-FLT_MAX) : x;
    return above > (float3)(FLT_MAX) ? (float3)(FLT_MAX) : above;
}

/* Per lane, the distance at which the ray (widened, from the packet's origin) enters node's box,
 * or +inf where it misses the box before limit. The node's faces (around the scene's anchor) are
 * taken relative to the origin once for all lanes, widened by the margin (from the origin moved by
 * it, box_packet): it covers the rounding of the origin and of o -+ m (each within an ulp of the
 * origin's size), and the ray's cone that of these differences (within an ulp of the face's
 * distance from the origin). */
inline realv box_entries_of(const float3 low, const float3 high, const BoxPacket* b, const realv limit)
{
    const float3 lo = finite3(low - b->from_low), hi = finite3(high - b->from_high);
    realv near_x, near_y, near_z, far_x, far_y, far_z;
    if (b->same_signs) {  /* the faces chosen once for all lanes: no select per lane */
        const float3 near = b->negative ? hi : lo, far = b->negative ? lo : hi;
        near_x = SPLAT(near.x), near_y = SPLAT(near.y), near_z = SPLAT(near.z);
        far_x = SPLAT(far.x), far_y = SPLAT(far.y), far_z = SPLAT(far.z);
        if (b->steep) {  /* no far_add to add */
            const realv enter = v_max(v_max(near_x * b->near_inverse.x, near_y * b->near_inverse.y),
                                      v_max(near_z * b->near_inverse.z, SPLAT(0)));
            const realv leave = v_min(v_min(far_x * b->far_inverse.x, far_y * b->far_inverse.y),
                                      v_min(far_z * b->far_inverse.z, limit)) * SPLAT(BVH_GAMMA3_2);
            return enter <= leave ? enter : SPLAT(INFINITY);
        }
    } else {
        near_x = b->negative_x ? SPLAT(hi.x) : SPLAT(lo.x), far_x = b->negative_x ? SPLAT(lo.x) : SPLAT(hi.x);
        near_y = b->negative_y ? SPLAT(hi.y) : SPLAT(lo.y), far_y = b->negative_y ? SPLAT(lo.y) : SPLAT(hi.y);
        near_z = b->negative_z ? SPLAT(hi.z) : SPLAT(lo.z), far_z = b->negative_z ? SPLAT(lo.z) : SPLAT(hi.z);
    }
    const realv enter = v_max(v_max(near_x * b->near_inverse.x, near_y * b->near_inverse.y),
                              v_max(near_z * b->near_inverse.z, SPLAT(0)));
    const realv leave = v_min(v_min(far_x * b->far_inverse.x + b->far_add.x, far_y * b->far_inverse.y + b->far_add.y),
                              v_min(far_z * b->far_inverse.z + b->far_add.z, limit)) * SPLAT(BVH_GAMMA3_2);
    return enter <= leave ? enter : SPLAT(INFINITY);
}

inline realv box_entries(__global const BvhNode* node, const BoxPacket* b, const realv limit)
{
    return box_entries_of(node->lo.xyz, node->hi.xyz, b, limit);
}

/* A leaf some lane of a packet enters has its shapes' entries asked for from memory at once, so that
 * they arrive while the traversal goes on (on 1,000,000 triangles, whose leaves are mostly far apart
 * in memory: -11% CPU time of 512x512 primary rays): PYCLRAY_PACKET_LEAF_PREFETCH(first, count),
 * defined by the kernel where it knows where a leaf's entries lie (kernels/pyclray.cl), else nothing. */
#ifndef PYCLRAY_PACKET_LEAF_PREFETCH
#define PYCLRAY_PACKET_LEAF_PREFETCH(first, count)
#endif
#ifdef PYCLRAY_INLINE_BUILTINS
#define BVH_PREFETCH(p) __builtin_prefetch(p);
#else
#define BVH_PREFETCH(p) {}  /* a statement still: it may be a loop's body */
#endif
#define PYCLRAY_PACKET_CHILD_PREFETCH(nodes, child)                                     \
    {                                                                                   \
        const int child_count = as_int(nodes[child].hi.w), child_first = as_int(nodes[child].lo.w); \
        if (child_count > 0) {                                                          \
            PYCLRAY_PACKET_LEAF_PREFETCH(child_first, child_count)                      \
        } else {                                                                        \
            BVH_PREFETCH(&nodes[child_first])                                           \
            BVH_PREFETCH(&nodes[child_first + 1])                                       \
        }                                                                               \
    }

/* Visit, nearest child first (by its nearest lane), every leaf whose box some lane of the packet
 * enters before its own best (a realv variable VISIT lowers): VISIT(q) for each shape of each such
 * leaf, tested against the whole packet. */
#define PYCLRAY_TRAVERSE_PACKET(nodes, box, best, VISIT) \
    PYCLRAY_TRAVERSE_PACKET_WITH(nodes, box_entries, &(box), best, VISIT)
/* the same with another box test: ENTRIES(node, boxes, limit) (shadow rays: kernels/shading.h) */
#define PYCLRAY_TRAVERSE_PACKET_WITH(nodes, ENTRIES, boxes, best, VISIT)                \
    {                                                                                   \
        int stack_node[BVH_BINARY_STACK];                                               \
        real stack_entry[BVH_BINARY_STACK];                                             \
        int top = 0, k = 0;                                                             \
        bool going = ANY(ENTRIES(&nodes[0], boxes, best) < SPLAT(INFINITY));         \
        while (going) {                                                                 \
            const int first = as_int(nodes[k].lo.w), count = as_int(nodes[k].hi.w);     \
            if (count > 0) {                                                            \
                for (int q = first; q < first + count; ++q) { VISIT(q) }                \
            } else {                                                                    \
                const realv t0 = ENTRIES(&nodes[first], boxes, best);                   \
                const realv t1 = ENTRIES(&nodes[first + 1], boxes, best);               \
                const real near0 = lane_min(t0), near1 = lane_min(t1);                  \
                if (near0 < INFINITY) PYCLRAY_PACKET_CHILD_PREFETCH(nodes, first)       \
                if (near1 < INFINITY) PYCLRAY_PACKET_CHILD_PREFETCH(nodes, first + 1)   \
                if (near0 < INFINITY || near1 < INFINITY) {                             \
                    const bool left = near0 <= near1;                                   \
                    k = left ? first : first + 1;                                       \
                    const real other = left ? near1 : near0;                            \
                    if (other < INFINITY) {                                             \
                        stack_node[top] = left ? first + 1 : first;                     \
                        stack_entry[top++] = other;                                     \
                    }                                                                   \
                    continue;                                                           \
                }                                                                       \
            }                                                                           \
            going = false;                                                              \
            if (top > 0) {                                                              \
                const real farthest = lane_max(best);                                   \
                while (top > 0) {                                                       \
                    --top;                                                              \
                    if (stack_entry[top] <= farthest) {                                 \
                        k = stack_node[top];                                            \
                        going = true;                                                   \
                        break;                                                          \
                    }                                                                   \
                }                                                                       \
            }                                                                           \
        }                                                                               \
    }


/* -- packets through the wide tree (render's camera rays) ----------------------------------------
 * A packet visits a wide node's eight children at once, one child per lane of float8, and tests
 * each child's box against all its rays by interval arithmetic: per axis, the product of a face
 * (relative to the packet's origin, widened by the margin as in box_entries) and a lane's inverse
 * is monotonic in the inverse, and so is its rounding, so the least of those products over the
 * lanes is the lesser of the face's products with the lanes' least and most inverse, and the most
 * the greater. Every lane's entry is then at least E, the largest of the axes' least entries (and
 * 0), and its exit (its limit included, times the same 1 + 2 gamma(3)) at most L, the smallest of
 * the axes' most exits (and the largest lane's limit): where E > L, every lane misses the box as
 * box_entries would test it, so no box that some lane enters is dropped (the images are the same
 * bits), and E is a lower bound of the nearest lane's entry (the visit's order and the stack's
 * pruning stay conservative). An axis on which the lanes' signs differ, or some lane runs flat
 * (|d| <= widen), is left out: its entries count as 0 and its exits as +inf.
 * This test is loose where a box falls between the lanes' rays (a box smaller than the rays'
 * spacing: sub-pixel triangles), so a child is tested again when popped from the stack, lane by lane
 * as box_entries tests a binary node (each lane against its own best, by then often nearer).
 * Why: through the binary tree a packet of 4x2 rays visited 26 internal nodes and 9 leaves (100,000
 * spheres at 256x256), two box tests of all lanes and two reductions across them per visit, each
 * visit waiting on the last; through the wide tree 9 visits (one float8 test of 8 children each) and
 * the same 9 leaves. CPU time (kernels swapped in one process, one PoCL thread, medians of 4-6
 * rounds): render_views at 100,000 spheres -20% (12.9 -> 10.2 ms a view), the 80,000-triangle bunny
 * at 512x512 -27% (18.3 -> 13.5 ms), 1,000,000 triangles -22% (69 -> 54 ms); without the test at
 * the pop, +24% on 1,000,000 triangles (the loose test alone let 4-8 times the leaves through).
 * The products are in float at either precision, as fp32's box_entries computes them: at fp64 the
 * lanes' bounds are rounded outward to float (the least down, the most up, and the lanes' largest
 * limit up), so that they still bound every lane's. */
typedef struct {
    float3 from_low, from_high;  /* the origin moved by the margin (as BoxPacket's) */
    int3 negative;                /* per axis: all the lanes' direction components are negative */
    /* per axis the least and the most lane of near_inverse and far_inverse (0 where the axis is left
     * out), and the exits' addend: 0, or +inf where the axis is left out */
    float3 near_least, near_most, far_least, far_most, far_add;
} WidePacket;

/* a lane bound as a float: rounded down (least) or up (most, and a limit) where real is double */
#ifdef PYCLRAY_FP64
#define WIDE_DOWN(x) convert_float_rtn(x)
#define WIDE_UP(x) convert_float_rtp(x)
#else
#define WIDE_DOWN(x) (x)
#define WIDE_UP(x) (x)
#endif

inline WidePacket wide_packet(const BoxPacket* b)
{
    WidePacket w;
    w.from_low = b->from_low;
    w.from_high = b->from_high;
    const bool all_x = !ANY(!b->negative_x), all_y = !ANY(!b->negative_y), all_z = !ANY(!b->negative_z);
    const bool keep_x = (all_x || !ANY(b->negative_x)) && !ANY(b->far_add.x > SPLAT(0));
    const bool keep_y = (all_y || !ANY(b->negative_y)) && !ANY(b->far_add.y > SPLAT(0));
    const bool keep_z = (all_z || !ANY(b->negative_z)) && !ANY(b->far_add.z > SPLAT(0));
    w.negative = (int3)(all_x ? -1 : 0, all_y ? -1 : 0, all_z ? -1 : 0);
    /* per kept axis the lanes' least (rounded down) or most (rounded up) of an inverse, else 0 */
#define WIDE_LANES(ROUND, EXTREME, v)                                                    \
    (float3)(keep_x ? ROUND(EXTREME((v).x)) : 0.0f, keep_y ? ROUND(EXTREME((v).y)) : 0.0f, \
             keep_z ? ROUND(EXTREME((v).z)) : 0.0f)
    w.near_least = WIDE_LANES(WIDE_DOWN, lane_min, b->near_inverse);
    w.near_most = WIDE_LANES(WIDE_UP, lane_max, b->near_inverse);
    w.far_least = WIDE_LANES(WIDE_DOWN, lane_min, b->far_inverse);
    w.far_most = WIDE_LANES(WIDE_UP, lane_max, b->far_inverse);
#undef WIDE_LANES
    w.far_add = (float3)(keep_x ? 0.0f : INFINITY, keep_y ? 0.0f : INFINITY, keep_z ? 0.0f : INFINITY);
    return w;
}

/* x kept within the float range (as finite3: no inf - inf or 0 * inf below) */
inline float8 finite8(const float8 x)
{
    const float8 above = x < (float8)(-FLT_MAX) ? (float8)(-FLT_MAX) : x;
    return above > (float8)(FLT_MAX) ? (float8)(FLT_MAX) : above;
}

/* Per child of a wide node, a lower bound of the packet's nearest entry into its box, or +inf where
 * no lane enters it before farthest (the largest lane's limit); see above. */
inline float8 wide_packet_entries(__global const WideNode* node, const WidePacket* w, const float farthest)
{
    /* the faces from the origin moved by the margin: low faces from from_low, high from from_high */
    const float8 lo_x = finite8(node->lo_x - w->from_low.x), hi_x = finite8(node->hi_x - w->from_high.x);
    const float8 lo_y = finite8(node->lo_y - w->from_low.y), hi_y = finite8(node->hi_y - w->from_high.y);
    const float8 lo_z = finite8(node->lo_z - w->from_low.z), hi_z = finite8(node->hi_z - w->from_high.z);
    const float8 near_x = w->negative.x ? hi_x : lo_x, far_x = w->negative.x ? lo_x : hi_x;
    const float8 near_y = w->negative.y ? hi_y : lo_y, far_y = w->negative.y ? lo_y : hi_y;
    const float8 near_z = w->negative.z ? hi_z : lo_z, far_z = w->negative.z ? lo_z : hi_z;
    /* per axis the least entry and the most exit over the lanes (max and min by comparison: no NaN) */
    const float8 enter_x0 = near_x * w->near_least.x, enter_x1 = near_x * w->near_most.x;
    const float8 enter_y0 = near_y * w->near_least.y, enter_y1 = near_y * w->near_most.y;
    const float8 enter_z0 = near_z * w->near_least.z, enter_z1 = near_z * w->near_most.z;
    const float8 leave_x0 = far_x * w->far_least.x, leave_x1 = far_x * w->far_most.x;
    const float8 leave_y0 = far_y * w->far_least.y, leave_y1 = far_y * w->far_most.y;
    const float8 leave_z0 = far_z * w->far_least.z, leave_z1 = far_z * w->far_most.z;
    const float8 enter_x = enter_x0 < enter_x1 ? enter_x0 : enter_x1;
    const float8 enter_y = enter_y0 < enter_y1 ? enter_y0 : enter_y1;
    const float8 enter_z = enter_z0 < enter_z1 ? enter_z0 : enter_z1;
    const float8 leave_x = (leave_x0 > leave_x1 ? leave_x0 : leave_x1) + w->far_add.x;
    const float8 leave_y = (leave_y0 > leave_y1 ? leave_y0 : leave_y1) + w->far_add.y;
    const float8 leave_z = (leave_z0 > leave_z1 ? leave_z0 : leave_z1) + w->far_add.z;
    return wide_slabs(enter_x, enter_y, enter_z, leave_x, leave_y, leave_z, farthest);
}

/* Visit, nearest first, every leaf of the wide tree whose box some lane of the packet (its BoxPacket
 * box) enters before its own best (a realv variable VISIT lowers): VISIT(q) for each shape of
 * each such leaf, tested against the whole packet. A node's children that the packet may enter
 * (wide_packet_entries) go on the stack farthest first; one is skipped when popped if it lies beyond
 * every lane's best, or if no lane enters its box before its own best (box_entries_of). Each pushed
 * child is asked for from memory at once: a wide node's boxes, or a leaf's entries
 * (PYCLRAY_PACKET_LEAF_PREFETCH). The stack holds 7 entries a level (the host checks the depth). */
#define PYCLRAY_TRAVERSE_PACKET_WIDE(nodes, box, best, VISIT)                           \
    {                                                                                   \
        const WidePacket wide_box = wide_packet(&(box));                                \
        int stack_child[BVH_STACK];  /* a wide node's index * 8 + the child's slot */   \
        float stack_entry[BVH_STACK];                                                   \
        int top = 0;                                                                    \
        float farthest = WIDE_UP(lane_max(best));                                       \
        int code = 0;  /* the node to visit: a wide node's index, or a leaf's code */   \
        for (;;) {                                                                      \
            if (code < 0) {                                                             \
                const int first = (~code) >> 3, count = (~code) & 7;                    \
                for (int q = first; q < first + count; ++q) { VISIT(q) }                \
                farthest = WIDE_UP(lane_max(best));                                     \
            } else {                                                                    \
                union { float8 v; float a[8]; } entries;  /* no vstore8: a library call */ \
                entries.v = wide_packet_entries(&nodes[code], &wide_box, farthest);     \
                const int bottom = top;                                                 \
                /* the children entered (bvh_lane_bits; an empty slot's code is 0, and its \
                 * box, lo > hi, may pass where no axis is kept), nearest popped first */ \
                const int8 entered = entries.v < (float8)(INFINITY) & nodes[code].child != (int8)(0); \
                for (int mask = bvh_lane_bits(entered); mask != 0; mask &= mask - 1) {  \
                    const int slot = BVH_LOWEST_BIT(mask);                              \
                    const float entry = entries.a[slot];                                \
                    const int child = nodes[code].child[slot];                          \
                    BVH_STACK_PUSH(1, entry, code * 8 + slot)                           \
                    if (child >= 0) {                                                   \
                        for (int byte = 0; byte < (int)sizeof(WideNode); byte += 64)    \
                            BVH_PREFETCH((__global const char*)&nodes[child] + byte)    \
                    } else {                                                            \
                        PYCLRAY_PACKET_LEAF_PREFETCH((~child) >> 3, (~child) & 7)       \
                    }                                                                   \
                }                                                                       \
            }                                                                           \
            /* the next: the nearest pushed child before the farthest lane's best that some \
             * lane enters before its own best (box_entries of its box, from its parent) */ \
            code = 0;                                                                   \
            while (top > 0) {                                                           \
                --top;                                                                  \
                if (!(stack_entry[top] <= farthest)) continue;                          \
                __global const WideNode* parent = &nodes[stack_child[top] >> 3];        \
                const int slot = stack_child[top] & 7;                                  \
                const int child = parent->child[slot];                                  \
                {  /* its box, slot of its parent's float8 rows */                      \
                    __global const float* lo_x = (__global const float*)&parent->lo_x;  \
                    __global const float* lo_y = (__global const float*)&parent->lo_y;  \
                    __global const float* lo_z = (__global const float*)&parent->lo_z;  \
                    __global const float* hi_x = (__global const float*)&parent->hi_x;  \
                    __global const float* hi_y = (__global const float*)&parent->hi_y;  \
                    __global const float* hi_z = (__global const float*)&parent->hi_z;  \
                    const realv lane_entries = box_entries_of((float3)(lo_x[slot], lo_y[slot], lo_z[slot]), \
                                                              (float3)(hi_x[slot], hi_y[slot], hi_z[slot]), &(box), best); \
                    if (!ANY(lane_entries < SPLAT(INFINITY))) continue;                 \
                }                                                                       \
                code = child;                                                           \
                break;                                                                  \
            }                                                                           \
            if (code == 0) break;                                                       \
        }                                                                               \
    }
