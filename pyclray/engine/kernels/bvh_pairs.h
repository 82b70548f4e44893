/* One ray per work-item through the binary tree's pair nodes (a lane width of 1: GPUs; programs.py
 * compiles it in with PYCLRAY_PAIRS): Aila and Laine's two-box nodes (pyclray/engine/bvh/pairs.py: a
 * node holds both children's boxes and codes, 64 bytes) and their while-while loop: the inner
 * loop descends, a node read per level, both children's boxes tested, into the nearer one entered,
 * the other pushed with its entry distance, until a leaf (whose shapes are then visited) or no
 * child is entered; the outer loop pops the nearest pushed child still entered before the ray's
 * limit. A short stack in private memory: one entry per binary level (the host checks the depth,
 * BVH_BINARY_STACK). The boxes are the wide tree's, rounded as they are, tested by the same
 * operations (box_entered's, box_entries_of's): a leaf the wide traversal keeps this one keeps too,
 * every shape test is the same function and every tie rule picks its winner whatever the order
 * of the visit, so every result is the same bits (tests/test_gpu_traversal.py). */

#define PYCLRAY_PAIR_TRAVERSAL 1  /* the marker tests look for in the program's source */

/* a child's code: >= 0 a node, < 0 a leaf ~(first * 8 + count); 0 (the root, never a child): none */
#define PAIR_CODE(corner) as_int((corner).w)

#ifdef PYCLRAY_CAST
/* the ray queries' stacks (kernels/cast.cl, kernels/allhits.cl): a binary level per entry */
#undef BVH_STACK
#define BVH_STACK BVH_BINARY_STACK

/* The entry distance of a cast ray (BoxRay) into a child's box before limit, +inf where it misses:
 * box_entered's test (kernels/bvh_ray.h: box_span), the same operations in the same order. */
inline float pair_entry(const float4 low, const float4 high, const BoxRay* b, const float limit)
{
    float entry;
    return box_span(low.xyz, high.xyz, b, limit, &entry) ? entry : INFINITY;
}

/* PYCLRAY_TRAVERSE_STEP (kernels/bvh_ray.h) over pair nodes, with the same arguments and meaning:
 * the nearest waiting child popped; where the ray still enters it before limit, the inner loop
 * down to a leaf, whose shapes LEAF_MASK keeps are visited (VISIT(q)). Nearest child first where
 * NEAREST_FIRST is 1; the first child first where it is 0 (any order: occluded, the hit counts). */
#undef PYCLRAY_TRAVERSE_STEP
#define PYCLRAY_TRAVERSE_STEP(nodes, box, limit, stack_child, stack_entry, top, NEAREST_FIRST, LEAF_MASK, VISIT) \
    {                                                                                   \
        --top;                                                                          \
        if (stack_entry[top] <= limit) {                                                \
            int code = stack_child[top];                                                \
            float entry = stack_entry[top];  /* where the ray enters code's box */      \
            while (code >= 0) {  /* down: a node per level */                           \
                const PairNode node = nodes[code];                                      \
                const int left = PAIR_CODE(node.left_lo), right = PAIR_CODE(node.right_lo); \
                const float left_entry = pair_entry(node.left_lo, node.left_hi, &(box), limit); \
                const float right_entry = right != 0 ? pair_entry(node.right_lo, node.right_hi, &(box), limit) : INFINITY; \
                const bool in_left = left_entry < INFINITY, in_right = right_entry < INFINITY; \
                if (in_left && in_right) {                                              \
                    const bool right_first = (NEAREST_FIRST) && right_entry < left_entry; \
                    stack_child[top] = right_first ? left : right;                      \
                    stack_entry[top++] = right_first ? left_entry : right_entry;        \
                    code = right_first ? right : left;                                  \
                    entry = right_first ? right_entry : left_entry;                     \
                } else if (in_left || in_right) {                                       \
                    code = in_left ? left : right;                                      \
                    entry = in_left ? left_entry : right_entry;                         \
                } else {                                                                \
                    break;  /* neither entered: code stays a node's, no leaf */         \
                }                                                                       \
            }                                                                           \
            if (code < 0) {  /* a leaf: its shapes */                                   \
                const int first = (~code) >> 3, count = (~code) & 7;                    \
                PYCLRAY_LEAF_ENTERED(entry)                                             \
                for (int leaf_mask = LEAF_MASK(first, count); leaf_mask != 0 && !(limit < 0.0f); \
                     leaf_mask &= leaf_mask - 1) {                                      \
                    const int q = first + BVH_LOWEST_BIT(leaf_mask);                    \
                    VISIT(q)                                                            \
                }                                                                       \
            }                                                                           \
        }                                                                               \
    }

/* PYCLRAY_TRAVERSE (kernels/bvh_ray.h) runs these steps: its macro names PYCLRAY_TRAVERSE_STEP and
 * BVH_STACK, expanded where it is used, so it takes the pair nodes' step and stack above. */
#endif
#ifndef PYCLRAY_CLOSEST  /* (the closest-point query's search: below) */
/* A render's camera ray (a packet of one: LANES 1) through the pair nodes: every leaf whose box it
 * enters before its best (a real variable VISIT lowers), nearest first; each child's box tested by
 * box_entries_of (kernels/bvh_packet.h), the test the wide traversal gives a child it pops. Its
 * shadow rays likewise, with their own box tests (kernels/shading.h); and in every query a ray in a
 * mesh instance's own tree (kernels/instance.cl: INSTANCE_TRAVERSE), the same boxes and tests as
 * the binary tree's packets of one there (kernels/bvh_packet.h: PYCLRAY_TRAVERSE_PACKET). */
#if LANES != 1
#error "the pair nodes' traversal is one ray per work-item (LANES 1)"
#endif
/* a child's box (lo, hi: a pair node's corners) against the packet's ray: box_entries_of */
inline realv pair_box_entries(const float4 lo, const float4 hi, const BoxPacket* b, const realv limit)
{
    return box_entries_of(lo.xyz, hi.xyz, b, limit);
}
#define PYCLRAY_TRAVERSE_PAIRS(nodes, box, best, VISIT) \
    PYCLRAY_TRAVERSE_PAIRS_WITH(nodes, pair_box_entries, &(box), best, VISIT)
/* the same with another box test ENTRIES_OF(lo, hi, boxes, limit): shadow rays (kernels/shading.h:
 * shadow_box_entries_of, or pair_box_entries from a point light), whose best is their reach
 * (-inf once the ray is blocked: no box is entered then, and the traversal ends) */
#define PYCLRAY_TRAVERSE_PAIRS_WITH(nodes, ENTRIES_OF, boxes, best, VISIT)              \
    {                                                                                   \
        int stack_child[BVH_BINARY_STACK];                                              \
        real stack_entry[BVH_BINARY_STACK];                                             \
        int top = 0;                                                                    \
        int code = 0;  /* the root */                                                   \
        for (;;) {                                                                      \
            while (code >= 0) {  /* down: a node per level */                           \
                const PairNode node = nodes[code];                                      \
                const int left = PAIR_CODE(node.left_lo), right = PAIR_CODE(node.right_lo); \
                const real left_entry = ENTRIES_OF(node.left_lo, node.left_hi, boxes, best); \
                const real right_entry = right != 0 ? ENTRIES_OF(node.right_lo, node.right_hi, boxes, best) \
                                                    : (real)INFINITY;               \
                const bool in_left = left_entry < INFINITY, in_right = right_entry < INFINITY; \
                if (in_left && in_right) {                                              \
                    const bool right_first = right_entry < left_entry;                  \
                    stack_child[top] = right_first ? left : right;                      \
                    stack_entry[top++] = right_first ? left_entry : right_entry;        \
                    code = right_first ? right : left;                                  \
                } else if (in_left || in_right) {                                       \
                    code = in_left ? left : right;                                      \
                } else {                                                                \
                    break;                                                              \
                }                                                                       \
            }                                                                           \
            if (code < 0) {  /* a leaf: its shapes */                                   \
                const int first = (~code) >> 3, count = (~code) & 7;                    \
                for (int q = first; q < first + count; ++q) { VISIT(q) }                \
            }                                                                           \
            /* up: the nearest pushed child entered before the ray's best */            \
            while (top > 0 && !(stack_entry[top - 1] <= best)) --top;                   \
            if (top == 0) break;                                                        \
            code = stack_child[--top];                                                  \
        }                                                                               \
    }
#endif

#ifdef PYCLRAY_CLOSEST
/* The closest-point query's search (kernels/closest.cl; a point per work-item, float64) through the
 * pair nodes: its stack a binary level per entry. A child's box is kept while its distance from the
 * point can still beat or tie the best (the wide search's pruning, the same bound), so the same
 * shapes can win, and closest_take's tie rule picks the same one whatever the order of the visit. */
#undef BVH_STACK
#define BVH_STACK BVH_BINARY_STACK

/* A lower bound of the distance from the point pf (float, from the scene's anchor; margin: over
 * pf's rounding) to a child's float box (lo, hi: a pair node's corners), +inf for an empty box:
 * kernels/closest.cl's closest_box_distances for one box, the same operations in the same order. */
inline float pair_box_distance(const float4 lo, const float4 hi, const float3 pf, const float margin)
{
    const float3 gap = fmax(fmax(lo.xyz - pf, pf - hi.xyz) - margin, (float3)(0.0f));
    /* the sum's and the root's rounding: a few float ulps, taken off */
    const float distance = sqrt(gap.x * gap.x + gap.y * gap.y + gap.z * gap.z) * (1.0f - 0x1p-20f);
    return lo.x <= hi.x ? distance : INFINITY;
}

/* Every leaf of the pair nodes whose box lies within BOUND of the point (a float expression, read
 * again after each leaf: the best distance so far can only shrink), VISIT(first, count) each, until
 * none is left or DONE: down from a node, both children's boxes measured, into the nearer one kept
 * (the first on a tie), the other pushed with its distance; then the last pushed child still within
 * BOUND popped (the others beyond it dropped). stack_child and stack_entry: the caller's stack. */
#define PAIR_CLOSEST_TRAVERSE(nodes, pf, margin, BOUND, DONE, VISIT)                    \
    {                                                                                   \
        int top = 0;                                                                    \
        int code = 0;  /* the root */                                                   \
        float bound = (BOUND);                                                          \
        for (;;) {                                                                      \
            while (code >= 0) {  /* down: a node per level */                           \
                const PairNode node = nodes[code];                                      \
                const int left = PAIR_CODE(node.left_lo), right = PAIR_CODE(node.right_lo); \
                const float left_distance = pair_box_distance(node.left_lo, node.left_hi, pf, margin); \
                const float right_distance = pair_box_distance(node.right_lo, node.right_hi, pf, margin); \
                /* (code 0, the root, is never a child: no second child) */             \
                const bool in_left = left_distance <= bound, in_right = right != 0 && right_distance <= bound; \
                if (in_left && in_right) {                                              \
                    const bool right_first = right_distance < left_distance;            \
                    stack_child[top] = right_first ? left : right;                      \
                    stack_entry[top++] = right_first ? left_distance : right_distance;  \
                    code = right_first ? right : left;                                  \
                } else if (in_left || in_right) {                                       \
                    code = in_left ? left : right;                                      \
                } else {                                                                \
                    break;  /* neither kept: code stays a node's, no leaf */            \
                }                                                                       \
            }                                                                           \
            if (code < 0) {  /* a leaf: its shapes, which may lower the bound */        \
                const int first = (~code) >> 3, count = (~code) & 7;                    \
                VISIT(first, count)                                                     \
                bound = (BOUND);                                                        \
            }                                                                           \
            if (DONE) break;                                                            \
            /* up: the last pushed child still within the bound */                      \
            while (top > 0 && stack_entry[top - 1] > bound) --top;                      \
            if (top == 0) break;                                                        \
            code = stack_child[--top];                                                  \
        }                                                                               \
    }
#endif
