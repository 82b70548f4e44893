/* The BVH's traversal (pyclray/bvh.py builds it, pyclray/render.py packs it).
 *
 * Node k: its box lo.xyz .. hi.xyz (float, rounded outward from float64 and kept within the float
 * range, so that no test meets inf - inf or 0 * inf) in the box frame (world
 * axes around the eye for render, around the scene's anchor for cast); first = as_int(lo.w),
 * count = as_int(hi.w): a leaf of count shapes at positions first .. first + count - 1 of refs
 * (ref = index in its type's array * 8 + kind), else an internal node with children first and
 * first + 1.
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
#define BVH_STACK 64  /* the LBVH's depth is at most its keys' 63 bits */

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
    const float3 s = select((float3)(1.0f), (float3)(-1.0f), b.negative);
    const float3 size = s * d;
    b.near_origin = o + s * margin;
    b.far_origin = o - s * margin;
    b.near_inverse = s / (size + BVH_WIDEN);
    const int3 steep = size > (float3)(BVH_WIDEN);
    b.far_inverse = select((float3)(0.0f), s / (size - BVH_WIDEN), steep);
    b.far_add = select((float3)(INFINITY), (float3)(0.0f), steep);
    return b;
}

inline float bvh_max(const float a, const float b) { return a > b ? a : b; }
inline float bvh_min(const float a, const float b) { return a < b ? a : b; }

/* Distance along the ray at which it (widened) enters node k's box, or +inf if it misses the
 * box before limit. */
inline float box_entry(__global const BvhNode* node, const BoxRay* b, const float limit)
{
    const float3 lo = node->lo.xyz, hi = node->hi.xyz;
    const float3 near = select(lo, hi, b->negative), far = select(hi, lo, b->negative);
    const float3 t_near = (near - b->near_origin) * b->near_inverse;
    const float3 t_far = (far - b->far_origin) * b->far_inverse + b->far_add;
    const float enter = bvh_max(bvh_max(t_near.x, t_near.y), bvh_max(t_near.z, 0.0f));
    const float leave = bvh_min(bvh_min(t_far.x, t_far.y), bvh_min(t_far.z, limit)) * BVH_GAMMA3_2;
    return enter <= leave ? enter : INFINITY;
}

/* Visit, nearest box first, every leaf position q whose box the ray enters before *limit (a
 * variable the visit may lower): VISIT(q) runs for each shape of each such leaf. */
#define PYCLRAY_TRAVERSE(nodes, box, limit, VISIT)                                      \
    {                                                                                   \
        int stack_node[BVH_STACK];                                                      \
        float stack_entry[BVH_STACK];                                                   \
        int top = 0, k = 0;                                                             \
        bool going = box_entry(&nodes[0], &box, convert_float_rtp(limit)) < INFINITY;             \
        while (going) {                                                                 \
            const int first = as_int(nodes[k].lo.w), count = as_int(nodes[k].hi.w);     \
            if (count > 0) {                                                            \
                for (int q = first; q < first + count; ++q) { VISIT(q) }                \
            } else {                                                                    \
                const float lim = convert_float_rtp(limit);                                       \
                const float t0 = box_entry(&nodes[first], &box, lim);                   \
                const float t1 = box_entry(&nodes[first + 1], &box, lim);               \
                if (t0 < INFINITY || t1 < INFINITY) {                                   \
                    const bool left = t0 <= t1;                                         \
                    k = left ? first : first + 1;                                       \
                    const float other = left ? t1 : t0;                                 \
                    if (other < INFINITY) {                                             \
                        stack_node[top] = left ? first + 1 : first;                     \
                        stack_entry[top++] = other;                                     \
                    }                                                                   \
                    continue;                                                           \
                }                                                                       \
            }                                                                           \
            going = false;                                                              \
            while (top > 0) {                                                           \
                --top;                                                                  \
                if (stack_entry[top] <= convert_float_rtp(limit)) {                               \
                    k = stack_node[top];                                                \
                    going = true;                                                       \
                    break;                                                              \
                }                                                                       \
            }                                                                           \
        }                                                                               \
    }
