/* A packet of rays through the binary tree, one box against all its lanes at once: render's shadow
 * rays (kernels/shading.h) and mesh instances' own trees (kernels/instance.cl, also in cast and
 * any-hit, whose packet is one ray); render's camera packets start from the same box tests
 * (kernels/bvh_wide_packet.h). */

/* A packet's rays from one origin (the eye), per axis: sign / (|d| + widen), sign / (|d| - widen)
 * or 0, and +inf where |d| <= widen (see box_ray); and that origin in the box space (xyz: the eye
 * from the scene's anchor, rounded to float) with a margin over its rounding (w). */
typedef struct {
    vec3v near_inverse, far_inverse, far_add;
    vec3v flat_inverse;  /* sign / (|d| - widen) where |d| <= widen, else 0 (see box_ray) */
    intv negative_x, negative_y, negative_z;
    float4 from;
    /* whether the lanes' direction signs agree on every axis (a camera packet's almost always do),
     * and then those signs (-1: negative): each node's near and far faces are chosen once for all
     * lanes (box_entries) */
    int same_signs;
    int3 negative;
    /* whether also no lane runs flat along an axis (|d| <= widen: far_add is 0 in every lane) */
    int steep;
    /* whether some lane runs flat along some axis: flat_inverse's far-face entries are taken too */
    int flat;
    /* the origin moved by the margin, toward -inf (for the boxes' low faces) and +inf (high faces) */
    float3 from_low, from_high;
} BoxPacket;

inline void box_axis(const realv d, realv* near_inverse, realv* far_inverse, realv* far_add, realv* flat_inverse,
                     intv* negative)
{
    *negative = d < SPLAT(0);
    const realv s = *negative ? SPLAT(-1) : SPLAT(1);
    const realv size = v_abs(d);
    const intv steep = size > SPLAT(BVH_WIDEN);
    *near_inverse = s / (size + SPLAT(BVH_WIDEN));
    *far_inverse = steep ? s / (size - SPLAT(BVH_WIDEN)) : SPLAT(0);
    *far_add = steep ? SPLAT(0) : SPLAT(INFINITY);
    const realv flat_rise = size - SPLAT(BVH_WIDEN);  /* <= 0 where not steep */
    *flat_inverse = steep ? SPLAT(0) : s / (flat_rise < SPLAT(-FLT_MIN) ? flat_rise : SPLAT(-FLT_MIN));
}

inline BoxPacket box_packet(const vec3v d, const float4 from)
{
    BoxPacket b;
    b.from = from;
    box_axis(d.x, &b.near_inverse.x, &b.far_inverse.x, &b.far_add.x, &b.flat_inverse.x, &b.negative_x);
    box_axis(d.y, &b.near_inverse.y, &b.far_inverse.y, &b.far_add.y, &b.flat_inverse.y, &b.negative_y);
    box_axis(d.z, &b.near_inverse.z, &b.far_inverse.z, &b.far_add.z, &b.flat_inverse.z, &b.negative_z);
    const bool all_x = !ANY(!b.negative_x), all_y = !ANY(!b.negative_y), all_z = !ANY(!b.negative_z);
    b.same_signs = (all_x || !ANY(b.negative_x)) && (all_y || !ANY(b.negative_y)) && (all_z || !ANY(b.negative_z));
    b.negative = (int3)(all_x ? -1 : 0, all_y ? -1 : 0, all_z ? -1 : 0);
    b.flat = ANY(b.far_add.x > SPLAT(0) || b.far_add.y > SPLAT(0) || b.far_add.z > SPLAT(0));
    b.steep = b.same_signs && !b.flat;
    /* o + m and o - m round by at most an ulp of o, under 2^-4 m (m = 2^-20 |o|_1 >= 2^-20 |o_k|):
     * the faces stay widened by more than the rounding of o (see box_entries) */
    b.from_low = from.xyz + from.w;
    b.from_high = from.xyz - from.w;
    return b;
}

/* enter (per lane, from the faces relative to the widened origin) raised to the far faces' entries
 * of the axes a lane runs flat along (box_ray: the cone reaches such a slab from beyond its far
 * face too; 0 on the other axes, below enter's own 0) */
inline realv flat_entries(realv enter, const realv far_x, const realv far_y, const realv far_z, const BoxPacket* b)
{
    if (b->flat) {  /* compared so that a NaN product would keep enter (never drops a box) */
        const realv flat_x = far_x * b->flat_inverse.x, flat_y = far_y * b->flat_inverse.y;
        const realv flat_z = far_z * b->flat_inverse.z;
        enter = flat_x > enter ? flat_x : enter;
        enter = flat_y > enter ? flat_y : enter;
        enter = flat_z > enter ? flat_z : enter;
    }
    return enter;
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
    const realv enter = flat_entries(v_max(v_max(near_x * b->near_inverse.x, near_y * b->near_inverse.y),
                                           v_max(near_z * b->near_inverse.z, SPLAT(0))), far_x, far_y, far_z, b);
    const realv leave = v_min(v_min(far_x * b->far_inverse.x + b->far_add.x, far_y * b->far_inverse.y + b->far_add.y),
                              v_min(far_z * b->far_inverse.z + b->far_add.z, limit)) * SPLAT(BVH_GAMMA3_2);
    return enter <= leave ? enter : SPLAT(INFINITY);
}

inline realv box_entries(__global const BvhNode* node, const BoxPacket* b, const realv limit)
{
    return box_entries_of(node->lo.xyz, node->hi.xyz, b, limit);
}

/* A leaf some lane of a packet enters has its shapes' entries asked for from memory at once, so that
 * they arrive while the traversal goes on (leaves far apart in memory, as a large mesh's; docs/
 * benchmarks.md, "Why the engine does what it does"): PYCLRAY_PACKET_LEAF_PREFETCH(first, count),
 * defined by the kernel where it knows where a leaf's entries lie (kernels/render.cl), else nothing. */
#ifndef PYCLRAY_PACKET_LEAF_PREFETCH
#define PYCLRAY_PACKET_LEAF_PREFETCH(first, count)
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
