/* The nearest hit of each lane of a render's packet, and what the winners give the images.
 *
 * Every shape is tested against the whole packet; a lane takes a shape's s where it is nearer, or
 * equally near with a lower id, or equally near with the same id and a lower key (below): an exact
 * tie has one winner whatever the order of the visit, also between the triangles of one mesh (the
 * BVH's order and the tile lists' give the same images). Without an image that needs the winner
 * (PYCLRAY_TRACK_ID, from the host) only the distance is kept.
 * A lane's winner is also kept as one key, 16 k + kind (k its index in its type's array; kinds are
 * 1 to 15, as in the BVH's refs), 0 on a miss: one select per shape instead of two. */

#if defined(PYCLRAY_AOV_NORMAL) || defined(PYCLRAY_AOV_SHADED)
#define PYCLRAY_WINNER_NORMAL 1  /* the winner's normal is computed */
#endif
#if defined(PYCLRAY_WINNER_NORMAL) || defined(PYCLRAY_AOV_PRIMITIVE) || defined(PYCLRAY_AOV_BARYCENTRIC)
#define PYCLRAY_WINNER_LOOP 1  /* the packet's distinct winners are visited once each */
#endif
/* without shading (kernels/shading.h defines these), no material, light or shadow code at all */
#ifndef PYCLRAY_AOV_SHADED
#define PYCLRAY_MATERIALS_BEGIN
#define PYCLRAY_MATERIAL_OF(id, mine, flat)
#define PYCLRAY_WRITE_SHADED(index, first, end)
#define PYCLRAY_SMOOTH_NORMALS
#endif

/* A type whose hit also says which of its own primitives each lane hit (mesh instances: the
 * triangle; its kernel file defines PYCLRAY_SUBPRIMITIVES) writes it to hit_sub; the winner's is
 * kept in best_sub, for the winners' normals, primitives and barycentrics. */
#ifdef PYCLRAY_SUBPRIMITIVES
#define PYCLRAY_SUB_BEGIN intv best_sub = SPLAT_INT(-1), hit_sub = SPLAT_INT(-1);
#define PYCLRAY_KEEP_SUB(nearer) best_sub = (nearer) ? hit_sub : best_sub;
#else
#define PYCLRAY_SUB_BEGIN
#define PYCLRAY_KEEP_SUB(nearer)
#endif
#ifdef PYCLRAY_TRACK_ID
#define PYCLRAY_CONSIDER(s, shape_id, kind, k)                                        \
    {                                                                                 \
        const intv closer = s < best, tied = s == best && s < MISS;                   \
        if (ANY(closer || tied)) {  /* the id is read only then */                    \
            const intv id = SPLAT_INT(shape_id), key = SPLAT_INT((k) * 16 + (kind));  \
            const intv nearer = closer || (tied && (id < best_id || (id == best_id && key < best_key))); \
            best = nearer ? s : best;                                                 \
            best_id = nearer ? id : best_id;                                          \
            best_key = nearer ? key : best_key;                                       \
            PYCLRAY_KEEP_SUB(nearer)                                                  \
        }                                                                             \
    }
#define PYCLRAY_BEST                                                                  \
    realv best = SPLAT(MISS);                                                         \
    intv best_id = SPLAT_INT(-1), best_key = SPLAT_INT(0);                            \
    PYCLRAY_SUB_BEGIN
#else
#define PYCLRAY_CONSIDER(s, shape_id, kind, k) best = v_min(s, best);
#define PYCLRAY_BEST realv best = SPLAT(MISS); PYCLRAY_SUB_BEGIN
#endif
#define PYCLRAY_NEAREST(Type, type)                                                   \
    for (int q = PYCLRAY_FIRST(type), end = PYCLRAY_END(type); q < end; ++q) {        \
        const int k = PYCLRAY_SHAPE_AT(type, q);                                      \
        PYCLRAY_SHAPE_OF(Type, type, k, shape)                                        \
        const realv s = PYCLRAY_HIT_##type(shape, &ray, best);                        \
        PYCLRAY_CONSIDER(s, PYCLRAY_ID_OF(type, k), KIND_##type, k)                   \
    }
#define PYCLRAY_FIND_NEAREST                                                          \
    PYCLRAY_BEST                                                                      \
    PYCLRAY_LINEAR(PYCLRAY_NEAREST)

/* a shape at position q of the BVH's leaves, tested against the whole packet: PYCLRAY_REF(q) = index *
 * 16 + kind, refs[q]; in a render of one bounded type (PYCLRAY_ONE_BOUNDED: its kind), whose array is
 * in leaf order, q itself (the scene holds no refs) */
#ifdef PYCLRAY_ONE_BOUNDED
#define PYCLRAY_REF(q) ((q) * 16 + PYCLRAY_ONE_BOUNDED)
#else
#define PYCLRAY_REF(q) refs[q]
#endif
#define PYCLRAY_VISIT_KIND(Type, type)                                                \
    if (kind == KIND_##type) {                                                        \
        PYCLRAY_SHAPE_OF(Type, type, k, shape)                                        \
        const realv s = PYCLRAY_HIT_##type(shape, &ray, best);                        \
        PYCLRAY_CONSIDER(s, PYCLRAY_ID_OF(type, k), KIND_##type, k)                   \
    }
#define PYCLRAY_VISIT(q)                                                              \
    {                                                                                 \
        const int ref = PYCLRAY_REF(q), kind = ref & 15, k = ref >> 4;                 \
        PYCLRAY_BOUNDED(PYCLRAY_VISIT_KIND)                                           \
    }

#ifdef PYCLRAY_WINNER_NORMAL
/* the winner's normal, turned into the world by the camera's axes (read per winner, where its normal
 * function uses them, rather than once per packet: a packet without a winner reads none) */
#define PYCLRAY_NORMAL_OF(type, shape)                                                \
    {                                                                                 \
        const Basis basis = camera_basis(camera);                                     \
        normal = v3_select(normal, PYCLRAY_NORMAL_##type(shape, &ray, &basis, best, mine), mine); \
    }
#define PYCLRAY_NORMAL_BEGIN vec3v normal = v3(SPLAT(0), SPLAT(0), SPLAT(0));
#else
#define PYCLRAY_NORMAL_OF(type, shape)
#define PYCLRAY_NORMAL_BEGIN
#endif
/* the winner's index within its shape (a batch's primitive; 0 for a single shape), -1 on a miss */
#ifdef PYCLRAY_AOV_PRIMITIVE
#define PYCLRAY_PRIMITIVE_OF(type, shape) primitive = mine ? PYCLRAY_PRIMITIVE_##type(shape, k, best, mine) : primitive;
#define PYCLRAY_PRIMITIVE_BEGIN intv primitive = SPLAT_INT(-1);
#else
#define PYCLRAY_PRIMITIVE_OF(type, shape)
#define PYCLRAY_PRIMITIVE_BEGIN
#endif

/* the winner's barycentric (u, v) (triangles; 0, 0 for the other types and on a miss) */
#ifdef PYCLRAY_AOV_BARYCENTRIC
#define PYCLRAY_BARYCENTRIC_OF(Type, type)                                            \
    if (kind == KIND_##type) {                                                        \
        realv u, v;                                                                   \
        PYCLRAY_SHAPE_OF(Type, type, k, bary_shape)                                   \
        PYCLRAY_BARYCENTRIC_##type(bary_shape, &ray, best, mine, &u, &v);             \
        bary_u = mine ? u : bary_u;                                                   \
        bary_v = mine ? v : bary_v;                                                   \
    }
#define PYCLRAY_BARYCENTRIC_BEGIN realv bary_u = SPLAT(0), bary_v = SPLAT(0);
#define PYCLRAY_BARYCENTRICS PYCLRAY_BARYCENTRIC_TYPES(PYCLRAY_BARYCENTRIC_OF)
#else
#define PYCLRAY_BARYCENTRIC_BEGIN
#define PYCLRAY_BARYCENTRICS
#endif

#ifdef PYCLRAY_WINNER_LOOP
/* what one winning shape gives the lanes it won: its normal (and with shading, its material), its
 * primitive index */
#define PYCLRAY_NORMAL(Type, type)                                                    \
    if (kind == KIND_##type) {                                                        \
        PYCLRAY_SHAPE_OF(Type, type, k, winner_shape)                                 \
        PYCLRAY_WINNER_OF(type, k, winner_shape)                                      \
        PYCLRAY_NORMAL_OF(type, winner_shape)                                         \
        PYCLRAY_MATERIAL_OF(PYCLRAY_ID_OF(type, k), mine, PYCLRAY_FLAT_##type)        \
        PYCLRAY_PRIMITIVE_OF(type, winner_shape)                                      \
    }
/* the winners' normals (and with shading, their materials) per lane, (0, 0, 0) on a miss */
#define PYCLRAY_WINNERS                                                               \
    PYCLRAY_NORMAL_BEGIN                                                              \
    PYCLRAY_PRIMITIVE_BEGIN                                                           \
    PYCLRAY_BARYCENTRIC_BEGIN                                                         \
    PYCLRAY_MATERIALS_BEGIN                                                           \
    {                                                                                 \
        /* each distinct winner once, the largest key first: one reduction finds the    \
         * next (a packet inside one shape's image: two reductions in all) */           \
        const intv key = best_key;                                                    \
        intv pending = key;                                                           \
        for (int winner = (int)lanes_max_int(pending); winner > 0;                    \
             winner = (int)lanes_max_int(pending)) {                                  \
            const int kind = winner & 15, k = winner >> 4;                             \
            const intv mine = key == SPLAT_INT(winner);                               \
            PYCLRAY_SHAPES(PYCLRAY_NORMAL)                                            \
            PYCLRAY_BARYCENTRICS                                                      \
            PYCLRAY_SMOOTH_NORMALS                                                    \
            pending = mine ? SPLAT_INT(0) : pending;                                  \
        }                                                                             \
    }
#else
#define PYCLRAY_WINNERS
#endif
