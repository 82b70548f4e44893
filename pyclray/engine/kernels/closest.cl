/* The closest-point query: for each point (float64, world coordinates), the nearest point of any
 * shape's surface, its distance, shape, primitive, barycentrics and normal (PYCLRAY_AOV_POSITION ...
 * or the distance alone), whether it lies inside an analytic solid (PYCLRAY_AOV_INSIDE) and the
 * meshes' generalized winding number there (PYCLRAY_AOV_WINDING) (pyclray/engine/queries/closest.py).
 * The host puts before this file common.h, the generated struct header, bvh.h, closest.h and the
 * file of each shape type present (their type_closest, type_inside: kernels/closest.h).
 *
 * One point per work-item, in float64 from the point as given and the shapes' float64 world
 * entries: no lanes (a point's code whatever the lane width). The bounded shapes are found through the
 * wide BVH (its float boxes around the scene's anchor), nearest box first, pruned by the best
 * distance so far: a box is skipped only where even its float lower bound is beyond that distance.
 * With PYCLRAY_PAIRS (a lane width of 1: GPUs) the same search and the inside test go through the
 * BVH's pair nodes instead (kernels/bvh_pairs.h: the same boxes, bounds and leaves; the same bits);
 * the winding number's program keeps the wide nodes (its expansions are per wide child). */

/* the best candidate so far: an exact tie of distances keeps the lower id, then the lower primitive
 * (the same winner whatever the traversal's order) */
typedef struct {
    ClosestPoint point;
    int kind, k, id, primitive;
} ClosestBest;

inline void closest_take(ClosestBest* best, const ClosestPoint c, const int kind, const int k, const int id,
                         const int primitive)
{
    bool take = c.d2 < best->point.d2;
    if (!take && c.d2 == best->point.d2)
        take = best->kind == KIND_NONE || id < best->id || (id == best->id && primitive < best->primitive);
    if (take) {
        best->point = c;
        best->kind = kind;
        best->k = k;
        best->id = id;
        best->primitive = primitive;
    }
}

/* the smallest float not below x >= 0 (the pruning bound never cuts below the best distance) */
inline float closest_float_above(const double x)
{
    const float f = (float)x;
    return (double)f < x ? nextafter(f, INFINITY) : f;
}

#define CLOSEST_VISIT_KIND(Type, type)                                                          \
    if (kind == KIND_##type)                                                                    \
        closest_take(&best, type##_closest(&type##_worlds[k], p), kind, k, type##_ids[k], type##_primitives[k]);
#define CLOSEST_LINEAR(Type, type)                                                              \
    for (int k = 0; k < n_##type##s; ++k) {                                                     \
        const int kind = KIND_##type;                                                           \
        CLOSEST_VISIT_KIND(Type, type)                                                          \
    }
#define CLOSEST_INSIDE_KIND(Type, type) if (kind == KIND_##type) inside = type##_inside(&type##_worlds[k], p);
#define CLOSEST_INSIDE_LINEAR(Type, type)                                                       \
    for (int k = 0; k < n_##type##s && !inside; ++k) inside = type##_inside(&type##_worlds[k], p);
#define CLOSEST_WINDING_KIND(Type, type) if (kind == KIND_##type) omega += type##_solid_angle(&type##_worlds[k], p);
#ifdef PYCLRAY_PAIRS
#ifdef PYCLRAY_AOV_WINDING
#error "the winding number's expansions are per wide child: its program traverses the wide nodes"
#endif
/* a leaf's shapes (PAIR_CLOSEST_TRAVERSE's VISIT): as candidates of the nearest point; as solids
 * that may hold the point */
#define CLOSEST_VISIT_LEAF(first, count)                                                \
    for (int q = first; q < first + count; ++q) {                                       \
        const int ref = refs[q], kind = ref & 15, k = ref >> 4;                         \
        PYCLRAY_BOUNDED(CLOSEST_VISIT_KIND)                                             \
    }
#define CLOSEST_INSIDE_LEAF(first, count)                                               \
    for (int q = first; q < first + count && !inside; ++q) {                            \
        const int ref = refs[q], kind = ref & 15, k = ref >> 4;                         \
        PYCLRAY_SOLID(CLOSEST_INSIDE_KIND)                                              \
    }
#endif

#if defined(PYCLRAY_HAS_BOUNDED) && !defined(PYCLRAY_PAIRS)
/* Per child of a wide node, a lower bound of the float box's distance to the point pf (float, from
 * the scene's anchor; margin: over pf's rounding), +inf for an empty slot. */
inline float8 closest_box_distances(__global const WideNode* node, const float3 pf, const float margin)
{
    const float8 zero = (float8)(0.0f);
    const float8 gx = fmax(fmax(node->lo_x - pf.x, pf.x - node->hi_x) - margin, zero);
    const float8 gy = fmax(fmax(node->lo_y - pf.y, pf.y - node->hi_y) - margin, zero);
    const float8 gz = fmax(fmax(node->lo_z - pf.z, pf.z - node->hi_z) - margin, zero);
    /* the sum's and the root's rounding: a few float ulps, taken off */
    const float8 distance = sqrt(gx * gx + gy * gy + gz * gz) * (1.0f - 0x1p-20f);
    return node->lo_x <= node->hi_x ? distance : (float8)(INFINITY);
}
#endif

PYCLRAY_KERNELS_BEGIN
PYCLRAY_WORK_ITEM_FUNCTION void closest_point(const int i, PYCLRAY_PARAMETERS)
{
    const int r = ordered ? order[i] : i;
    const double3 p = (double3)(points[3 * r], points[3 * r + 1], points[3 * r + 2]);
#ifdef PYCLRAY_HAS_BOUNDED
    /* the point in the boxes' space, rounded (a relative 2^-24 per coordinate, which the margin covers) */
    const double3 relative = p - scene_anchor.xyz;
    const float3 pf = convert_float3(relative);
    const float margin = (fabs(pf.x) + fabs(pf.y) + fabs(pf.z)) * 0x1p-22f;
    int stack_child[BVH_STACK];
    float stack_entry[BVH_STACK];
#endif

#if defined(PYCLRAY_AOV_DISTANCE) || defined(PYCLRAY_AOV_INSIDE)
    /* -- the nearest surface point: from within (the squared distance to beat: inf, or 0 where only
     * whether the point lies on a surface matters) */
    ClosestBest best;
    best.point.d2 = within;
    best.kind = KIND_NONE;
    best.k = best.id = best.primitive = -1;
    PYCLRAY_UNBOUNDED(CLOSEST_LINEAR)
#if defined(PYCLRAY_HAS_BOUNDED) && defined(PYCLRAY_PAIRS)
    PAIR_CLOSEST_TRAVERSE(nodes, pf, margin, closest_float_above(sqrt(best.point.d2)), 0, CLOSEST_VISIT_LEAF)
#elif defined(PYCLRAY_HAS_BOUNDED)
    {
        int top = 0;
        stack_child[top] = 0;
        stack_entry[top++] = 0.0f;
        while (top > 0) {
            --top;
            const float bound = closest_float_above(sqrt(best.point.d2));
            if (stack_entry[top] > bound) continue;
            const int code = stack_child[top];
            if (code < 0) {  /* a leaf: its shapes */
                const int first = (~code) >> 3, count = (~code) & 7;
                for (int q = first; q < first + count; ++q) {
                    const int ref = refs[q], kind = ref & 15, k = ref >> 4;
                    PYCLRAY_BOUNDED(CLOSEST_VISIT_KIND)
                }
            } else {  /* a node: its children within the bound, nearest popped first */
                union { float8 v; float a[8]; } entries;
                entries.v = closest_box_distances(&nodes[code], pf, margin);
                const int bottom = top;
                for (int mask = bvh_lane_bits(entries.v <= (float8)(bound)); mask != 0; mask &= mask - 1) {
                    const int slot = BVH_LOWEST_BIT(mask);
                    BVH_STACK_PUSH(1, entries.a[slot], nodes[code].child[slot])
                }
            }
        }
    }
#endif
#endif

#ifdef PYCLRAY_AOV_DISTANCE
    {
        const bool found = best.kind != KIND_NONE;
        distance_out[r] = found ? sqrt(best.point.d2) : INFINITY;
#ifdef PYCLRAY_AOV_POSITION
        position_out[3 * r] = found ? (real)best.point.position.x : (real)NAN;
        position_out[3 * r + 1] = found ? (real)best.point.position.y : (real)NAN;
        position_out[3 * r + 2] = found ? (real)best.point.position.z : (real)NAN;
        normal_out[3 * r] = found ? (real)best.point.normal.x : (real)0;
        normal_out[3 * r + 1] = found ? (real)best.point.normal.y : (real)0;
        normal_out[3 * r + 2] = found ? (real)best.point.normal.z : (real)0;
        barycentric_out[2 * r] = (real)best.point.barycentric.x;
        barycentric_out[2 * r + 1] = (real)best.point.barycentric.y;
        id_out[r] = best.id;
        primitive_out[r] = best.primitive;
#endif
    }
#endif

#ifdef PYCLRAY_AOV_INSIDE
    {
        /* -- inside an analytic solid (any whose box holds the point), or on a surface */
        int inside = best.kind != KIND_NONE && best.point.d2 == 0.0;
        PYCLRAY_UNBOUNDED(CLOSEST_INSIDE_LINEAR)
#if defined(PYCLRAY_HAS_BOUNDED) && defined(PYCLRAY_HAS_SOLID) && defined(PYCLRAY_PAIRS)
        if (!inside) PAIR_CLOSEST_TRAVERSE(nodes, pf, margin, 0.0f, inside, CLOSEST_INSIDE_LEAF)
#elif defined(PYCLRAY_HAS_BOUNDED) && defined(PYCLRAY_HAS_SOLID)  /* (bounded solids present: PYCLRAY_SOLID) */
        int top = 0;
        stack_child[top] = 0;
        stack_entry[top++] = 0.0f;
        while (top > 0 && !inside) {
            const int code = stack_child[--top];
            if (code < 0) {
                const int first = (~code) >> 3, count = (~code) & 7;
                for (int q = first; q < first + count && !inside; ++q) {
                    const int ref = refs[q], kind = ref & 15, k = ref >> 4;
                    PYCLRAY_SOLID(CLOSEST_INSIDE_KIND)
                }
            } else {
                union { float8 v; float a[8]; } entries;
                entries.v = closest_box_distances(&nodes[code], pf, margin);
                const int bottom = top;
                for (int mask = bvh_lane_bits(entries.v <= (float8)(0.0f)); mask != 0; mask &= mask - 1) {
                    const int slot = BVH_LOWEST_BIT(mask);
                    BVH_STACK_PUSH(0, 0.0f, nodes[code].child[slot])
                }
            }
        }
#endif
        inside_out[r] = (uchar)inside;
    }
#endif

#ifdef PYCLRAY_AOV_WINDING
    {
        /* -- the meshes' generalized winding number: each wide child's expansion where the point is
         * far from it (bvh/winding.py), its triangles' exact solid angles where near */
        double omega = 0.0;
        int top = 0;
        stack_child[top++] = 0;
        while (top > 0) {
            const int code = stack_child[--top];
            for (int slot = 0; slot < 8; ++slot) {
                __global const WindingSlot* s = &winding_slots[8 * code + slot];
                if (!(s->area.w > 0.0)) continue;  /* empty, or no triangle's area */
                const double3 d = s->center.xyz - p;
                const double d2 = closest_norm2(d);
                const double far = WINDING_BETA * s->center.w;
                if (d2 > far * far) {  /* the expansion to second order (bvh/winding.py) */
                    const double inverse = 1.0 / sqrt(d2), inverse2 = inverse * inverse;
                    const double inverse3 = inverse * inverse2, inverse5 = inverse3 * inverse2;
                    const double3 Md = (double3)(closest_dot(s->m0.xyz, d), closest_dot(s->m1.xyz, d), closest_dot(s->m2.xyz, d));
                    const double trace = s->m0.x + s->m1.y + s->m2.z;
                    /* C_j (xx, yy, zz, xy, xz, yz) for j = x, y, z; u = sum_j row j of C_j, v_j = trace C_j */
                    __global const double* C = (__global const double*)&s->second0;
                    double dCd = 0.0;
                    const double3 u = (double3)(C[0], C[3], C[4]) + (double3)(C[9], C[7], C[11]) + (double3)(C[16], C[17], C[14]);
                    const double3 v = (double3)(C[0] + C[1] + C[2], C[6] + C[7] + C[8], C[12] + C[13] + C[14]);
                    for (int j = 0; j < 3; ++j) {
                        __global const double* Cj = C + 6 * j;
                        const double3 Cd = (double3)(Cj[0] * d.x + Cj[3] * d.y + Cj[4] * d.z,
                                                     Cj[3] * d.x + Cj[1] * d.y + Cj[5] * d.z,
                                                     Cj[4] * d.x + Cj[5] * d.y + Cj[2] * d.z);
                        dCd += (j == 0 ? d.x : (j == 1 ? d.y : d.z)) * closest_dot(d, Cd);
                    }
                    omega += closest_dot(s->area.xyz, d) * inverse3 + trace * inverse3 - 3.0 * closest_dot(d, Md) * inverse5
                             + 0.5 * (-3.0 * inverse5 * (2.0 * closest_dot(u, d) + closest_dot(v, d))
                                      + 15.0 * inverse5 * inverse2 * dCd);
                    continue;
                }
                const int child = nodes[code].child[slot];
                if (child < 0) {
                    const int first = (~child) >> 3, count = (~child) & 7;
                    for (int q = first; q < first + count; ++q) {
                        const int ref = refs[q], kind = ref & 15, k = ref >> 4;
                        PYCLRAY_WINDING_TYPES(CLOSEST_WINDING_KIND)
                    }
                } else {
                    stack_child[top++] = child;
                }
            }
        }
        winding_out[r] = omega / (4.0 * M_PI);
    }
#endif
}

__kernel void closest(PYCLRAY_PARAMETERS)
{
    const int i = get_global_id(0);
    if (i < n_points) closest_point(i, PYCLRAY_ARGUMENTS);
}
