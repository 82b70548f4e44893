/* The shaded image (scene-format.md, "Shading"): compiled in only when it is asked for, and its shadow
 * rays only with PYCLRAY_SHADOWS. The host puts this file before kernels/render.cl, whose render
 * kernel expands the macros below (they use the kernel's arguments: the shapes, the camera).
 *
 * Everything is computed in the camera's space, where the hit point is p = s D (D the camera ray's
 * direction, s its distance): the host packs the lights there (in float64), and each winner's world
 * normal is turned into the space. At a hit with normal n seen along the unit direction D:
 *   n_s = n if n.D < 0 else -n                                    (the side facing the viewer)
 *   shaded = albedo ambient + sum over lights of V E (albedo max(0, n_s.L)
 *            + (specular max(0, n_s.H)^shininess if n_s.L > 0 else 0)),   H = normalize(L - D),
 * E = intensity / |light - p|^2 (point) or the irradiance (directional), V = 0 where the shadow ray
 * from p toward the light meets a shape before the light, else 1.
 *
 * Shadow rays without acne or leaks, at any scale. The shadow ray of a hit p starts where the
 * point hit and the shape it lies on say:
 * - skip-self: where the winner cannot meet its own shadow ray, the ray starts at p itself and that
 *   shape (the winning primitive) is not tested: a flat primitive (plane, disk, rectangle:
 *   PYCLRAY_FLAT_<type> 1 in its kernel file) on either side, a convex one (sphere, box, cylinder:
 *   0) seen from its outer side (n.D < 0, the lit side is then outward: n_s.L > 0). Nothing else is
 *   moved or skipped: an occluder touching p (a ball on the ground) still shadows it.
 * - otherwise (a convex shape's inner side, where the ray may meet the opposite wall), pbrt-v4's
 *   OffsetRayOrigin: p moved along n_s by d = |n_s| . e, e the rounding bound of p's coordinates
 *   and of the shadow test's own roundings. The hit is p = s D in the eye's space, with s from the
 *   host's exact terms: s and each D_i carry a relative error of a few eps (the render's depth is
 *   within a few ulps of t), so p is off by a few eps |p|; the shadow ray's test of the surface from
 *   p rounds terms of about eps |p| too where it takes the better of two forms (a sphere's c directly
 *   or moved from the eye's exact c, kernels/sphere.cl, kernels/cylinder.cl). So d = K eps |p|,
 *   K = SHADOW_OFFSET_K = 16 about twice their sum. It does not grow with the shape's size: the
 *   inside of a dome of radius 1e8 gets the offset of a plane.
 * A point light's shadow ray ends at the light: a hit counts below the distance from the origin to
 * the light.
 */

#ifdef PYCLRAY_FP64
#define SHADING_EPSILON 0x1p-53
#else
#define SHADING_EPSILON 0x1p-24f
#endif
#define SHADOW_OFFSET_K 16  /* pyclray.engine.scene.lighting.SHADOW_OFFSET_K */

/* Smooth shading (PYCLRAY_SMOOTH: a shape of a type in PYCLRAY_SMOOTH_TYPES, a smooth mesh, is
 * present): the winner's shading normal, <type>_shading_normal (world, unit; (0, 0, 0) where the
 * shape is flat), lights the hit instead of the geometric normal, turned toward the viewer as n_s
 * is (as Mitsuba's two-sided BSDF does in its shading space). The geometric normal still decides
 * the side (front), and the shadow ray starts on the geometric surface: at p, the triangle itself
 * skipped (flat), so a shading normal never moves a shadow ray's origin. */
#ifdef PYCLRAY_SMOOTH
#define PYCLRAY_SMOOTH_BEGIN vec3v shading_normal = v3(SPLAT(0), SPLAT(0), SPLAT(0));
#define PYCLRAY_SMOOTH_OF(Type, type)                                                 \
    if (kind == KIND_##type)                                                          \
    {                                                                                 \
        PYCLRAY_SHAPE_OF(Type, type, k, smooth_shape)                                 \
        const PYCLRAY_CAT(Type, Normals) smooth_normals = PYCLRAY_SMOOTH_AT(type, k);    \
        shading_normal = v3_select(shading_normal, type##_shading_normal(smooth_shape, &ray, &smooth_normals), mine); \
    }
#define PYCLRAY_SMOOTH_NORMALS PYCLRAY_SMOOTH_TYPES(PYCLRAY_SMOOTH_OF)
/* n_l: the normal that lights, facing the viewer: the shading normal where there is one, else n_s */
#define PYCLRAY_LIGHTING_NORMAL                                                       \
    const vec3v n_shading = space_from_world(camera, shading_normal);                 \
    const intv has_shading = v3_dot(n_shading, n_shading) > 0;                        \
    const vec3v n_facing = v3_select(v3_scale(n_shading, SPLAT(-1)), n_shading, v3_dot(n_shading, D) < 0); \
    const vec3v n_l = v3_select(n_s, n_facing, has_shading);
#else
#define PYCLRAY_SMOOTH_BEGIN
#define PYCLRAY_SMOOTH_NORMALS
#define PYCLRAY_LIGHTING_NORMAL const vec3v n_l = n_s;
#endif

/* per lane: the winner's material (albedo, specular, shininess) and whether its type is flat,
 * gathered in the winners' loop of kernels/nearest.h (each distinct winner once) */
#define PYCLRAY_MATERIALS_BEGIN                                                       \
    vec3v albedo = v3(SPLAT(0), SPLAT(0), SPLAT(0));                                  \
    realv specular = SPLAT(0), shininess = SPLAT(1);                                  \
    intv flat = SPLAT_INT(0);                                                         \
    PYCLRAY_SMOOTH_BEGIN
#define PYCLRAY_MATERIAL_OF(id, mine, is_flat)                                        \
    {                                                                                 \
        __global const Material* m = &materials[id];                                  \
        albedo = v3_select(albedo, v3_splat(m->color), mine);                         \
        specular = (mine) ? SPLAT(m->color.w) : specular;                             \
        shininess = (mine) ? SPLAT(m->shininess) : shininess;                         \
        flat = (mine) ? SPLAT_INT(is_flat) : flat;                                    \
    }

inline vec3v v3_mul(const vec3v a, const vec3v b) { return v3(a.x * b.x, a.y * b.y, a.z * b.z); }

/* a world direction in the camera's space: its components along u, v, w */
inline vec3v space_from_world(__global const Camera* camera, const vec3v n)
{
    return v3(v3_dot(n, v3_splat(camera->u)), v3_dot(n, v3_splat(camera->v)), v3_dot(n, v3_splat(camera->w)));
}

/* Blinn-Phong from one light: E (albedo cos + specular max(0, n_s.H)^shininess) where cos > 0.
 * x^k as exp2(k log2 x): pow itself is several times slower on PoCL's CPU device and was most of the
 * cost of shading; log2 and exp2 (3 ulps each) make a relative error of about ln 2 |log2 x^k| 7 eps
 * + 6 eps (pyclray.reference.shading.tolerance counts it). Packets without a specular surface skip it. */
inline vec3v shade_light(const vec3v albedo, const realv specular, const realv shininess, const vec3v n_s,
                         const vec3v L, const vec3v D, const realv cos_l, const vec3v E)
{
    realv glossy = SPLAT(0);
    if (ANY(specular > 0)) {
        const vec3v H = v3_normalize(v3_sub(L, D));
        const realv n_h = v_max(v3_dot(n_s, H), SPLAT(0));
        glossy = specular * exp2(shininess * log2(n_h));  /* log2(0) = -inf: 0 */
    }
    return v3_mul(E, v3(albedo.x * cos_l + glossy, albedo.y * cos_l + glossy, albedo.z * cos_l + glossy));
}

#ifdef PYCLRAY_SHADOWS
/* Any hit before the light: the lanes still open (lit, no hit found yet) test a shape and close
 * where it is hit at s < limit (s along the unit direction toward the light; limit: the distance to
 * a point light, +inf for a directional one). Without a BVH every shape of every type is tested;
 * with it (large scenes) the unbounded types (planes) are, and the bounded ones are reached through
 * the BVH's any-hit packet traversal, which drops a lane once it is closed and ends when all are. */
#define PYCLRAY_SHADOW_TEST(Type, type)                                               \
    for (int q = 0; q < n_##type##s && ANY(open); ++q) {                              \
        PYCLRAY_SHAPE_OF(Type, type, q, shape)                                        \
        const intv self = skip && best_key == SPLAT_INT(q * 16 + KIND_##type);        \
        const realv s = PYCLRAY_SHADOW_HIT_##type(shape, &shadow, open ? limit : SPLAT(-INFINITY), self); \
        open = open && (PYCLRAY_SELF_##type(self) || !(s < limit));                   \
    }
#if defined(PYCLRAY_BVH) && defined(PYCLRAY_HAS_BOUNDED)
/* The shadow packet for box tests, in the BVH's space (world axes around the scene's anchor): its
 * unit directions, its per-lane origins, and a margin over their rounding and over a shape test's
 * error from an origin of that size (2^-20 |o|_1, as cast's box rays), and over the rounding of
 * the eye from the anchor (the camera's box origin). */
typedef struct {
    BoxPacket box;
    /* per lane the origin moved by the margin toward each slab's near and far face (the near face
     * is hi where the direction is negative): a face minus these is the face widened by the margin,
     * taken from the origin, in one subtraction per face and lane (as cast's box_ray) */
    vec3v near_origin, far_origin;
} ShadowBoxes;

inline void shadow_box_origins(ShadowBoxes* s, const vec3v origin, const realv margin)
{
    const BoxPacket* b = &s->box;
    s->near_origin = v3(b->negative_x ? origin.x - margin : origin.x + margin,
                        b->negative_y ? origin.y - margin : origin.y + margin,
                        b->negative_z ? origin.z - margin : origin.z + margin);
    s->far_origin = v3(b->negative_x ? origin.x + margin : origin.x - margin,
                       b->negative_y ? origin.y + margin : origin.y - margin,
                       b->negative_z ? origin.z + margin : origin.z - margin);
}

/* per lane, where the ray from its own origin enters the node's box before limit, else +inf
 * (kernels/bvh_packet.h's box_entries, with the faces taken relative to the origin and the margin; the
 * origin's rounding by the margin, the faces' differences by the ray's cone, as there) */
inline realv shadow_box_entries_of(const float4 lo, const float4 hi, const ShadowBoxes* s, const realv limit)
{
    const BoxPacket* b = &s->box;
    const realv near_x = (b->negative_x ? SPLAT(hi.x) : SPLAT(lo.x)) - s->near_origin.x;
    const realv near_y = (b->negative_y ? SPLAT(hi.y) : SPLAT(lo.y)) - s->near_origin.y;
    const realv near_z = (b->negative_z ? SPLAT(hi.z) : SPLAT(lo.z)) - s->near_origin.z;
    const realv far_x = (b->negative_x ? SPLAT(lo.x) : SPLAT(hi.x)) - s->far_origin.x;
    const realv far_y = (b->negative_y ? SPLAT(lo.y) : SPLAT(hi.y)) - s->far_origin.y;
    const realv far_z = (b->negative_z ? SPLAT(lo.z) : SPLAT(hi.z)) - s->far_origin.z;
    const realv enter = flat_entries(v_max(v_max(near_x * b->near_inverse.x, near_y * b->near_inverse.y),
                                           v_max(near_z * b->near_inverse.z, SPLAT(0))), far_x, far_y, far_z, b);
    const realv leave = v_min(v_min(far_x * b->far_inverse.x + b->far_add.x, far_y * b->far_inverse.y + b->far_add.y),
                              v_min(far_z * b->far_inverse.z + b->far_add.z, limit)) * SPLAT(BVH_GAMMA3_2);
    return enter <= leave ? enter : SPLAT(INFINITY);
}

inline realv shadow_box_entries(__global const BvhNode* node, const ShadowBoxes* s, const realv limit)
{
    return shadow_box_entries_of(node->lo, node->hi, s, limit);
}

#define PYCLRAY_SHADOW_VISIT_KIND(Type, type)                                         \
    if (kind == KIND_##type) {                                                        \
        PYCLRAY_SHAPE_OF(Type, type, k, shape)                                        \
        const intv self = skip && best_key == SPLAT_INT(ref);                         \
        const realv s = PYCLRAY_SHADOW_HIT_##type(shape, &shadow, open ? limit : SPLAT(-INFINITY), self); \
        open = open && (PYCLRAY_SELF_##type(self) || !(s < limit));                   \
    }
#define PYCLRAY_SHADOW_VISIT(q)                                                       \
    {                                                                                 \
        if (ANY(open)) { /* the rest of a leaf once every lane is closed: nothing to test */ \
            const int ref = PYCLRAY_REF(q), kind = ref & 15, k = ref >> 4;             \
            PYCLRAY_BOUNDED(PYCLRAY_SHADOW_VISIT_KIND)                                \
            reach = open ? reach : SPLAT(-INFINITY);                                  \
        }                                                                             \
    }
/* A point light's shadow packet, traversed from the light (all its lanes share that origin, so
 * kernels/bvh_packet.h's box_entries takes each node's faces relative to it once for all lanes): lane i's
 * box ray runs from the light along -dir_i over [0, limit_i], the segment the shape tests cover
 * from the lane's own origin (they are still made from there: their exactness does not change).
 * A point the shape test puts at s along dir_i from the origin o_i lies at limit_i - s from the
 * light along -dir_i, up to the roundings of the light in the box space, of o_i and of dir_i limit_i:
 * a few eps of |light| + |o_i| (limit_i <= their sum) and of the direction's length, which the cone
 * covers (t BVH_WIDEN >> eps t). The margin is the one of the origin-wise test, taken at the largest
 * lane, plus that of the light: 2^-20 (|light|_1 + |light from the eye|_1 + max_i (|o_i|_1 + |o_i from
 * the eye|_1)) + the eye's own (box_origin.w). */
inline BoxPacket shadow_light_packet(__global const Camera* camera, const real4 light, const vec3v dir,
                                     const vec3v origin_from_eye, const intv open)
{
    const real4 u = camera->u, v = camera->v, w = camera->w;
    const real3 light_eye = (real3)((light.x * u.x + light.y * v.x) + light.z * w.x,
                                    (light.x * u.y + light.y * v.y) + light.z * w.y,
                                    (light.x * u.z + light.y * v.z) + light.z * w.z);
    const float3 from = convert_float3(light_eye + convert_real3(camera->box_origin.xyz));
    const vec3v o = origin_from_eye;
    const realv lane = (v_abs(o.x) + v_abs(o.y)) + v_abs(o.z);  /* |o_i from the eye|_1 */
    const real3 box_origin = convert_real3(camera->box_origin.xyz);
    /* |x| as the vector ?: (fabs of a vector is a call into PoCL's library on its CPU device) */
    const real3 box_o = box_origin < (real3)(0) ? -box_origin : box_origin;
    /* |o_i|_1 <= |o_i from the eye|_1 + |box origin|_1: one lane_max for both terms */
    const real lanes = 2 * lane_max(open ? lane : SPLAT(0)) + ((box_o.x + box_o.y) + box_o.z);
    const float3 from_abs = from < (float3)(0.0f) ? -from : from;
    const real3 light_abs = light_eye < (real3)(0) ? -light_eye : light_eye;
    const real margin = (real)0x1p-20 * ((((real)from_abs.x + from_abs.y) + from_abs.z)
                                         + ((light_abs.x + light_abs.y) + light_abs.z) + lanes)
                        + camera->box_origin.w;
    /* rounded up to float: a margin never shrinks */
    const float m = (float)margin;
    return box_packet(v3_scale(world_from_space(camera, dir), SPLAT(-1)),
                      (float4)(from, (real)m < margin ? m * (1.0f + 0x1p-23f) : m));
}

/* the bounded shapes' any-hit traversal, given a box test of a node (the binary tree's packets) and
 * of a box (lo, hi: the pair nodes' children, one ray per work-item: kernels/bvh_pairs.h) */
#ifdef PYCLRAY_PAIRS
#define PYCLRAY_SHADOW_TRAVERSE(ENTRIES, ENTRIES_OF, boxes) \
    PYCLRAY_TRAVERSE_PAIRS_WITH(pair_nodes, ENTRIES_OF, boxes, reach, PYCLRAY_SHADOW_VISIT)
#else
#define PYCLRAY_SHADOW_TRAVERSE(ENTRIES, ENTRIES_OF, boxes) \
    PYCLRAY_TRAVERSE_PACKET_WITH(nodes, ENTRIES, boxes, reach, PYCLRAY_SHADOW_VISIT)
#endif
#define PYCLRAY_SHADOW_SHAPES                                                         \
    PYCLRAY_UNBOUNDED(PYCLRAY_SHADOW_TEST)                                            \
    if (point && ANY(open)) {                                                         \
        const BoxPacket from_light = shadow_light_packet(camera, light.position, shadow.dir, \
                                                         world_from_space(camera, shadow.origin), open); \
        realv reach = open ? limit : SPLAT(-INFINITY);                                \
        PYCLRAY_SHADOW_TRAVERSE(box_entries, pair_box_entries, &from_light)          \
    } else if (ANY(open)) {                                                           \
        ShadowBoxes boxes;                                                            \
        boxes.box = box_packet(world_from_space(camera, shadow.dir), camera->box_origin); \
        const vec3v from_eye = world_from_space(camera, shadow.origin);               \
        const vec3v origin = v3_add(from_eye, v3_splat((real4)(convert_real3(camera->box_origin.xyz), 0))); \
        shadow_box_origins(&boxes, origin,                                            \
                           SPLAT(0x1p-20) * ((v_abs(origin.x) + v_abs(origin.y)) + v_abs(origin.z)) \
                           + SPLAT(0x1p-20) * ((v_abs(from_eye.x) + v_abs(from_eye.y)) + v_abs(from_eye.z)) \
                           + SPLAT(camera->box_origin.w));                            \
        realv reach = open ? limit : SPLAT(-INFINITY);                                \
        PYCLRAY_SHADOW_TRAVERSE(shadow_box_entries, shadow_box_entries_of, &boxes)   \
    }
#else
#define PYCLRAY_SHADOW_SHAPES PYCLRAY_SHAPES(PYCLRAY_SHADOW_TEST)
#endif
#define PYCLRAY_SHADOW_RAY                                                            \
    if (point) {                                                                      \
        const vec3v to = v3_sub(v3_splat(light.position), shadow.origin);             \
        limit = v_sqrt(v3_dot(to, to));                                               \
        shadow.dir = v3_scale(to, SPLAT(1) / limit);                                  \
    } else {                                                                          \
        shadow.dir = L;                                                               \
        limit = SPLAT(MISS);                                                          \
    }                                                                                 \
    shadow.a = v3_dot(shadow.dir, shadow.dir);                                        \
    intv open = lit;                                                                  \
    PYCLRAY_SHADOW_SHAPES                                                             \
    lit = open;
#define PYCLRAY_SHADOW_ORIGIN                                                         \
    RayPacket shadow;                                                                 \
    shadow.from_eye = 0;                                                              \
    /* skip-self (see above), or the offset d = K eps |p| along n_s */               \
    const intv skip = flat != 0 || front;                                             \
    {                                                                                 \
        const realv d = SPLAT(SHADOW_OFFSET_K * SHADING_EPSILON) * v_sqrt(v3_dot(p, p)); \
        shadow.origin = v3_add(p, v3_scale(n_s, skip ? SPLAT(0) : d));                \
    }                                                                                 \
    realv limit;
#else
#define PYCLRAY_SHADOW_RAY
#define PYCLRAY_SHADOW_ORIGIN
#endif

/* the shaded colour of each lane (the background on a miss), written as R, G, B */
#define PYCLRAY_WRITE_SHADED(index, first, end)                                       \
    {                                                                                 \
        const intv hit = best < MISS;                                                 \
        const vec3v p = v3_scale(ray.dir, hit ? best : SPLAT(0));                     \
        const vec3v D = v3_scale(ray.dir, SPLAT(1) / v_sqrt(ray.a));                  \
        const vec3v n = space_from_world(camera, normal);                             \
        const intv front = v3_dot(n, D) < 0;                                          \
        const vec3v n_s = v3_select(v3_scale(n, SPLAT(-1)), n, front);                \
        PYCLRAY_LIGHTING_NORMAL                                                       \
        vec3v color = v3_mul(albedo, v3_splat(ambient));                              \
        PYCLRAY_SHADOW_ORIGIN                                                         \
        for (int l = 0; l < n_lights; ++l) {                                          \
            const Light light = lights[l];                                            \
            const int point = light.position.w != 0;                                  \
            vec3v L, E = v3_splat(light.power);                                       \
            if (point) {                                                              \
                const vec3v to = v3_sub(v3_splat(light.position), p);                 \
                const realv d2 = v3_dot(to, to);                                      \
                L = v3_scale(to, SPLAT(1) / v_sqrt(d2));                              \
                E = v3_scale(E, SPLAT(1) / d2);                                       \
            } else {                                                                  \
                L = v3_splat(light.position);                                         \
            }                                                                         \
            const realv cos_l = v3_dot(n_l, L);                                       \
            intv lit = hit && cos_l > 0;                                              \
            if (!ANY(lit)) continue;                                                  \
            PYCLRAY_SHADOW_RAY                                                        \
            if (!ANY(lit)) continue;  /* all in shadow: nothing to add */            \
            const vec3v add = shade_light(albedo, specular, shininess, n_l, L, D, cos_l, E); \
            const vec3v zero = v3(SPLAT(0), SPLAT(0), SPLAT(0));                      \
            color = v3_add(color, v3_select(zero, add, lit));                         \
        }                                                                             \
        write_vec3s(v3_select(v3_splat(background), color, hit), index, first, end, shaded_out); \
    }
