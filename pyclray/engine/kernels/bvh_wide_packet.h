/* Packets through the wide tree (render's camera rays, kernels/render.cl).
 *
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
 * Why: a wide node's visit is one float8 test of its 8 children where the binary tree took three
 * visits, each waiting on the last; the test at the pop keeps the leaves a packet meets
 * (docs/benchmarks.md, "Render's packets through the wide tree").
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
