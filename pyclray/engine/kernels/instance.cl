/* Instance (meshes that share their arrays, pyclray/model/shapes/instance.py): two levels.
 *
 * The scene's BVH holds each instance as one entry (its world box); its mesh's triangles and BVH are
 * one copy in object space (instance_vertices: the meshes' float64 vertices; instance_faces: each
 * triangle's three vertices and its index in its mesh, ~index where it has zero area, from the
 * instance's first, in its tree's leaf order; instance_nodes from the instance's root), shared by all
 * its instances (engine/scene/instances.py). A packet enters an instance through its
 * per-view entry: the eye in object space (float64) and the space's directions there (the rows of
 * object_from_space / k, k a power of two, rounded once). Each triangle it visits is rebased on that
 * object-space eye (its float64 vertices minus the eye, rounded once: the same bits for a vertex
 * shared by two triangles, as a mesh's world triangles get from the per-view pass) and tested by
 * kernels/mesh.cl's watertight test. The tree is traversed in units u = s k along object_from_space d
 * / k (exact: k is a power of two), whose length is at most 1, so that kernels/bvh.h's cone is at
 * least as wide in the object's units as in the world's. Each lane's nearest triangle is kept with
 * its hit (kernels/nearest.h's best_sub): the winners' normals (the object normal through
 * sign(det A) A^-T, normalized in float64), indices and barycentrics come from it. */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable

inline double instance_dot(const double4 row, const double3 x) { return (row.x * x.x + row.y * x.y) + row.z * x.z; }

/* x minus its rounding to the kernel's precision, rounded (0 in fp64) */
inline real instance_low(const double x) { return (real)(x - (double)(real)x); }

#if defined(PYCLRAY_REBASE) || defined(PYCLRAY_CAST)

/* an instance in a camera's space: the same float64 operations, in the same order, as
 * pyclray.model.shapes.instance.Instances._rebase (a test holds the two to the same bits); in cast,
 * on the ray's origin with the world's axes (kernels/cast.h) */
inline void instance_rebase(__global const InstanceWorld* world, PYCLRAY_REBASE_OUT Instance* out, const Space* space)
{
    /* the eye in object space: object_from_world (eye - translate) */
    const double3 F = space->origin - world->translate.xyz;
    const double3 eye = (double3)(instance_dot(world->inverse0, F), instance_dot(world->inverse1, F),
                                  instance_dot(world->inverse2, F));
    out->eye = (double4)(eye, 0.0);
    out->normal0 = world->normal0;
    out->normal1 = world->normal1;
    out->normal2 = world->normal2;
    /* object_from_space = object_from_world world_from_space (the space's axes are its columns), over k */
#ifdef PYCLRAY_CAST
    const double3 u = (double3)(1, 0, 0), v = (double3)(0, 1, 0), w = (double3)(0, 0, 1);
#else
    const double3 u = space->u, v = space->v, w = space->w;
#endif
    const double k = world->anchor.w;
    out->m0 = (real4)((real)(instance_dot(world->inverse0, u) / k), (real)(instance_dot(world->inverse0, v) / k),
                      (real)(instance_dot(world->inverse0, w) / k), (real)k);
    out->m1 = (real4)((real)(instance_dot(world->inverse1, u) / k), (real)(instance_dot(world->inverse1, v) / k),
                      (real)(instance_dot(world->inverse1, w) / k), 0);
    out->m2 = (real4)((real)(instance_dot(world->inverse2, u) / k), (real)(instance_dot(world->inverse2, v) / k),
                      (real)(instance_dot(world->inverse2, w) / k), 0);
    /* and what their rounding left out, rounded (the fp32 camera rays' exact object direction) */
    out->m_low0 = (real4)(instance_low(instance_dot(world->inverse0, u) / k), instance_low(instance_dot(world->inverse0, v) / k),
                          instance_low(instance_dot(world->inverse0, w) / k), 0);
    out->m_low1 = (real4)(instance_low(instance_dot(world->inverse1, u) / k), instance_low(instance_dot(world->inverse1, v) / k),
                          instance_low(instance_dot(world->inverse1, w) / k), 0);
    out->m_low2 = (real4)(instance_low(instance_dot(world->inverse2, u) / k), instance_low(instance_dot(world->inverse2, v) / k),
                          instance_low(instance_dot(world->inverse2, w) / k), 0);
    /* the eye from the tree's anchor, rounded to float, and a margin over that rounding (as the camera's) */
    const float3 box = convert_float3(eye - world->anchor.xyz);
    const double3 size = convert_double3(box < (float3)(0.0f) ? -box : box);
    out->box = (float4)(box, (float)(0x1p-20 * ((size.x + size.y) + size.z)));
    out->root = world->root;
    out->first = world->first;
}

#endif

#if !defined(PYCLRAY_REBASE) && !defined(PYCLRAY_CLOSEST)  /* the ray tests (none in the closest-point query) */

/* a shadow ray leaving a triangle never meets it again (as a mesh's); shadow rays see instances'
 * meshes as their own triangles, though (engine/queries/render.py), so this only completes the type */
#define PYCLRAY_FLAT_instance 1

/* The instance's own tree: its binary nodes from root, traversed as a packet (kernels/bvh_packet.h);
 * where the program traverses pair nodes (one ray per work-item, a GPU's lane width: PYCLRAY_PAIRS)
 * its pair nodes from root / 2 (engine/scene/instances.py: instance_nodes holds them there), walked
 * by kernels/bvh_pairs.h. A pair node holds its two children's binary boxes, tested by the same
 * operations, so the leaves are the same, and every search below keeps its winner by a rule that
 * does not depend on the order of the visit (tests/test_gpu_traversal.py: the same bits). */
#ifdef PYCLRAY_PAIRS
#define INSTANCE_NODE PairNode
#define INSTANCE_ROOT(root) ((root) >> 1)
#define INSTANCE_TRAVERSE(nodes, box, best, VISIT) PYCLRAY_TRAVERSE_PAIRS(nodes, box, best, VISIT)
/* with another box test: ENTRIES of a binary node, ENTRIES_OF of a pair node's child box (lo, hi) */
#define INSTANCE_TRAVERSE_WITH(nodes, ENTRIES, ENTRIES_OF, boxes, best, VISIT) \
    PYCLRAY_TRAVERSE_PAIRS_WITH(nodes, ENTRIES_OF, boxes, best, VISIT)
#else
#define INSTANCE_NODE BvhNode
#define INSTANCE_ROOT(root) root
#define INSTANCE_TRAVERSE PYCLRAY_TRAVERSE_PACKET
#define INSTANCE_TRAVERSE_WITH(nodes, ENTRIES, ENTRIES_OF, boxes, best, VISIT) \
    PYCLRAY_TRAVERSE_PACKET_WITH(nodes, ENTRIES, boxes, best, VISIT)
#endif

/* a face's corners rebased on the object-space eye: each vertex's float64 difference rounded once; w
 * 1, or 0 for a zero-area triangle (kernels/mesh.cl then never hits it) */
#define INSTANCE_CORNERS(vertices, f, eye)                                                            \
    (real4)(convert_real3(vertices[(f).x].xyz - (eye)), (f).w >= 0 ? 1 : 0),                          \
    (real4)(convert_real3(vertices[(f).y].xyz - (eye)), (f).w >= 0 ? 1 : 0),                          \
    (real4)(convert_real3(vertices[(f).z].xyz - (eye)), (f).w >= 0 ? 1 : 0)

#ifdef PYCLRAY_PIXEL_EXACT
/* A packet's lanes in float64 (instances are built only where the device has it: their kernel
 * reads float64 vertices anyway), converted lane by lane: a library conversion of 512 bits of
 * doubles is a call that PoCL's CPU device cannot build (pyclray/engine/launch/programs.py:
 * MAX_LANE_BITS), a cast per lane compiles to vector conversions everywhere. */
#if LANES == 1
typedef double instance_doublev;
inline instance_doublev instance_to_double(const realv x) { return (double)x; }
inline realv instance_to_real(const instance_doublev x) { return (real)x; }
#else
typedef PYCLRAY_CAT(double, LANES) instance_doublev;
#define INSTANCE_LANE_TO_DOUBLE(l, s) r.s = (double)x.s;
#define INSTANCE_LANE_TO_REAL(l, s) r.s = (real)x.s;
inline instance_doublev instance_to_double(const realv x)
{
    instance_doublev r;
    PYCLRAY_EACH_LANE(INSTANCE_LANE_TO_DOUBLE)
    return r;
}
inline realv instance_to_real(const instance_doublev x)
{
    realv r;
    PYCLRAY_EACH_LANE(INSTANCE_LANE_TO_REAL)
    return r;
}
#endif

/* one component of a camera ray's object direction: a row of object_from_space / k, high + low
 * (a float pair: exact in float64), times the pixel point (sx, sy, 1) (sx = x + x_low, sy alike:
 * exact in float64) in float64, whose roundings are far below float's even where the terms cancel,
 * rounded to float, over the point's length: the float64 pixel ray's component within a rounding
 * or two, relative to itself (kernels/lanes.h's pixel_dot in float64, where the device has it) */
inline realv instance_pixel_row(const instance_doublev sx, const instance_doublev sy, const real4 high, const real4 low,
                                const realv length)
{
    const double rx = (double)high.x + (double)low.x, ry = (double)high.y + (double)low.y, rz = (double)high.z + (double)low.z;
    return instance_to_real((sx * rx + sy * ry) + rz) / length;
}
#endif

/* the packet in object space: from the eye (where its triangles are rebased), along object_from_space d / k
 * as the float product of the rounded rows and the rounded direction */
inline RayPacket instance_rounded_ray(SHAPE_SPACE const Instance* inst, const RayPacket* ray)
{
    const vec3v d = ray->dir;
    const real4 m0 = inst->m0, m1 = inst->m1, m2 = inst->m2;
    RayPacket r;
    r.origin = v3(SPLAT(0), SPLAT(0), SPLAT(0));
    r.dir = v3((SPLAT(m0.x) * d.x + SPLAT(m0.y) * d.y) + SPLAT(m0.z) * d.z,
               (SPLAT(m1.x) * d.x + SPLAT(m1.y) * d.y) + SPLAT(m1.z) * d.z,
               (SPLAT(m2.x) * d.x + SPLAT(m2.y) * d.y) + SPLAT(m2.z) * d.z);
    r.a = v3_dot(r.dir, r.dir);
#ifdef PYCLRAY_SHADOWS
    r.from_eye = 1;
#endif
    return r;
}

#ifdef PYCLRAY_PIXEL_EXACT
/* A camera ray's object direction is the float64 pixel ray's, rounded (instance_pixel_row), as a
 * copy's camera-space direction is: the rounded product above turns it by a few eps, enough to
 * move a contour pixel's ray across the edge it passes within a few eps of (issue 42). */
inline void instance_pixel_direction(SHAPE_SPACE const Instance* inst, const RayPacket* ray, RayPacket* object)
{
    const instance_doublev sx = instance_to_double(ray->x) + instance_to_double(ray->x_low);
    const instance_doublev sy = instance_to_double(ray->y) + instance_to_double(ray->y_low);
    object->dir = v3(instance_pixel_row(sx, sy, inst->m0, inst->m_low0, ray->length),
                     instance_pixel_row(sx, sy, inst->m1, inst->m_low1, ray->length),
                     instance_pixel_row(sx, sy, inst->m2, inst->m_low2, ray->length));
    object->a = v3_dot(object->dir, object->dir);
}
#endif

/* the packet in object space, a camera ray's direction exact */
inline RayPacket instance_ray(SHAPE_SPACE const Instance* inst, const RayPacket* ray)
{
    RayPacket r = instance_rounded_ray(inst, ray);
#ifdef PYCLRAY_PIXEL_EXACT
    if (FROM_EYE(ray)) instance_pixel_direction(inst, ray, &r);
#endif
    return r;
}

/* Per lane the nearest hit s <= limit (along the packet's own directions; an exact tie with limit
 * counts, so that the caller's lowest-id rule sees it), or MISS; which: its triangle's position in
 * the tree's leaf order (the lowest on a tie), -1 where none. */
inline realv instance_search(SHAPE_SPACE const Instance* inst, const RayPacket* ray, const realv limit,
                             __global const double4* vertices, __global const int4* faces, __global const INSTANCE_NODE* nodes,
                             intv* which)
{
    const real scale = inst->m0.w;
    /* the tree's boxes are tested along the rounded direction, within a few eps of a camera ray's
     * exact one: far inside the boxes' cone (kernels/bvh.h: BVH_WIDEN, 2^-12 of the distance), so
     * that no box the exact ray's hits lie in is dropped; the exact direction is taken at the first
     * leaf the packet reaches (a packet that meets no leaf of this instance never pays for it) */
    RayPacket object = instance_rounded_ray(inst, ray);
    const BoxPacket box = box_packet(object.dir, inst->box);
#ifdef PYCLRAY_PIXEL_EXACT
    bool exact = !FROM_EYE(ray);
#define INSTANCE_EXACT_DIRECTION                           \
    if (!exact) {                                          \
        instance_pixel_direction(inst, ray, &object);      \
        exact = true;                                      \
    }
#else
#define INSTANCE_EXACT_DIRECTION
#endif
    const double3 eye = inst->eye.xyz;
    __global const INSTANCE_NODE* tree = nodes + INSTANCE_ROOT(inst->root);
    __global const int4* own = faces + inst->first;
    realv nearest = limit * SPLAT(scale);  /* in the tree's units: exact */
    intv found = SPLAT_INT(0), leaf = SPLAT_INT(-1);
#define INSTANCE_VISIT(q)                                                                             \
    {                                                                                                 \
        INSTANCE_EXACT_DIRECTION                                                                      \
        const int4 f = own[q];                                                                        \
        const realv s = mesh_hit_of(INSTANCE_CORNERS(vertices, f, eye), &object);                     \
        const intv take = s < nearest || (s == nearest && s < MISS && (!found || SPLAT_INT(q) < leaf)); \
        if (ANY(take)) {                                                                              \
            nearest = take ? s : nearest;                                                             \
            leaf = take ? SPLAT_INT(q) : leaf;                                                        \
            found = found || take;                                                                    \
        }                                                                                             \
    }
    INSTANCE_TRAVERSE(tree, box, nearest, INSTANCE_VISIT)
#undef INSTANCE_VISIT
#undef INSTANCE_EXACT_DIRECTION
    *which = leaf;
    return found ? nearest / SPLAT(scale) : SPLAT(MISS);
}

/* each distinct winning triangle q once (the largest first), with the lanes it won */
#define INSTANCE_EACH_WINNER(which, ...)                                                              \
    {                                                                                                 \
        intv pending = which;                                                                         \
        for (int q = (int)lanes_max_int(pending); q >= 0; q = (int)lanes_max_int(pending)) {          \
            const intv lanes = pending == SPLAT_INT(q);                                               \
            __VA_ARGS__                                                                               \
            pending = lanes ? SPLAT_INT(-1) : pending;                                                \
        }                                                                                             \
    }

/* the unit world normal: the object normal through the normal matrix sign(det A) A^-T, in float64 */
inline vec3v instance_normal(SHAPE_SPACE const Instance* inst, const intv which, __global const double4* vertices,
                             __global const int4* faces)
{
    vec3v normal = v3(SPLAT(0), SPLAT(0), SPLAT(0));
    INSTANCE_EACH_WINNER(which, {
        const int4 f = faces[inst->first + q];  /* its unit object normal (kernels/mesh.cl) */
        const double3 n = mesh_unit_normal(vertices[f.x].xyz, vertices[f.y].xyz, vertices[f.z].xyz);
        const double3 w = (double3)(instance_dot(inst->normal0, n), instance_dot(inst->normal1, n), instance_dot(inst->normal2, n));
        const real3 unit = convert_real3(w / sqrt((w.x * w.x + w.y * w.y) + w.z * w.z));
        normal = v3_select(normal, v3(SPLAT(unit.x), SPLAT(unit.y), SPLAT(unit.z)), lanes);
    })
    return normal;
}

/* the winning triangle's index in its mesh (its face's w: a winner has area, so w >= 0) */
inline intv instance_primitive(SHAPE_SPACE const Instance* inst, const intv which, __global const int4* faces)
{
    intv primitive = SPLAT_INT(-1);
    INSTANCE_EACH_WINNER(which, { primitive = lanes ? SPLAT_INT(faces[inst->first + q].w) : primitive; })
    return primitive;
}

/* the winning triangle's barycentrics, from its test in object space (an affine map keeps them) */
inline void instance_barycentric(SHAPE_SPACE const Instance* inst, const RayPacket* ray, const intv which,
                                 __global const double4* vertices, __global const int4* faces, realv* u, realv* v)
{
    const RayPacket object = instance_ray(inst, ray);
    const double3 eye = inst->eye.xyz;
    *u = SPLAT(0);
    *v = SPLAT(0);
    INSTANCE_EACH_WINNER(which, {
        const int4 f = faces[inst->first + q];
        realv tu, tv;
        mesh_barycentric_of(INSTANCE_CORNERS(vertices, f, eye), &object, &tu, &tv);
        *u = lanes ? tu : *u;
        *v = lanes ? tv : *v;
    })
}

#ifdef PYCLRAY_SHADOWS
/* Shadow packets (kernels/shading.h): each lane from its own point p of the eye's space, which is
 * k object_from_space p / k from the object-space eye: the triangles rebased on that eye as for
 * camera rays, each lane's origin subtracted in the shape test (kernels/mesh.cl, as a mesh's shadow
 * rays do), and the tree's boxes tested from each lane's origin with a margin over its rounding (as
 * shading.h's shadow_box_entries). The skip-self rule is per triangle: the lanes whose winner is this
 * instance skip their winning triangle (skip), not the whole instance. Any hit before limit closes a
 * lane (and drops it from the traversal); returns 0 there (< limit), MISS elsewhere. */
typedef struct {
    BoxPacket box;
    vec3v origin;
    realv margin;
} InstanceShadowBoxes;

/* a box (lo, hi) against the lanes' origins, widened by their margin */
inline realv instance_shadow_entries_of(const float4 lo, const float4 hi, const InstanceShadowBoxes* s, const realv limit)
{
    const BoxPacket* b = &s->box;
    const realv m = s->margin;
    const realv near_x = (b->negative_x ? SPLAT(hi.x) + m : SPLAT(lo.x) - m) - s->origin.x;
    const realv near_y = (b->negative_y ? SPLAT(hi.y) + m : SPLAT(lo.y) - m) - s->origin.y;
    const realv near_z = (b->negative_z ? SPLAT(hi.z) + m : SPLAT(lo.z) - m) - s->origin.z;
    const realv far_x = (b->negative_x ? SPLAT(lo.x) - m : SPLAT(hi.x) + m) - s->origin.x;
    const realv far_y = (b->negative_y ? SPLAT(lo.y) - m : SPLAT(hi.y) + m) - s->origin.y;
    const realv far_z = (b->negative_z ? SPLAT(lo.z) - m : SPLAT(hi.z) + m) - s->origin.z;
    const realv enter = flat_entries(v_max(v_max(near_x * b->near_inverse.x, near_y * b->near_inverse.y),
                                           v_max(near_z * b->near_inverse.z, SPLAT(0))), far_x, far_y, far_z, b);
    const realv leave = v_min(v_min(far_x * b->far_inverse.x + b->far_add.x, far_y * b->far_inverse.y + b->far_add.y),
                              v_min(far_z * b->far_inverse.z + b->far_add.z, limit)) * SPLAT(BVH_GAMMA3_2);
    return enter <= leave ? enter : SPLAT(INFINITY);
}

/* a binary node's box (the packets' traversal) */
inline realv instance_shadow_entries(__global const BvhNode* node, const InstanceShadowBoxes* s, const realv limit)
{
    return instance_shadow_entries_of(node->lo, node->hi, s, limit);
}

inline realv instance_shadow_hit(SHAPE_SPACE const Instance* inst, const RayPacket* ray, const realv limit, const intv skip,
                                 __global const double4* vertices, __global const int4* faces,
                                 __global const INSTANCE_NODE* nodes)
{
    const real scale = inst->m0.w;
    RayPacket object = instance_ray(inst, ray);
    const vec3v p = ray->origin;
    const real4 m0 = inst->m0, m1 = inst->m1, m2 = inst->m2;
    /* the lanes' origins from the object-space eye: k (object_from_space / k) p, k a power of two */
    object.origin = v3_scale(v3((SPLAT(m0.x) * p.x + SPLAT(m0.y) * p.y) + SPLAT(m0.z) * p.z,
                                (SPLAT(m1.x) * p.x + SPLAT(m1.y) * p.y) + SPLAT(m1.z) * p.z,
                                (SPLAT(m2.x) * p.x + SPLAT(m2.y) * p.y) + SPLAT(m2.z) * p.z), SPLAT(scale));
    object.from_eye = 0;
    InstanceShadowBoxes boxes;
    boxes.box = box_packet(object.dir, inst->box);
    const vec3v o = object.origin;
    boxes.origin = v3_add(o, v3_splat((real4)(convert_real3(inst->box.xyz), 0)));  /* from the tree's anchor */
    boxes.margin = SPLAT(0x1p-20) * ((v_abs(boxes.origin.x) + v_abs(boxes.origin.y)) + v_abs(boxes.origin.z))
                   + SPLAT(0x1p-20) * ((v_abs(o.x) + v_abs(o.y)) + v_abs(o.z)) + SPLAT(inst->box.w);
    const double3 eye = inst->eye.xyz;
    __global const INSTANCE_NODE* tree = nodes + INSTANCE_ROOT(inst->root);
    __global const int4* own = faces + inst->first;
    const realv bound = limit * SPLAT(scale);  /* in the tree's units */
    realv reach = bound;
    intv blocked = SPLAT_INT(0);
#define INSTANCE_SHADOW_VISIT(q)                                                                      \
    {                                                                                                 \
        const int4 f = own[q];                                                                        \
        const realv s = mesh_hit_of(INSTANCE_CORNERS(vertices, f, eye), &object);                     \
        const intv hit = s < bound && SPLAT_INT(q) != skip;                                           \
        blocked = blocked || hit;                                                                     \
        reach = blocked ? SPLAT(-INFINITY) : reach;                                                   \
    }
    INSTANCE_TRAVERSE_WITH(tree, instance_shadow_entries, instance_shadow_entries_of, &boxes, reach, INSTANCE_SHADOW_VISIT)
#undef INSTANCE_SHADOW_VISIT
    return blocked ? SPLAT(0) : SPLAT(MISS);
}
#define PYCLRAY_SHADOW_HIT_instance(shape, ray, limit, self) \
    instance_shadow_hit(shape, ray, limit, (self) ? best_sub : SPLAT_INT(-1), instance_vertices, instance_faces, \
                        instance_nodes)
#define PYCLRAY_SELF_instance(self) SPLAT_INT(0)  /* its winning triangle is skipped, not the instance */
#endif

#ifdef PYCLRAY_SMOOTH
/* Smooth shading: the winning triangle's vertex normals placed (the object's through the normal
 * matrix, normalized in float64: the placed mesh's vertex normals, Mesh.vertex_normals, up to their
 * sign, which the lighting's facing rule drops) and interpolated at the hit's barycentrics, as
 * kernels/mesh.cl's mesh_shading_normal; (0, 0, 0) where the instance is flat. */
inline real4 instance_vertex_normal(SHAPE_SPACE const Instance* inst, const double4 n)
{
    const double3 w = (double3)(instance_dot(inst->normal0, n.xyz), instance_dot(inst->normal1, n.xyz),
                                instance_dot(inst->normal2, n.xyz));
    const double length = sqrt((w.x * w.x + w.y * w.y) + w.z * w.z);
    return length > 0 ? (real4)(convert_real3(w / length), 0) : (real4)(0);
}

inline vec3v instance_smooth_normal(SHAPE_SPACE const Instance* inst, const RayPacket* ray, const InstanceNormals* flags,
                                    const intv which, __global const double4* vertices, __global const int4* faces,
                                    __global const double4* normals)
{
    vec3v out = v3(SPLAT(0), SPLAT(0), SPLAT(0));
    if (!flags->smooth) return out;
    realv u, v;  /* each lane's, from its winning triangle */
    instance_barycentric(inst, ray, which, vertices, faces, &u, &v);
    const realv w = (SPLAT(1) - u) - v;
    INSTANCE_EACH_WINNER(which, {
        const int4 f = faces[inst->first + q];
        const real4 na = instance_vertex_normal(inst, normals[f.x]), nb = instance_vertex_normal(inst, normals[f.y]);
        const real4 nc = instance_vertex_normal(inst, normals[f.z]);
        const vec3v n = v3((w * na.x + u * nb.x) + v * nc.x, (w * na.y + u * nb.y) + v * nc.y, (w * na.z + u * nb.z) + v * nc.z);
        const realv length2 = v3_dot(n, n);
        out = v3_select(out, v3_scale(n, length2 > 0 ? SPLAT(1) / v_sqrt(length2) : SPLAT(0)), lanes);
    })
    return out;
}
/* kernels/shading.h's call, in its winners' loop (mine: the lanes this instance won) */
#define instance_shading_normal(shape, ray, flags) \
    instance_smooth_normal(shape, ray, flags, (mine) ? best_sub : SPLAT_INT(-1), instance_vertices, instance_faces, \
                           instance_normals)
#endif

#ifdef PYCLRAY_CAST
/* cast's and occluded's one ray (LANES 1): its nearest hit in the instance; the winner's triangle is
 * found again for its normal (the same search gives the same bits) */
inline real instance_cast_hit(const Instance* inst, const RayPacket* ray, __global const double4* vertices,
                              __global const int4* faces, __global const INSTANCE_NODE* nodes)
{
    int which;
    return instance_search(inst, ray, MISS, vertices, faces, nodes, &which);
}

inline vec3v instance_cast_normal(const Instance* inst, const RayPacket* ray, __global const double4* vertices,
                                  __global const int4* faces, __global const INSTANCE_NODE* nodes)
{
    int which;
    instance_search(inst, ray, MISS, vertices, faces, nodes, &which);
    return instance_normal(inst, which, vertices, faces);
}
#ifdef PYCLRAY_ALL_HITS
/* every triangle the ray crosses (count_hits, all_hits: kernels/allhits.cl), each one's distance
 * ALLHITS_TAKE'n with its index in its mesh: the instance's tree traversed to its end, each triangle
 * rebased on the object-space eye and tested by kernels/mesh.cl (with its tie rule); from is the
 * distance of the ray's start, where the instance was rebased, k the instance's index */
#define INSTANCE_ALL_VISIT(q)                                                                         \
    {                                                                                                 \
        const int4 f_ = own_[q];                                                                      \
        const real s_ = mesh_hit_of(INSTANCE_CORNERS(instance_vertices, f_, eye_), &object_);         \
        if (s_ < MISS) ALLHITS_TAKE(from_ + (double)(s_ / scale_) * ray_length, kind_, instance_k_, f_.w) \
    }
#define PYCLRAY_ALL_HITS_instance(shape, ray, from, kind, k)                                          \
    {                                                                                                 \
        const Instance* inst_ = (shape);                                                              \
        const real scale_ = inst_->m0.w;                                                              \
        const RayPacket object_ = instance_ray(inst_, (ray));                                         \
        const BoxPacket box_ = box_packet(object_.dir, inst_->box);                                   \
        const double3 eye_ = inst_->eye.xyz;                                                          \
        __global const INSTANCE_NODE* tree_ = instance_nodes + INSTANCE_ROOT(inst_->root);            \
        __global const int4* own_ = instance_faces + inst_->first;                                    \
        const double from_ = (from);                                                                  \
        const int kind_ = (kind), instance_k_ = (k);                                                  \
        const realv reach_ = SPLAT(MISS);                                                             \
        INSTANCE_TRAVERSE(tree_, box_, reach_, INSTANCE_ALL_VISIT)                                    \
    }
#endif
/* cast's winner's triangle index in its mesh and its barycentrics (found again, as for its normal) */
inline int instance_cast_primitive(const Instance* inst, const RayPacket* ray, __global const double4* vertices,
                                   __global const int4* faces, __global const INSTANCE_NODE* nodes)
{
    int which;
    instance_search(inst, ray, MISS, vertices, faces, nodes, &which);
    return instance_primitive(inst, which, faces);
}

inline void instance_cast_barycentric(const Instance* inst, const RayPacket* ray, __global const double4* vertices,
                                      __global const int4* faces, __global const INSTANCE_NODE* nodes, real* u, real* v)
{
    int which;
    instance_search(inst, ray, MISS, vertices, faces, nodes, &which);
    instance_barycentric(inst, ray, which, vertices, faces, u, v);
}
#define PYCLRAY_CAST_PRIMITIVE_OF_instance(shape, ray) \
    instance_cast_primitive(shape, ray, instance_vertices, instance_faces, instance_nodes)
#define PYCLRAY_CAST_BARYCENTRIC_OF_instance(shape, ray, u, v) \
    instance_cast_barycentric(shape, ray, instance_vertices, instance_faces, instance_nodes, u, v)
#define PYCLRAY_HIT_instance(shape, ray, limit) \
    instance_cast_hit(shape, ray, instance_vertices, instance_faces, instance_nodes)
#define PYCLRAY_NORMAL_instance(shape, ray, basis, best, mine) \
    instance_cast_normal(shape, ray, instance_vertices, instance_faces, instance_nodes)
#else
/* how kernels/nearest.h calls an instance's functions: with the shared arrays, the lanes' best so
 * far, and for the winners the triangle each lane's hit was on (best_sub, kept from hit_sub) */
#define PYCLRAY_SUBPRIMITIVES 1
#define PYCLRAY_HIT_instance(shape, ray, limit) \
    instance_search(shape, ray, limit, instance_vertices, instance_faces, instance_nodes, &hit_sub)
#define PYCLRAY_NORMAL_instance(shape, ray, basis, best, mine) \
    instance_normal(shape, (mine) ? best_sub : SPLAT_INT(-1), instance_vertices, instance_faces)
#define PYCLRAY_PRIMITIVE_instance(shape, k, best, mine) \
    instance_primitive(shape, (mine) ? best_sub : SPLAT_INT(-1), instance_faces)
#define PYCLRAY_BARYCENTRIC_instance(shape, ray, best, mine, u, v) \
    instance_barycentric(shape, ray, (mine) ? best_sub : SPLAT_INT(-1), instance_vertices, instance_faces, u, v)

#endif

#endif
