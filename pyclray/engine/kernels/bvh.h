/* The BVH's boxes and what every traversal shares (pyclray/engine/bvh/tree.py builds the trees,
 * pyclray/engine/scene/prepared.py packs them). The traversals: one ray through the wide tree
 * (kernels/bvh_ray.h: cast and any-hit), a packet through the binary tree (kernels/bvh_packet.h:
 * shadow rays, mesh instances' own trees) and a packet through the wide tree
 * (kernels/bvh_wide_packet.h: render's camera rays).
 *
 * A binary node: its box lo.xyz .. hi.xyz (float, as below); first = as_int(lo.w), count =
 * as_int(hi.w): a leaf of count shapes at positions first .. first + count - 1 of refs, else an
 * internal node with children first and first + 1.
 *
 * A wide node holds up to 8 children's boxes (float, rounded outward from float64 and kept
 * within the float range, so that no test meets inf - inf or 0 * inf; an empty slot has lo > hi)
 * in the box space (world axes around the scene's anchor),
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

/* Per child of a wide node, the slab test's end: the entry (the axes' latest, from 0) where it is no
 * later than the exit (the axes' earliest, limit at most, widened by 1 + 2 gamma(3): the products'
 * rounding), else +inf. Max and min by comparison: no NaN reaches here (the box space above). */
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

/* the index of the lowest set bit of a non-zero mask (ctz: OpenCL 2.0's, or a call into PoCL's
 * library: clang's own on PoCL's CPU device, else from clz, which OpenCL 1.2 has) */
#ifdef PYCLRAY_INLINE_BUILTINS
#define BVH_LOWEST_BIT(mask) __builtin_ctz(mask)
#else
#define BVH_LOWEST_BIT(mask) (31 - clz((mask) & -(mask)))
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

/* a hint that the bytes at p will be read soon (nothing where the compiler has no prefetch) */
#ifdef PYCLRAY_INLINE_BUILTINS
#define BVH_PREFETCH(p) __builtin_prefetch(p);
#else
#define BVH_PREFETCH(p) {}  /* a statement still: it may be a loop's body */
#endif
