/* pyclray's kernels. The host puts before this file common.h, lanes.h, the generated struct header,
 * camera.h and the file of each shape type present, and selects what is compiled with -D options:
 *   PYCLRAY_FP64                        double precision
 *   PYCLRAY_LANES                       rays per work-item, in vector lanes (lanes.h)
 *   PYCLRAY_CAST                        the batch-ray kernel instead of the camera kernel (LANES 1)
 *   PYCLRAY_OCCLUDED                    (with PYCLRAY_CAST) the any-hit kernel instead
 *   PYCLRAY_BVH                         render: the bounded shapes through the BVH, not tile lists
 *   PYCLRAY_BOUNDED(X), PYCLRAY_UNBOUNDED(X)  the shape types present with and without bounds
 *   PYCLRAY_HAS_BOUNDED                 some bounded type is present (the BVH's buffers are passed)
 *   PYCLRAY_AOV_DEPTH/_NORMAL/_ID       which images are written (no buffer, no code for the others)
 *   PYCLRAY_AOV_ZDEPTH/_POSITION        render: depth along the optical axis, world hit points
 *   PYCLRAY_AOV_SHADED                  render: the shading model (kernels/shading.h, put before this file)
 *   PYCLRAY_SHADOWS                     render, with SHADED: shadow rays (without it none are cast)
 *   PYCLRAY_AOV_PRIMITIVE               render: the winner's index within its shape (a batch's primitive)
 *   PYCLRAY_SHAPES(X)                   X(Type, type) for each shape type present
 *   PYCLRAY_FRAMED, PYCLRAY_MODE_<type>  render: where each type's shapes are read (see below)
 *   PYCLRAY_ONE_BOUNDED                 render: the kind of the only bounded type present (no refs)
 * Geometry and camera come in buffers, so moving a shape or the camera never recompiles.
 *
 * A shape plugs in through two functions of its kernel file, both over a packet of rays:
 *   realv type_hit(shape, ray)             per lane, the nearest s > 0 along ray->dir, or MISS
 *   vec3v type_normal(shape, ray, camera)  the unit world normal, used in the lanes the shape won
 * called through PYCLRAY_HIT_<type>, PYCLRAY_NORMAL_<type>, PYCLRAY_PRIMITIVE_<type> and
 * PYCLRAY_BARYCENTRIC_<type> (pyclray/engine/programs.py writes them for each type; a type with
 * arrays shared by its entries, PYCLRAY_SHARED_ARGS_<type>, defines its own: mesh instances,
 * kernels/instance.cl, which also take the lanes' best so far and keep each lane's triangle).
 */

#if defined(PYCLRAY_AOV_NORMAL) || defined(PYCLRAY_AOV_ID) || defined(PYCLRAY_AOV_SHADED) || defined(PYCLRAY_AOV_PRIMITIVE) \
    || defined(PYCLRAY_AOV_BARYCENTRIC)
#define PYCLRAY_TRACK_ID 1   /* the winner matters, not only its distance */
#endif
#if defined(PYCLRAY_AOV_NORMAL) || defined(PYCLRAY_AOV_SHADED)
#define PYCLRAY_WINNER_NORMAL 1  /* the winner's normal is computed */
#endif
#if defined(PYCLRAY_WINNER_NORMAL) || defined(PYCLRAY_AOV_PRIMITIVE) || defined(PYCLRAY_AOV_BARYCENTRIC)
#define PYCLRAY_WINNER_LOOP 1  /* the packet's distinct winners are visited once each */
#endif
/* without shading (kernels/shading.h defines these), no material, light or shadow code at all */
#ifndef PYCLRAY_AOV_SHADED
#define PYCLRAY_SHADED_ARGS(P)
#define PYCLRAY_MATERIALS_BEGIN
#define PYCLRAY_MATERIAL_OF(id, mine, flat)
#define PYCLRAY_WRITE_SHADED(index, first, end)
#define PYCLRAY_SMOOTH_NORMALS
#endif

/* Each list of arguments is written once, as P(type, name) for each: PYCLRAY_DECLARE makes it a
 * list of parameters (", type name" each), PYCLRAY_PASS the arguments of a call (", name" each). */
#define PYCLRAY_DECLARE(type, name) , type name
#define PYCLRAY_PASS(type, name) , name

/* -- where a render reads its shapes -------------------------------------------------------------
 * A render's shapes in the eye's frame (origin the eye, the camera's axes: what the shape tests
 * take) come from one of three places, chosen per type (PYCLRAY_MODE_<type>, from the host: in a
 * framed scene, pyclray.engine.prepared's FRAMED_FROM, Shape.frames_in_render and Shape.indexed):
 * - FRAMED (devices with float64): each shape is framed where it is tested, from its float64 world
 *   entry, by its <type>_rebase (the per-view pass's function, compiled without contraction as
 *   there: the same bits) into a private copy; its id and its index within its shape come from
 *   their own arrays. The scene holds its world entries only: no copy per view, no pass over them
 *   when the camera moves (pyclray.engine.prepared).
 * - COPIED: the per-view pass's buffer of the entries in the frame (type##s), ids included (in a
 *   framed program, copied to private memory where tested: the shape functions take one space).
 * PYCLRAY_SHAPE_OF(Type, type, k, name) declares name, a pointer to shape k of its type in the frame;
 * PYCLRAY_ID_OF(type, k) and PYCLRAY_PRIMITIVE_AT(type, k) are its id and its index in its shape. */
#define PYCLRAY_ENTRIES_FRAMED(P, Type, type) \
    P(__global const Type##World*, type##_worlds) P(__global const int*, type##_ids) P(__global const int*, type##_primitives)
#define PYCLRAY_SHAPE_FRAMED(Type, type, k, name)                                     \
    Type name##_framed;                                                               \
    type##_rebase(&type##_worlds[k], &name##_framed, &view_frame);                    \
    const Type* const name = &name##_framed;
#define PYCLRAY_ID_FRAMED(type, k) type##_ids[k]
#define PYCLRAY_PRIMITIVE_FRAMED(type, k) type##_primitives[k]
#define PYCLRAY_ENTRIES_COPIED(P, Type, type) P(__global const Type*, type##s)
#ifdef PYCLRAY_FRAMED
#define PYCLRAY_SHAPE_COPIED(Type, type, k, name)                                     \
    const Type name##_copy = type##s[k];                                              \
    const Type* const name = &name##_copy;
#else
#define PYCLRAY_SHAPE_COPIED(Type, type, k, name) SHAPE_SPACE const Type* const name = &type##s[k];
#endif
#define PYCLRAY_ID_COPIED(type, k) type##s[k].id
#define PYCLRAY_PRIMITIVE_COPIED(type, k) type##s[k].primitive
/* - INDEXED (a framed scene's triangles, pyclray/engine/indexed.py): each triangle assembled from its face
 * and the per-view pass's vertices (<type>_assemble), its id from its own array, its index in its
 * shape from its face; the winner's world normal from the float64 vertices (<type>_world_normal) */
#define PYCLRAY_ENTRIES_INDEXED(P, Type, type)                                        \
    P(__global const int4*, type##_faces) P(__global const real4*, type##_vertices)   \
    P(__global const double4*, type##_world_vertices) P(__global const int*, type##_ids)
#define PYCLRAY_SHAPE_INDEXED(Type, type, k, name)                                    \
    Type name##_framed;                                                               \
    type##_assemble(type##_faces[k], type##_vertices, &name##_framed);                \
    const Type* const name = &name##_framed;
#define PYCLRAY_ID_INDEXED(type, k) type##_ids[k]
#define PYCLRAY_PRIMITIVE_INDEXED(type, k) type##_faces[k].w
/* what a winner needs besides its shape in the frame: an indexed triangle's world normal */
#define PYCLRAY_WINNER_FRAMED(type, k, name)
#define PYCLRAY_WINNER_COPIED(type, k, name)
#define PYCLRAY_WINNER_INDEXED(type, k, name) type##_world_normal(&name##_framed, type##_faces[k], type##_world_vertices);
#define PYCLRAY_WINNER_OF(type, k, name) PYCLRAY_CAT(PYCLRAY_WINNER_, PYCLRAY_MODE_##type)(type, k, name)
/* a smooth shape's shading normals (kernels/shading.h): its entry's, or an indexed triangle's vertices' */
#define PYCLRAY_SMOOTH_FRAMED(type, k) type##_smooth[k]
#define PYCLRAY_SMOOTH_COPIED(type, k) type##_smooth[k]
#define PYCLRAY_SMOOTH_INDEXED(type, k) type##_smooth_of(type##_faces[k], type##_smooth)
#define PYCLRAY_SMOOTH_AT(type, k) PYCLRAY_CAT(PYCLRAY_SMOOTH_, PYCLRAY_MODE_##type)(type, k)
#define PYCLRAY_ENTRIES(P, Type, type) PYCLRAY_CAT(PYCLRAY_ENTRIES_, PYCLRAY_MODE_##type)(P, Type, type)
#define PYCLRAY_SHAPE_OF(Type, type, k, name) PYCLRAY_CAT(PYCLRAY_SHAPE_, PYCLRAY_MODE_##type)(Type, type, k, name)
#define PYCLRAY_ID_OF(type, k) PYCLRAY_CAT(PYCLRAY_ID_, PYCLRAY_MODE_##type)(type, k)
#define PYCLRAY_PRIMITIVE_AT(type, k) PYCLRAY_CAT(PYCLRAY_PRIMITIVE_, PYCLRAY_MODE_##type)(type, k)
#ifdef PYCLRAY_FRAMED
/* the eye's frame, float64: its origin and axes */
#define PYCLRAY_FRAME_ARGS(P) P(const double4, frame_origin) P(const double4, frame_u) P(const double4, frame_v) P(const double4, frame_w)
#else
#define PYCLRAY_FRAME_ARGS(P)
#endif

#if defined(PYCLRAY_CAST) || defined(PYCLRAY_BVH)
/* one argument pair per shape type present: the packed array and its length; the bounded types'
 * shapes are reached through the BVH's leaves, the others (planes) are each tested by every ray.
 * cast adds the float64 world entries, on which it frames each shape it tests (kernels/cast.h). */
#ifdef PYCLRAY_CAST
#define PYCLRAY_SHAPE_ARGS(P, Type, type)                                             \
    P(__global const Type*, type##s) P(__global const Type##World*, type##_worlds)    \
    PYCLRAY_SHARED_ARGS_##type(P) P(const int, n_##type##s)
#else
#define PYCLRAY_SHAPE_ARGS(P, Type, type) \
    PYCLRAY_ENTRIES(P, Type, type) PYCLRAY_SHARED_ARGS_##type(P) P(const int, n_##type##s)
#endif
#define PYCLRAY_FIRST(type) 0
#define PYCLRAY_END(type) n_##type##s
#define PYCLRAY_SHAPE_AT(type, q) (q)
#define PYCLRAY_LINEAR(X) PYCLRAY_UNBOUNDED(X)
#ifdef PYCLRAY_HAS_BOUNDED
#ifdef PYCLRAY_CAST
/* the wide BVH, per leaf position its shape's anchor in world coordinates (xyz) and bounding
 * radius (w), the same as the leaf pre-test takes them (box_anchors: xyz the anchor from the
 * scene's anchor, w the radius, each rounded once to float: cast_may_pass), and the box of the
 * root's children (lo xyz, hi xyz; PYCLRAY_CAST_BOUNDED) */
#define PYCLRAY_BVH_ARGS(P) P(__global const WideNode*, nodes) P(__global const int*, refs) P(__global const double4*, anchors) \
    P(__global const float4*, box_anchors) P(const float8, root_box)
#elif defined(PYCLRAY_SHADOWS)
/* the wide BVH (camera packets traverse it: kernels/bvh.h's PYCLRAY_TRAVERSE_PACKET_WIDE), and the
 * binary one of the same boxes for shadow rays (kernels/shading.h) */
#define PYCLRAY_BVH_ARGS(P) P(__global const WideNode*, wide_nodes) P(__global const BvhNode*, nodes) P(__global const int*, refs)
#else
#define PYCLRAY_BVH_ARGS(P) P(__global const WideNode*, wide_nodes) P(__global const int*, refs)
#endif
#else
#define PYCLRAY_BVH_ARGS(P)
#endif
#else
/* per shape type: the packed array, and for each tile of the image the shapes that can be seen
 * in it (type##_tile_list[type##_tile_start[tile] .. type##_tile_start[tile + 1]], increasing;
 * the host's conservative screen bounds, pyclray/engine/culling.py): the others miss every ray there */
#ifdef PYCLRAY_SHADOWS
/* shadow rays go anywhere: they test every shape of the type (n_##type##s of them) */
#define PYCLRAY_SHAPE_ARGS(P, Type, type)                                             \
    PYCLRAY_ENTRIES(P, Type, type) PYCLRAY_SHARED_ARGS_##type(P)                      \
    P(__global const int*, type##_tile_start)                                         \
    P(__global const int*, type##_tile_list) P(const int, n_##type##s)
#else
#define PYCLRAY_SHAPE_ARGS(P, Type, type)                                             \
    PYCLRAY_ENTRIES(P, Type, type) PYCLRAY_SHARED_ARGS_##type(P)                      \
    P(__global const int*, type##_tile_start)                                         \
    P(__global const int*, type##_tile_list)
#endif
#define PYCLRAY_FIRST(type) type##_tile_start[tile]
#define PYCLRAY_END(type) type##_tile_start[tile + 1]
#define PYCLRAY_SHAPE_AT(type, q) type##_tile_list[q]
#define PYCLRAY_LINEAR(X) PYCLRAY_SHAPES(X)
#define PYCLRAY_BVH_ARGS(P)
#endif
#define PYCLRAY_KIND(Type, type) KIND_##type,
enum { KIND_NONE = 0, PYCLRAY_SHAPES(PYCLRAY_KIND) KIND_COUNT };

/* -- the nearest hit of each lane ----------------------------------------------------------------
 * Every shape is tested against the whole packet; a lane takes a shape's s where it is nearer, or
 * equally near with a lower id, or equally near with the same id and a lower key (below): an exact
 * tie has one winner whatever the order of the visit, also between the triangles of one mesh (the
 * BVH's order and the tile lists' give the same images).
 * A lane's winner is also kept as one key, 16 k + kind (k its index in its type's array; kinds are
 * 1 to 15, as in the BVH's refs), 0 on a miss: one select per shape instead of two. */
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
#if defined(PYCLRAY_ONE_BOUNDED) && !defined(PYCLRAY_CAST)
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

/* -- the images: distance along the unit ray, the winner's world normal, its id -----------------
 * MISS (+inf), (0, 0, 0) and -1 on a miss. Lane l of the packet is element index + l of the images,
 * written for the lanes first <= l < end inside the image (or window): a whole packet with vector
 * stores, the ends of a row lane by lane. */
#ifdef PYCLRAY_AOV_DEPTH
#define PYCLRAY_DEPTH_ARG(P) P(__global real*, depth)
#define PYCLRAY_WRITE_DEPTH(index, first, end) \
    write_reals(best < MISS ? best * v_sqrt(ray.a) : SPLAT(MISS), index, first, end, depth);
#else
#define PYCLRAY_DEPTH_ARG(P)
#define PYCLRAY_WRITE_DEPTH(index, first, end)
#endif

#ifdef PYCLRAY_WINNER_NORMAL
#define PYCLRAY_NORMAL_OF(type, shape) \
    normal = v3_select(normal, PYCLRAY_NORMAL_##type(shape, &ray, camera, best, mine), mine);
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

#ifdef PYCLRAY_AOV_NORMAL
#define PYCLRAY_NORMAL_ARG(P) P(__global real*, normal_out)
#define PYCLRAY_WRITE_NORMAL(index, first, end) write_vec3s(normal, index, first, end, normal_out);
#else
#define PYCLRAY_NORMAL_ARG(P)
#define PYCLRAY_WRITE_NORMAL(index, first, end)
#endif

#ifdef PYCLRAY_AOV_ID
#define PYCLRAY_ID_ARG(P) P(__global int*, id_out)
#define PYCLRAY_WRITE_ID(index, first, end) write_ints(TO_INT32V(best_id), index, first, end, id_out);
#else
#define PYCLRAY_ID_ARG(P)
#define PYCLRAY_WRITE_ID(index, first, end)
#endif

/* render only: depth along the optical axis, the frame's z axis (w): the ray's s times its z */
#ifdef PYCLRAY_AOV_ZDEPTH
#define PYCLRAY_ZDEPTH_ARG(P) P(__global real*, zdepth_out)
#define PYCLRAY_WRITE_ZDEPTH(index, first, end) \
    write_reals(best < MISS ? best * ray.dir.z : SPLAT(MISS), index, first, end, zdepth_out);
#else
#define PYCLRAY_ZDEPTH_ARG(P)
#define PYCLRAY_WRITE_ZDEPTH(index, first, end)
#endif

/* render only: the world hit point, eye + world_from_frame(s D). The eye comes as a float64 sum
 * eye_high + eye_low of two reals, added to the (small) offset from the eye high part first, so that
 * a scene far from the world's origin loses no more than the output's own rounding. */
#ifdef PYCLRAY_AOV_POSITION
#define PYCLRAY_POSITION_ARG(P) P(const real4, eye_high) P(const real4, eye_low) P(__global real*, position_out)
#define PYCLRAY_WRITE_POSITION(index, first, end)                                     \
    {                                                                                 \
        const intv hit = best < MISS;                                                 \
        const vec3v offset = world_from_frame(camera, v3_scale(ray.dir, hit ? best : SPLAT(0))); \
        const vec3v world = v3_add(v3_add(v3_splat(eye_high), offset), v3_splat(eye_low)); \
        const vec3v zero = v3(SPLAT(0), SPLAT(0), SPLAT(0));                          \
        write_vec3s(v3_select(zero, world, hit), index, first, end, position_out);    \
    }
#else
#define PYCLRAY_POSITION_ARG(P)
#define PYCLRAY_WRITE_POSITION(index, first, end)
#endif

/* render only: the winner's primitive index within its shape */
#ifdef PYCLRAY_AOV_PRIMITIVE
#define PYCLRAY_PRIMITIVE_ARG(P) P(__global int*, primitive_out)
#define PYCLRAY_WRITE_PRIMITIVE(index, first, end) write_ints(TO_INT32V(primitive), index, first, end, primitive_out);
#else
#define PYCLRAY_PRIMITIVE_ARG(P)
#define PYCLRAY_WRITE_PRIMITIVE(index, first, end)
#endif

/* render only: the winner's barycentric (u, v), interleaved per pixel */
#ifdef PYCLRAY_AOV_BARYCENTRIC
#define PYCLRAY_BARYCENTRIC_ARG(P) P(__global real*, barycentric_out)
/* lane l of the packet is pixel (l % PYCLRAY_PACKET_W, l / PYCLRAY_PACKET_W) of it (see PacketPlace) */
#define PYCLRAY_STORE_UV_LANE(l, c)                                                   \
    if (packet_lane_written(bary_place, l, bary_first, bary_end)) {                   \
        const long at = packet_lane_index(bary_place, l);                             \
        barycentric_out[2 * at] = bary_u.c;                                           \
        barycentric_out[2 * at + 1] = bary_v.c;                                       \
    }
#if LANES == 1
#define PYCLRAY_WRITE_BARYCENTRIC(place, first, end) \
    { barycentric_out[2 * (place).index] = bary_u; barycentric_out[2 * (place).index + 1] = bary_v; }
#else
#define PYCLRAY_WRITE_BARYCENTRIC(place, first, end)                                 \
    {                                                                                 \
        const PacketPlace bary_place = (place);                                       \
        const int bary_first = (first), bary_end = (end);                             \
        PYCLRAY_EACH_LANE(PYCLRAY_STORE_UV_LANE)                                      \
    }
#endif
#else
#define PYCLRAY_BARYCENTRIC_ARG(P)
#define PYCLRAY_WRITE_BARYCENTRIC(index, first, end)
#endif

#define PYCLRAY_OUTPUT_ARGS(P) PYCLRAY_DEPTH_ARG(P) PYCLRAY_NORMAL_ARG(P) PYCLRAY_ID_ARG(P)
#define PYCLRAY_RENDER_OUTPUT_ARGS(P) \
    PYCLRAY_OUTPUT_ARGS(P) PYCLRAY_ZDEPTH_ARG(P) PYCLRAY_POSITION_ARG(P) PYCLRAY_SHADED_ARGS(P) PYCLRAY_PRIMITIVE_ARG(P) \
    PYCLRAY_BARYCENTRIC_ARG(P)
/* the shapes' arguments as parameters and as the arguments of a call */
#define PYCLRAY_SHAPE_PARAMETERS(Type, type) PYCLRAY_SHAPE_ARGS(PYCLRAY_DECLARE, Type, type)
#define PYCLRAY_SHAPE_PASSED(Type, type) PYCLRAY_SHAPE_ARGS(PYCLRAY_PASS, Type, type)
#define PYCLRAY_WRITE(index, first, end) \
    PYCLRAY_WINNERS \
    PYCLRAY_WRITE_DEPTH(index, first, end) PYCLRAY_WRITE_NORMAL(index, first, end) PYCLRAY_WRITE_ID(index, first, end)
#define PYCLRAY_RENDER_WRITE(index, first, end) \
    PYCLRAY_WRITE(index, first, end) PYCLRAY_WRITE_ZDEPTH(index, first, end) \
    PYCLRAY_WRITE_POSITION(index, first, end) PYCLRAY_WRITE_SHADED(index, first, end) \
    PYCLRAY_WRITE_PRIMITIVE(index, first, end) PYCLRAY_WRITE_BARYCENTRIC(index, first, end)

#if LANES == 1
#define PYCLRAY_INT32V int
#else
#define PYCLRAY_INT32V PYCLRAY_CAT(int, LANES)
#endif

/* -- a packet's pixels in the images ------------------------------------------------------------
 * A render's packet covers PYCLRAY_PACKET_W x PYCLRAY_PACKET_H pixels (pyclray/engine/programs.py:
 * packet_shape): lane l is column l % W, row l / W of it, element index + (l / W) stride + l % W of
 * the images. A packet cut by the border of the window writes its columns first <= c < end of its
 * rows row_first <= r < row_end only; a whole row of W lanes with one vector store. */
#ifndef PYCLRAY_PACKET_W
#define PYCLRAY_PACKET_W LANES
#define PYCLRAY_PACKET_H 1
#endif
typedef struct {
    long index;   /* the element of the packet's lane 0 (before the window's first row: < 0 there) */
    long stride;  /* elements from one row of the images to the next */
    int row_first, row_end;
} PacketPlace;

inline bool packet_lane_written(const PacketPlace place, const int l, const int first, const int end)
{
    const int column = l % PYCLRAY_PACKET_W, row = l / PYCLRAY_PACKET_W;
    return first <= column && column < end && place.row_first <= row && row < place.row_end;
}
inline long packet_lane_index(const PacketPlace place, const int l)
{
    return place.index + (l / PYCLRAY_PACKET_W) * place.stride + l % PYCLRAY_PACKET_W;
}

/* one row of a packet: W lanes (the whole packet where it is one row) */
#if PYCLRAY_PACKET_W == 1
typedef real realw;
typedef int int32w;
#else
typedef PYCLRAY_CAT(PYCLRAY_REAL_NAME, PYCLRAY_PACKET_W) realw;
typedef PYCLRAY_CAT(int, PYCLRAY_PACKET_W) int32w;
#endif

/* W lanes stored at p (the first lane's element): one move instruction through a vector type of the
 * element's alignment on PoCL's CPU device (see v_sqrt in kernels/lanes.h), else vstoren */
#if PYCLRAY_PACKET_W == 1
#define STORE_ROW_REALS(v, p) (*(p) = (v))
#define STORE_ROW_INT32S(v, p) (*(p) = (v))
#elif defined(PYCLRAY_INLINE_BUILTINS)
typedef realw realw_unaligned __attribute__((aligned(sizeof(real))));
typedef int32w int32w_unaligned __attribute__((aligned(sizeof(int))));
#define STORE_ROW_REALS(v, p) (*(__global realw_unaligned*)(p) = (v))
#define STORE_ROW_INT32S(v, p) (*(__global int32w_unaligned*)(p) = (v))
#else
#define STORE_ROW_REALS(v, p) PYCLRAY_CAT(vstore, PYCLRAY_PACKET_W)((v), 0, (p))
#define STORE_ROW_INT32S(v, p) PYCLRAY_CAT(vstore, PYCLRAY_PACKET_W)((v), 0, (p))
#endif

/* interleaved x, y, z of a whole row of W lanes at p */
inline void store_row_vec3s(const realw x, const realw y, const realw z, __global real* p)
{
#if PYCLRAY_PACKET_W == 8
    STORE_ROW_REALS((realw)(x.s0, y.s0, z.s0, x.s1, y.s1, z.s1, x.s2, y.s2), p);
    STORE_ROW_REALS((realw)(z.s2, x.s3, y.s3, z.s3, x.s4, y.s4, z.s4, x.s5), p + 8);
    STORE_ROW_REALS((realw)(y.s5, z.s5, x.s6, y.s6, z.s6, x.s7, y.s7, z.s7), p + 16);
#elif PYCLRAY_PACKET_W == 4
    STORE_ROW_REALS((realw)(x.s0, y.s0, z.s0, x.s1), p);
    STORE_ROW_REALS((realw)(y.s1, z.s1, x.s2, y.s2), p + 4);
    STORE_ROW_REALS((realw)(z.s2, x.s3, y.s3, z.s3), p + 8);
#elif PYCLRAY_PACKET_W == 2
    STORE_ROW_REALS((realw)(x.s0, y.s0), p);
    STORE_ROW_REALS((realw)(z.s0, x.s1), p + 2);
    STORE_ROW_REALS((realw)(y.s1, z.s1), p + 4);
#else
    p[0] = x;
    p[1] = y;
    p[2] = z;
#endif
}

/* A whole packet (every lane in the window) with a vector store per row; a packet cut by the border
 * of the window lane by lane. Row 0 of the packet is its lanes' low half, row 1 the high half. */
#if PYCLRAY_PACKET_H == 1
#define PYCLRAY_PACKET_ROWS(STORE, v, place) STORE(v, (place).index)
#else
#define PYCLRAY_PACKET_ROWS(STORE, v, place) STORE((v).lo, (place).index) STORE((v).hi, (place).index + (place).stride)
#endif
#define PYCLRAY_WHOLE_PACKET(place, first, end) \
    ((first) == 0 && (end) == PYCLRAY_PACKET_W && (place).row_first == 0 && (place).row_end == PYCLRAY_PACKET_H)
#define PYCLRAY_STORE_LANE(l, c) \
    if (packet_lane_written(place, l, first, end)) out[packet_lane_index(place, l)] = v.c;
#define PYCLRAY_STORE_VEC3_LANE(l, c)                                                 \
    if (packet_lane_written(place, l, first, end)) {                                  \
        const long at = 3 * packet_lane_index(place, l);                              \
        out[at] = v.x.c;                                                              \
        out[at + 1] = v.y.c;                                                          \
        out[at + 2] = v.z.c;                                                          \
    }

inline void write_reals(const realv v, const PacketPlace place, const int first, const int end, __global real* out)
{
#if LANES == 1
    out[place.index] = v;
#else
    if (PYCLRAY_WHOLE_PACKET(place, first, end)) {
#define PYCLRAY_ROW(row, at) STORE_ROW_REALS(row, out + (at));
        PYCLRAY_PACKET_ROWS(PYCLRAY_ROW, v, place)
#undef PYCLRAY_ROW
    } else {
        PYCLRAY_EACH_LANE(PYCLRAY_STORE_LANE)
    }
#endif
}

inline void write_ints(const PYCLRAY_INT32V v, const PacketPlace place, const int first, const int end, __global int* out)
{
#if LANES == 1
    out[place.index] = v;
#else
    if (PYCLRAY_WHOLE_PACKET(place, first, end)) {
#define PYCLRAY_ROW(row, at) STORE_ROW_INT32S(row, out + (at));
        PYCLRAY_PACKET_ROWS(PYCLRAY_ROW, v, place)
#undef PYCLRAY_ROW
    } else {
        PYCLRAY_EACH_LANE(PYCLRAY_STORE_LANE)
    }
#endif
}

/* interleaved x, y, z per element */
inline void write_vec3s(const vec3v v, const PacketPlace place, const int first, const int end, __global real* out)
{
#if LANES == 1
    out[3 * place.index] = v.x;
    out[3 * place.index + 1] = v.y;
    out[3 * place.index + 2] = v.z;
#else
    if (PYCLRAY_WHOLE_PACKET(place, first, end)) {
#if PYCLRAY_PACKET_H == 1
        store_row_vec3s(v.x, v.y, v.z, out + 3 * place.index);
#else
        store_row_vec3s(v.x.lo, v.y.lo, v.z.lo, out + 3 * place.index);
        store_row_vec3s(v.x.hi, v.y.hi, v.z.hi, out + 3 * (place.index + place.stride));
#endif
    } else {
        PYCLRAY_EACH_LANE(PYCLRAY_STORE_VEC3_LANE)
    }
#endif
}

/* On PoCL's CPU device every function above is always inlined (pyclray/engine/programs.py), the kernels themselves not. */
#ifdef PYCLRAY_INLINE_BUILTINS
#define PYCLRAY_KERNELS_BEGIN _Pragma("clang attribute pop")
#else
#define PYCLRAY_KERNELS_BEGIN
#endif

/* Each kernel calls one function per work-item (a packet, or cast's ray). On PoCL's CPU device that
 * function is not inlined into the kernel: PoCL copies a kernel's body into each of the three
 * functions it makes of it (the work-item loops and two launchers), and the compile time of a first
 * render grows with that code (measured: 0.26 s -> 0.12 s for tp02's default images); a call per
 * work-item costs nothing measurable. Elsewhere it is inlined as usual. */
#ifdef PYCLRAY_INLINE_BUILTINS
#define PYCLRAY_WORK_ITEM_FUNCTION __attribute__((noinline))
#else
#define PYCLRAY_WORK_ITEM_FUNCTION inline
#endif

#ifndef PYCLRAY_CAST

/* The camera rays of a packet: its PYCLRAY_PACKET_W x PYCLRAY_PACKET_H pixels from column i0 and
 * row j0 on (lane l: column i0 + l % W, row j0 + l / W), in the camera frame. */
#if PYCLRAY_PACKET_H == 1
#define PYCLRAY_LANE_COLUMN LANE_INDEX
#define PYCLRAY_LANE_ROW SPLAT_INT(0)
#else
#define PYCLRAY_LANE_COLUMN (LANE_INDEX % SPLAT_INT(PYCLRAY_PACKET_W))
#define PYCLRAY_LANE_ROW (LANE_INDEX / SPLAT_INT(PYCLRAY_PACKET_W))
#endif
inline RayPacket camera_rays(__global const Camera* camera, const int i0, const int j0)
{
    const int width = camera->width, height = camera->height;
    const intv i = SPLAT_INT(i0) + PYCLRAY_LANE_COLUMN, j = SPLAT_INT(j0) + PYCLRAY_LANE_ROW;
    /* pixel centres on the image plane at distance 1 (pyclray/model/camera.py): the integer part of
     * the numerator 2 cx - 1 - 2 i is exact and its fraction (0 for a centred camera, whose numerator
     * is width - 1 - 2 i as ever) adds one rounding, so each coordinate carries three roundings and
     * keeps its relative precision even for a tiny fov or next to the principal point */
    const realv sx = SPLAT(camera->tan_x) * ((TO_REALV(SPLAT_INT(camera->centre_x - 1) - 2 * i) + SPLAT(camera->centre_x_low))
                                            / SPLAT((real)width));
    const realv sy = SPLAT(camera->tan_y) * ((TO_REALV(SPLAT_INT(camera->centre_y - 1) - 2 * j) + SPLAT(camera->centre_y_low))
                                            / SPLAT((real)height));
    /* normalized in the camera frame, where each component is divided on its own: the tiny
     * lateral components of a narrow field of view keep their relative precision */
    const realv length = v_sqrt((sx * sx + sy * sy) + SPLAT(1));
    RayPacket ray;
    ray.origin = v3(SPLAT(0), SPLAT(0), SPLAT(0));
    ray.dir = v3(sx / length, sy / length, SPLAT(1) / length);
    ray.a = v3_dot(ray.dir, ray.dir);
#ifdef PYCLRAY_SHADOWS
    ray.from_eye = 1;
#endif
    return ray;
}

#if defined(PYCLRAY_BVH) && defined(PYCLRAY_ONE_BOUNDED) && defined(PYCLRAY_INLINE_BUILTINS)
/* One bounded type (PYCLRAY_ONE_BOUNDED): leaf position q is entry q of its arrays, so a leaf's
 * entries are asked for at once where the traversal first meets the leaf (kernels/bvh.h): the
 * entries its tests read, in the frame (COPIED), in the world (FRAMED), or its faces (INDEXED: the
 * vertices they name follow when read). PoCL's CPU device only: elsewhere OpenCL's prefetch is a
 * call, or nothing. */
#define PYCLRAY_PREFETCH_RANGE(p, bytes) \
    for (int byte = 0; byte < (bytes); byte += 64) __builtin_prefetch((__global const char*)(p) + byte);
#define PYCLRAY_PREFETCH_COPIED(Type, type) PYCLRAY_PREFETCH_RANGE(&type##s[leaf_first], leaf_count * (int)sizeof(Type))
#define PYCLRAY_PREFETCH_FRAMED(Type, type) \
    PYCLRAY_PREFETCH_RANGE(&type##_worlds[leaf_first], leaf_count * (int)sizeof(Type##World))
#define PYCLRAY_PREFETCH_INDEXED(Type, type) PYCLRAY_PREFETCH_RANGE(&type##_faces[leaf_first], leaf_count * (int)sizeof(int4))
#define PYCLRAY_PACKET_PREFETCH_TYPE(Type, type) PYCLRAY_CAT(PYCLRAY_PREFETCH_, PYCLRAY_MODE_##type)(Type, type)
#undef PYCLRAY_PACKET_LEAF_PREFETCH
#define PYCLRAY_PACKET_LEAF_PREFETCH(first, count)                                    \
    {                                                                                 \
        const int leaf_first = (first), leaf_count = (count);                         \
        PYCLRAY_BOUNDED(PYCLRAY_PACKET_PREFETCH_TYPE)                                 \
    }
#endif

/* One work-item per packet of PYCLRAY_PACKET_W x PYCLRAY_PACKET_H pixels: packet column
 * get_global_id(0) and row get_global_id(1), counted from the packet of the window's first pixel (a
 * render of a window of the image starts at row row0 and column col0, and writes its own
 * cols x rows images; packets start at multiples of their size in the image, so that a window's
 * pixels are the whole image's, and none straddles two tiles). Tiles are 1 << tile_shift pixels
 * square, tiles_x per image row (and the work-groups where the device allows). */
/* the render kernel's arguments after the camera; SHAPE: PYCLRAY_SHAPE_PARAMETERS or _PASSED */
#define PYCLRAY_RENDER_ARGS(P, SHAPE)                                                 \
    P(const int, col0) P(const int, row0) P(const int, cols) P(const int, rows)       \
    P(const int, tile_shift) P(const int, tiles_x)                                    \
    PYCLRAY_FRAME_ARGS(P) PYCLRAY_BVH_ARGS(P) PYCLRAY_SHAPES(SHAPE) PYCLRAY_RENDER_OUTPUT_ARGS(P)

PYCLRAY_KERNELS_BEGIN
PYCLRAY_WORK_ITEM_FUNCTION void render_packet(const int packet, const int r, __global const Camera* camera
                                              PYCLRAY_RENDER_ARGS(PYCLRAY_DECLARE, PYCLRAY_SHAPE_PARAMETERS))
{
    const int i0 = (col0 / PYCLRAY_PACKET_W + packet) * PYCLRAY_PACKET_W;
    const int j0 = (row0 / PYCLRAY_PACKET_H + r) * PYCLRAY_PACKET_H;
    if (i0 >= col0 + cols || j0 >= row0 + rows) return;
    const int tile = (j0 >> tile_shift) * tiles_x + (i0 >> tile_shift);  /* shifts: no division per packet */
    /* the columns and rows in the window (no min or max: PoCL's would be calls, see v_sqrt); lane 0
     * is element (j0 - row0) cols + (i0 - col0) of the window's images */
    const int from = col0 > i0 ? col0 - i0 : 0;
    const int to = col0 + cols - i0 < PYCLRAY_PACKET_W ? col0 + cols - i0 : PYCLRAY_PACKET_W;
    PacketPlace place;
    place.index = (long)(j0 - row0) * (long)cols + (long)(i0 - col0);
    place.stride = cols;
    place.row_first = row0 > j0 ? row0 - j0 : 0;
    place.row_end = row0 + rows - j0 < PYCLRAY_PACKET_H ? row0 + rows - j0 : PYCLRAY_PACKET_H;
    const RayPacket ray = camera_rays(camera, i0, j0);
#ifdef PYCLRAY_FRAMED
    const Frame view_frame = {frame_origin.xyz, frame_u.xyz, frame_v.xyz, frame_w.xyz};  /* the eye's */
#endif

    PYCLRAY_FIND_NEAREST
#if defined(PYCLRAY_BVH) && defined(PYCLRAY_HAS_BOUNDED)
    /* the bounded shapes through the BVH, whose boxes are in world axes around the scene's anchor */
    const BoxPacket box = box_packet(world_from_frame(camera, ray.dir), camera->box_origin);
    PYCLRAY_TRAVERSE_PACKET_WIDE(wide_nodes, box, best, PYCLRAY_VISIT)
#endif
    PYCLRAY_RENDER_WRITE(place, from, to)
}

/* The work-groups in a scattered order: group g of n works on the block of packets at g s mod n,
 * s the first integer from 5n/8 up that is prime to n (a bijection; consecutive groups land far
 * apart). Why: PoCL's CPU device hands its threads runs of consecutive work-groups (64 at a time
 * for a 256x256 image's 256 groups, a quarter of the image); in image order a thread that drew the
 * sky idled while the other traced the ground, and a render kept 1.5 of the 2 cores busy.
 * Scattered, each run samples the whole image: 1.8 cores, a same-camera render of 100,000 spheres
 * at 256x256 15% faster, a view of render_views 12% (medians of alternating runs against image
 * order, quiet machine). Every packet is still traced once, by the same code. Not for cast and
 * occluded: their batches come in ray order, and a thread's consecutive groups reuse what the ones
 * before brought into its caches (scattered, 100,000 view rays over 16,384 spheres took 11.8 ms
 * instead of 8.7, occluded 3.2-4.2 instead of 2.3). Nor for images of SCATTERED_BELOW groups or
 * more (a 512x512 image has 1,024): their 16 runs or more balance the threads well enough, and
 * scattering only costs the caches what neighbouring tiles share (a 998,000-triangle mesh at 512x512: 35-37 ms
 * scattered against 33-34 ms in order). */
#define SCATTERED_BELOW 1024
inline int scattered_group(const int g, const int n)
{
    int s = n - n / 4 - n / 8;
    for (;; ++s) {
        int a = s, b = n;  /* Euclid's gcd(s, n) */
        while (b != 0) {
            const int t = a % b;
            a = b;
            b = t;
        }
        if (a == 1) break;
    }
    return (int)(((long)g * (long)s) % (long)n);
}

__kernel void render(__global const Camera* camera PYCLRAY_RENDER_ARGS(PYCLRAY_DECLARE, PYCLRAY_SHAPE_PARAMETERS))
{
    const int nx = get_num_groups(0);
    const int n = nx * get_num_groups(1), in_order = get_group_id(1) * nx + get_group_id(0);
    const int g = n < SCATTERED_BELOW ? scattered_group(in_order, n) : in_order;
    render_packet((g % nx) * get_local_size(0) + get_local_id(0), (g / nx) * get_local_size(1) + get_local_id(1),
                  camera PYCLRAY_RENDER_ARGS(PYCLRAY_PASS, PYCLRAY_SHAPE_PASSED));
}

#else

#if LANES != 1
#error "cast traces one ray at a time (LANES 1)"
#endif

/* One ray at a time (CAST_GROUP of them per work-item, below), in world coordinates: origin
 * (float64), unit direction (float64), and the largest distance that counts (float64,
 * limits[r * limit_stride]). Where ordered is 1 the host has found a coherent order of the rays
 * (neighbouring rays then walk the same nodes): place i of the batch traces ray r = order[i], the
 * i-th of that order, read and written at its own place r (the rays stay where the caller put
 * them: gathering them on the host cost more than the kernel's scattered reads); else ray i.
 *
 * Exact and independent of the other rays: each shape is tested from a point of the ray just
 * before it, as a camera there would test it. For a bounded shape of anchor A and bounding radius
 * R, the ray's origin O moves along the unit direction D to O' = O + s0 D, s0 = max(0, (A - O).D - R),
 * which no point of the shape precedes (float64); the shape is then framed on O' from its float64
 * world entry (kernels/cast.h: its coordinates relative to O' rounded once, and the terms O' decides,
 * such as a sphere's c = |C - O'|^2 - r^2, in float64) and tested from the frame's origin. A ray
 * from 1e8 away thus meets a sphere of radius 1e-4 with errors relative to the sphere's size, and a
 * ray starting on a surface, or 1e-9 off it, knows which side it starts on; its distance is s0 + s
 * (s: the shape's own, from O'). Unbounded shapes (planes) are framed on the ray's own origin. */
#define PYCLRAY_CAST_FRAMED(Type, type, k, from)                                    \
    Type framed = type##s[k];                                                       \
    {                                                                               \
        const Frame frame = {(from)};                                               \
        type##_rebase(&type##_worlds[k], &framed, &frame);                          \
    }
/* A type's entries are tested one by one (PYCLRAY_CAST_MODE_<type> ENTRY), or in blocks of a leaf's
 * entries that its kernel file tests at once (BLOCKS: a mesh's triangles, kernels/mesh.cl); the
 * mode also says where the winner's id and normal come from, and what a leaf's prefetch asks for */
#define PYCLRAY_CAST_MODE(what, type) PYCLRAY_CAT(what, PYCLRAY_CAST_MODE_##type)
#define PYCLRAY_CAST_VISIT_KIND(Type, type)                                         \
    if (kind == KIND_##type) { PYCLRAY_CAST_MODE(PYCLRAY_CAST_TEST_, type)(Type, type) }
#define PYCLRAY_CAST_TEST_ENTRY(Type, type)                                         \
    {                                                                               \
        PYCLRAY_CAST_FRAMED(Type, type, k, moved.world)                             \
        const real s = PYCLRAY_HIT_##type(&framed, &moved, MISS);                   \
        const double t = s < MISS ? s0 + (double)s * length : INFINITY;             \
        PYCLRAY_CAST_TAKE(t, type##s[k].id, KIND_##type, k, q)                      \
        PYCLRAY_CAST_PREFETCH_WINNER(Type, type, k)                                 \
    }
/* The moved ray of the last anchor met is kept (PYCLRAY_CAST_MOVED): the triangles of a mesh share
 * their mesh's anchor, so that a ray moves once per mesh rather than once per triangle (the same
 * function of the same anchor: the same bits). An anchor of NaNs is never equal: the first is moved. */
#define PYCLRAY_CAST_MOVED                                                          \
    double4 moved_anchor = (double4)(NAN);                                          \
    double s0 = 0;                                                                  \
    bool near = false;                                                              \
    RayPacket moved = ray;
#define PYCLRAY_CAST_VISIT(q)                                                       \
    {                                                                               \
        const int ref = refs[q], kind = ref & 15, k = ref >> 4;                      \
        const double4 anchor = anchors[q];                                          \
        if (!(anchor.x == moved_anchor.x && anchor.y == moved_anchor.y && anchor.z == moved_anchor.z \
              && anchor.w == moved_anchor.w)) {                                     \
            moved = moved_ray(&ray, anchor, &s0, &near);                            \
            moved_anchor = anchor;                                                  \
        }                                                                           \
        if (near && s0 <= PYCLRAY_CAST_REACH) {                                     \
            PYCLRAY_BOUNDED(PYCLRAY_CAST_VISIT_KIND)                                \
            PYCLRAY_CAST_LIMIT                                                      \
        }                                                                           \
    }
/* a child wide node's boxes, or a leaf's anchors and its shapes' world entries, asked for as the
 * child is pushed (kernels/bvh.h): the shapes of a type lie in leaf order in their arrays, so a
 * leaf's entries of its first shape's type follow that shape's */
#define PYCLRAY_CAST_PREFETCH_KIND(Type, type)                                      \
    if (leaf_kind == KIND_##type) { PYCLRAY_CAST_MODE(PYCLRAY_CAST_PREFETCH_, type)(Type, type) }
#define PYCLRAY_CAST_PREFETCH_ENTRY(Type, type) CAST_PREFETCH(&type##_worlds[leaf_k], count * sizeof(Type##World))
#define PYCLRAY_CHILD_PREFETCH(code)                                                \
    if ((code) >= 0) {                                                              \
        CAST_PREFETCH(&nodes[code], sizeof(WideNode))                               \
    } else {                                                                        \
        const int first = (~(code)) >> 3, count = (~(code)) & 7;                    \
        CAST_PREFETCH(&box_anchors[first], count * sizeof(float4))                  \
        CAST_PREFETCH(&anchors[first], count * sizeof(double4))                     \
        const int leaf_kind = refs[first] & 15, leaf_k = refs[first] >> 4;          \
        PYCLRAY_BOUNDED(PYCLRAY_CAST_PREFETCH_KIND)                                 \
    }
#define PYCLRAY_CAST_LINEAR(Type, type)                                             \
    for (int q = 0; q < n_##type##s; ++q) {                                         \
        PYCLRAY_CAST_FRAMED(Type, type, q, ray.world)                               \
        const real s = PYCLRAY_HIT_##type(&framed, &ray, MISS);                     \
        const double t = s < MISS ? (double)s * length : INFINITY;                  \
        PYCLRAY_CAST_TAKE(t, type##s[q].id, KIND_##type, q, -1)                     \
    }

/* The packed entry of a new nearest hit, asked for from memory: the traversal reads only the
 * world entries, and the id (and the normal's frame) read from it at the end would otherwise miss
 * the cache (that read drew 9% of cast's samples on a mesh of 75k triangles, 5% with this) */
#ifdef PYCLRAY_TRACK_ID
#define PYCLRAY_CAST_PREFETCH_WINNER(Type, type, k)                                 \
    if (best_kind == KIND_##type && best_k == (k)) { CAST_PREFETCH(&type##s[k], sizeof(Type)) }
#else
#define PYCLRAY_CAST_PREFETCH_WINNER(Type, type, k)
#endif

/* Each work-item traces CAST_GROUP rays (consecutive places of the order), one after the other
 * (interleaved where leaves are blocks: cast_group, below). Their setups come first, together: a
 * ray's unit direction and the length of its rounding are a chain of dependent divisions and
 * square roots, on which, one ray at a time, about a quarter of the perf
 * samples of occluded on bench/secondary.py's view rays sat (most of those rays end at their first
 * test, the ground); a group's four-ray vectors take one instruction per division or root (below).
 * The group's first rows are asked for from memory as it starts, and the next group's rows too
 * (origin, direction and limit: each may straddle two cache lines): the rays are read where the
 * caller put them, scattered in the coherent order, and PoCL runs a work-group's items one after
 * the other, which would otherwise wait for each ray's first read (a seventh of cast's time on a
 * mesh). Each ray's own computations are unchanged: no bit of any result depends on the grouping. */
#define CAST_GROUP 8
#define CAST_PREFETCH_ROW(p) { CAST_PREFETCH(p, 1) CAST_PREFETCH((__global const char*)(p) + 23, 1) }
#define PYCLRAY_CAST_PREFETCH_GROUP(start)                                          \
    for (int ahead_i = (start); ahead_i < (start) + CAST_GROUP && ahead_i < n_rays; ++ahead_i) { \
        const size_t ahead = (size_t)(ordered ? order[ahead_i] : ahead_i);          \
        CAST_PREFETCH_ROW(&origins[3 * ahead * (size_t)origin_stride])              \
        CAST_PREFETCH_ROW(&directions[3 * ahead])                                   \
        CAST_PREFETCH(&limits[ahead * (size_t)limit_stride], 1)                     \
    }

/* The ray from O + s0 D, s0 = max(0, (A - O).D - R - m): see above. m = 2^-50
 * |A - O|_1 bounds the float64 rounding of (A - O).D, so that the new origin is never past the
 * shape's near side, however far O is (at 1e40 the rounding of (A - O).D alone exceeds a unit R).
 * near: whether the ray passes within R of A (|G x D| <= R, G = A - O - s0 D, in float64 without
 * cancellation); where it does not, it misses the shape by more than 2^-12 R, far more than the
 * shape's test, which rounds quantities of the size of G, could err by: the test is skipped. */
inline RayPacket moved_ray(const RayPacket* ray, const double4 anchor, double* s0, bool* near)
{
    const double3 O = ray->world, D = ray->dir_exact;
    const double3 F = anchor.xyz - O;
    const double size = (CAST_FABS(F.x) + CAST_FABS(F.y)) + CAST_FABS(F.z);
    const double along = (F.x * D.x + F.y * D.y) + F.z * D.z - anchor.w - 0x1p-50 * size;
    *s0 = along > 0 ? along : 0;
    const double3 G = F - *s0 * D;
    const double3 GxD = (double3)(G.y * D.z - G.z * D.y, G.z * D.x - G.x * D.z, G.x * D.y - G.y * D.x);
    *near = (GxD.x * GxD.x + GxD.y * GxD.y) + GxD.z * GxD.z <= anchor.w * anchor.w;
    RayPacket moved = *ray;
    moved.world = O + *s0 * D;  /* where the shape is framed */
    return moved;
}

/* Whether the ray (o, d: its origin from the scene's anchor and its unit direction, rounded to
 * float, the box tests' ray) may pass within R of a shape's anchor A (anchor: A - S and R, each
 * rounded once to float on the host, as a convert_float would: the pre-test reads 16 bytes per
 * shape, not the 32 of the float64 anchor, which only the shapes it keeps read). With g = A - o,
 * the ray's distance from A is |g x d|; rounding A - S (S the scene's anchor), o, g and d to float
 * and the cross product's products and sums err by a few eps32 (|A - S|_1 + |o|_1 + |g|_1): the
 * test widens R by 2^-16 (1 + that sum), hundreds of times more, and drops only a ray farther than
 * that from A, whose moved_ray would find it not near. Only where the box tests run (|o| < 2^100,
 * the scene within 2^100 of S): g is finite there; a square that overflows to inf is a distance
 * beyond 2^64, dropped only where the widened R is finite, below it. */
inline bool cast_may_pass(const float4 anchor, const float3 o, const float3 d)
{
    const float3 a = anchor.xyz;  /* the anchor from the scene's anchor, rounded once (host: cast_inputs) */
    const float3 g = a - o;
    const float3 gxd = (float3)(g.y * d.z - g.z * d.y, g.z * d.x - g.x * d.z, g.x * d.y - g.y * d.x);
    const float3 size = (a < (float3)(0.0f) ? -a : a) + (o < (float3)(0.0f) ? -o : o) + (g < (float3)(0.0f) ? -g : g);
    const float reach = anchor.w * (1.0f + 0x1p-16f) + 0x1p-16f * ((size.x + size.y) + size.z);
    return (gxd.x * gxd.x + gxd.y * gxd.y) + gxd.z * gxd.z <= reach * reach;
}

/* The shapes of a leaf (positions first .. first + count - 1) the ray may meet, as a mask (bit i:
 * position first + i; kernels/bvh.h's LEAF_MASK), each by cast_may_pass: on the view rays of
 * bench/secondary.py into 16,384 spheres, a ray that enters the field looks at 14 shapes in 2.6
 * leaves and tests 3.5 of them; a branch per shape on its own pre-test went either way at random.
 * A leaf of one ref (a mesh's block of triangles, kernels/mesh.cl, whose anchor is the whole mesh's)
 * is visited as it is: moved_ray's own test of that anchor is all a pre-test would do (on a mesh's
 * blocks it cost 7% of cast's time). */
inline int cast_leaf_mask(__global const float4* box_anchors, const int first, const int count, const float3 o,
                          const float3 d)
{
    if (count == 1) return 1;
    int mask = 0;
    for (int i = 0; i < count; ++i) mask |= cast_may_pass(box_anchors[first + i], o, d) ? 1 << i : 0;
    return mask;
}

/* A ray's direction as its tests take it: D = d / |d| (float64), its rounding dir, |dir|^2 and |dir| */
typedef struct {
    double3 unit;
    vec3v dir;
    real a, length;
} CastDirection;

/* The square root of each lane of a 4-vector: on PoCL's CPU device one vector instruction of the
 * compiler's own (OpenCL's sqrt is a call there: kernels/lanes.h's v_sqrt), correctly rounded either way */
#ifdef PYCLRAY_INLINE_BUILTINS
#define CAST_SQRT4(T, F, x) ((T)(F((x).s0), F((x).s1), F((x).s2), F((x).s3)))
#else
#define CAST_SQRT4(T, F, x) sqrt(x)
#endif
#ifdef PYCLRAY_FP64
#define CAST_REAL_SQRT4(x) CAST_SQRT4(double4, CAST_SQRT, x)
#define CAST_TO_REAL4(x) (x)
#else
#ifdef PYCLRAY_INLINE_BUILTINS
#define CAST_REAL_SQRT4(x) CAST_SQRT4(float4, __builtin_sqrtf, x)
#else
#define CAST_REAL_SQRT4(x) sqrt(x)
#endif
#define CAST_TO_REAL4(x) convert_float4(x)
#endif

/* Four rays' directions (their x, y and z components in the lanes of x, y, z), set up at once in
 * vector registers: their divisions and square roots are one vector instruction each (see CAST_GROUP).
 * Per lane D = d / |d| in float64, d scaled first by the power of two 2^-e of its largest
 * component m (m in [2^e, 2^(e+1)); at least 2^-1022, a normal number, for m beyond 2^1023;
 * 2^1023 for a subnormal m, whose exponent bits are 0): exact, and a multiplication where a
 * division by m cost one more division per ray; the largest scaled component lies in [2^-51, 4),
 * so neither a tiny nor a huge finite direction under- or overflows in the length. */
inline void cast_directions4(const double4 x, const double4 y, const double4 z, CastDirection* out)
{
    const double4 zero = (double4)(0.0);
    const double4 size_x = x < zero ? -x : x, size_y = y < zero ? -y : y, size_z = z < zero ? -z : z;
    const double4 largest_xy = size_x > size_y ? size_x : size_y;
    const double4 largest = size_z > largest_xy ? size_z : largest_xy;
    const long4 field = (long4)(2046) - (as_long4(largest) >> 52);  /* the exponent bits of 2^-e: 1023 - e */
    const double4 scale = as_double4((field < (long4)(1) ? (long4)(1) : field) << 52);
    const double4 sx = x * scale, sy = y * scale, sz = z * scale;
    const double4 root = CAST_SQRT4(double4, CAST_SQRT, (sx * sx + sy * sy) + sz * sz);
    const double4 ux = sx / root, uy = sy / root, uz = sz / root;
    const real4 dx = CAST_TO_REAL4(ux), dy = CAST_TO_REAL4(uy), dz = CAST_TO_REAL4(uz);
    const real4 a = (dx * dx + dy * dy) + dz * dz;
    const real4 length = CAST_REAL_SQRT4(a);  /* |dir|: the shapes' s is along dir, not D */
#define CAST_DIRECTION_LANE(l, s)                                                   \
    out[l].unit = (double3)(ux.s, uy.s, uz.s);                                      \
    out[l].dir = v3(dx.s, dy.s, dz.s);                                              \
    out[l].a = a.s;                                                                 \
    out[l].length = length.s;
    CAST_DIRECTION_LANE(0, s0) CAST_DIRECTION_LANE(1, s1) CAST_DIRECTION_LANE(2, s2) CAST_DIRECTION_LANE(3, s3)
#undef CAST_DIRECTION_LANE
}

/* rays[l0 .. l0 + 3]'s directions, set up at once */
#define CAST_LOAD_DIRECTIONS4(l0)                                                   \
    {                                                                               \
        const double3 d0 = load_double3(directions, rays[(l0)]), d1 = load_double3(directions, rays[(l0) + 1]); \
        const double3 d2 = load_double3(directions, rays[(l0) + 2]), d3 = load_double3(directions, rays[(l0) + 3]); \
        cast_directions4((double4)(d0.x, d1.x, d2.x, d3.x), (double4)(d0.y, d1.y, d2.y, d3.y), \
                         (double4)(d0.z, d1.z, d2.z, d3.z), &directions_of[(l0)]);  \
    }

/* The places i0 .. i0 + CAST_GROUP - 1 of the order (those below n_rays): each one's ray rays[l] and
 * its direction, set up together (see CAST_GROUP) */
#define PYCLRAY_CAST_GROUP_SETUP                                                    \
    const int i0 = group * CAST_GROUP;                                              \
    const int in_group = n_rays - i0 < CAST_GROUP ? n_rays - i0 : CAST_GROUP;       \
    int rays[CAST_GROUP];                                                           \
    CastDirection directions_of[CAST_GROUP];                                        \
    PYCLRAY_CAST_PREFETCH_GROUP(i0)                                                 \
    PYCLRAY_CAST_PREFETCH_GROUP(i0 + CAST_GROUP)                                    \
    /* all CAST_GROUP (8) set up, four at once, the places past the batch's end as its last ray */ \
    for (int l = 0; l < CAST_GROUP; ++l) {                                          \
        const int i = l < in_group ? i0 + l : n_rays - 1;                           \
        rays[l] = ordered ? order[i] : i;                                           \
    }                                                                               \
    CAST_LOAD_DIRECTIONS4(0)                                                        \
    CAST_LOAD_DIRECTIONS4(4)

/* the setup shared by cast and occluded: ray r (origins: 3 doubles per ray; one origin for every
 * ray where origin_stride is 0) and its direction, set up by its group */
#define PYCLRAY_CAST_RAY                                                            \
    RayPacket ray;                                                                  \
    ray.world = load_double3(origins, r * origin_stride);                           \
    ray.dir_exact = direction->unit;                                                \
    ray.dir = direction->dir;                                                       \
    ray.a = direction->a;                                                           \
    ray.origin = v3(0, 0, 0);  /* each shape is framed on the ray's origin */       \
    const real length = direction->length;                                          \
    const double t_max = limits[(size_t)r * (size_t)limit_stride];

/* its box ray around the scene's anchor, with a margin over the rounding of its origin */
#define PYCLRAY_CAST_BOX                                                            \
    PYCLRAY_CAST_MOVED                                                              \
    const double3 from_anchor = ray.world - scene_anchor.xyz;                       \
    const float3 o = convert_float3(from_anchor);                                   \
    const float3 size = o < (float3)(0.0f) ? -o : o;                                \
    const float margin = 0x1p-20f * ((size.x + size.y) + size.z);                   \
    const float3 box_direction = convert_float3(ray.dir_exact);                     \
    const BoxRay box = box_ray(o, box_direction, margin);

/* The box tests are in float: an origin beyond 2^100 from the scene's anchor (possible in fp64),
 * or a scene that large (scene_anchor.w != 0), would overflow them; such a ray tests every bounded
 * shape instead, one after the other (exactly as through the BVH, only slower). */
#define PYCLRAY_CAST_BOUNDED(VISIT, ENTERED)                                        \
    if (scene_anchor.w != 0 || !(CAST_FABS(from_anchor.x) < 0x1p100 && CAST_FABS(from_anchor.y) < 0x1p100 \
                                  && CAST_FABS(from_anchor.z) < 0x1p100)) {         \
        int n_bounded = 0;                                                          \
        PYCLRAY_BOUNDED(PYCLRAY_CAST_COUNT)                                         \
        for (int q = 0; q < n_bounded; ++q) { VISIT(q) }                            \
    } else if (box_entered(root_box, &box, limit)) {                                \
        ENTERED  /* the BVH's traversal (or its start, where cast interleaves rays) */ \
    }
#define PYCLRAY_CAST_COUNT(Type, type) n_bounded += n_##type##s;
#define PYCLRAY_CAST_LEAF_MASK(first, count) cast_leaf_mask(box_anchors, first, count, o, box_direction)

#ifndef PYCLRAY_OCCLUDED

/* the nearest hit so far (float64 distance), on an exact tie the lowest id */
#ifdef PYCLRAY_TRACK_ID
/* The id of the shape of this kind at index k of its type's array (-1 for none): read only for the
 * winner and on exact ties, not at every nearer hit (a read of the packed entries that missed the
 * cache: a fifth of the kernel's time on 100,000 spheres). */
#define PYCLRAY_CAST_ID_OF(Type, type) \
    if (id_kind == KIND_##type) id_value = PYCLRAY_CAST_MODE(PYCLRAY_CAST_ID_, type)(type, id_k);
#define PYCLRAY_CAST_ID_ENTRY(type, k) type##s[k].id
#define PYCLRAY_CAST_ID(value, kind, k)                                             \
    {                                                                               \
        const int id_kind = (kind), id_k = (k);                                     \
        int id_value = -1;                                                          \
        PYCLRAY_SHAPES(PYCLRAY_CAST_ID_OF)                                          \
        value = id_value;                                                           \
    }
#define PYCLRAY_CAST_TAKE(t, id, kind, k, q)                                        \
    {                                                                               \
        bool take = (t) < best;                                                     \
        if (!take && (t) == best && (t) < INFINITY) {                               \
            int best_id;                                                            \
            PYCLRAY_CAST_ID(best_id, best_kind, best_k)                             \
            take = (id) < best_id;                                                  \
        }                                                                           \
        if (take) { best = (t); best_kind = (kind); best_k = (k); best_q = (q); }   \
    }
#else
#define PYCLRAY_CAST_TAKE(t, id, kind, k, q) best = (t) < best ? (t) : best;
#endif
#define PYCLRAY_CAST_LIMIT limit = float_above_wide(best);
#define PYCLRAY_CAST_REACH best  /* no hit of the shape precedes s0 */
#define PYCLRAY_CAST_NORMAL(Type, type)                                             \
    if (best_kind == KIND_##type) { PYCLRAY_CAST_MODE(PYCLRAY_CAST_NORMAL_, type)(Type, type) }
#define PYCLRAY_CAST_NORMAL_ENTRY(Type, type)                                       \
    {                                                                               \
        PYCLRAY_CAST_FRAMED(Type, type, best_k, ray.world)                          \
        normal = PYCLRAY_NORMAL_##type(&framed, &ray, camera, MISS, 1);             \
    }

/* the cast kernel's arguments after the camera (SHAPE as for render) */
#define PYCLRAY_CAST_ARGS(P, SHAPE)                                                   \
    P(const int, n_rays) P(__global const int*, order) P(const int, ordered)          \
    P(__global const double*, origins) P(const int, origin_stride)                    \
    P(__global const double*, directions) P(__global const double*, limits)           \
    P(const int, limit_stride) P(const double4, scene_anchor)                         \
    PYCLRAY_BVH_ARGS(P) PYCLRAY_SHAPES(SHAPE) PYCLRAY_OUTPUT_ARGS(P)

/* Each work-item's rays (a group of CAST_GROUP) traverse the BVH together: a step of each in turn
 * (kernels/bvh.h's PYCLRAY_TRAVERSE_STEP: a node's children pushed, or a leaf's shapes tested), so
 * that the misses of one ray's next node or leaf overlap the others' work and misses, where one ray
 * alone waits for each of its reads in turn (a node, its child, ..., a leaf's ref, its block: on a
 * mesh of 1,000,000 triangles, whose cast data is twice the L3 cache, most of the time). Each ray's
 * own steps are the same, in the same order, as one ray's traversal: no bit of any result depends
 * on the interleaving. CPU time of 100,000 incoherent rays (bench.cast_ab, against rays one after
 * the other): 1M triangles -25%, the 75k-triangle bunny (whose data fits the L3) -4%. A ray's state
 * (CastRay) lives between its steps in the work-item's memory: cast_start sets it up (the ray, its
 * unbounded shapes, its box ray, the root pushed), cast_step is one step, cast_end writes its
 * results. */
/* the state's parts, (type, name) each, kept as name_ and saved from cast_start's local of that name:
 * the ray's, and (with bounded shapes) its traversal's */
#define CAST_RAY_STATE(X) \
    X(RayPacket, ray) X(double, t_max) X(double, best) X(int, r) X(int, best_kind) X(int, best_k) X(int, best_q) X(real, length)
#define CAST_TRAVERSAL_STATE(X) X(RayPacket, moved) X(double4, moved_anchor) X(double, s0) X(bool, near) \
    X(float3, o) X(float3, box_direction) X(BoxRay, box) X(float, limit)
#define CAST_STATE_FIELD(T, name) T name##_;
#define CAST_STATE_SAVE(T, name) S->name##_ = name;
typedef struct {
    CAST_RAY_STATE(CAST_STATE_FIELD)
#ifdef PYCLRAY_HAS_BOUNDED
    CAST_TRAVERSAL_STATE(CAST_STATE_FIELD)
    int top_;
    int stack_child_[BVH_STACK];
    float stack_entry_[BVH_STACK];
#endif
} CastRay;

/* (always inlined on PoCL's CPU device, as the functions above: a step is called per ray in the
 * interleaving loop) */
inline void cast_start(CastRay* S, const int r, const CastDirection* direction, __global const Camera* camera
                       PYCLRAY_CAST_ARGS(PYCLRAY_DECLARE, PYCLRAY_SHAPE_PARAMETERS))
{
    PYCLRAY_CAST_RAY
    /* hits up to t_max count: best starts just above it */
    double best = t_max < INFINITY ? as_double(as_long(t_max) + 1) : t_max;  /* nextafter up, t_max > 0 */
    int best_kind = KIND_NONE, best_k = 0, best_q = -1;
    PYCLRAY_UNBOUNDED(PYCLRAY_CAST_LINEAR)
#ifdef PYCLRAY_HAS_BOUNDED
    {
        PYCLRAY_CAST_BOX
        float limit = float_above_wide(best);
        S->top_ = 0;
        PYCLRAY_CAST_BOUNDED(PYCLRAY_CAST_VISIT, S->stack_child_[0] = 0; S->stack_entry_[0] = 0.0f; S->top_ = 1;)
        CAST_TRAVERSAL_STATE(CAST_STATE_SAVE)
    }
#endif
    CAST_RAY_STATE(CAST_STATE_SAVE)
}

#ifdef PYCLRAY_HAS_BOUNDED
/* the names the visit's macros use (PYCLRAY_CAST_VISIT and what it expands to), bound to the state's
 * (none may be a shape type's name, which the macros paste: the box ray is passed as S->box_) */
#define ray (S->ray_)
#define length (S->length_)
#define best (S->best_)
#define best_kind (S->best_kind_)
#define best_k (S->best_k_)
#define best_q (S->best_q_)
#define moved (S->moved_)
#define moved_anchor (S->moved_anchor_)
#define s0 (S->s0_)
#define near (S->near_)
#define o (S->o_)
#define box_direction (S->box_direction_)
#define limit (S->limit_)
#define top (S->top_)
#define stack_child (S->stack_child_)
#define stack_entry (S->stack_entry_)
inline void cast_step(CastRay* S, __global const Camera* camera PYCLRAY_CAST_ARGS(PYCLRAY_DECLARE, PYCLRAY_SHAPE_PARAMETERS))
{
    PYCLRAY_TRAVERSE_STEP(nodes, S->box_, limit, stack_child, stack_entry, top, PYCLRAY_CAST_LEAF_MASK, PYCLRAY_CAST_VISIT)
}
#undef ray
#undef length
#undef best
#undef best_kind
#undef best_k
#undef best_q
#undef moved
#undef moved_anchor
#undef s0
#undef near
#undef o
#undef box_direction
#undef limit
#undef top
#undef stack_child
#undef stack_entry
#endif

inline void cast_end(const CastRay* S, __global const Camera* camera PYCLRAY_CAST_ARGS(PYCLRAY_DECLARE, PYCLRAY_SHAPE_PARAMETERS))
{
    RayPacket ray = S->ray_;
    const double best = S->best_, t_max = S->t_max_;
    const int best_kind = S->best_kind_, best_k = S->best_k_, best_q = S->best_q_;
    const bool hit = best <= t_max && best < INFINITY;
    const size_t index = (size_t)S->r_;
#ifdef PYCLRAY_AOV_DEPTH
    depth[index] = hit ? (real)best : MISS;
#endif
#ifdef PYCLRAY_AOV_NORMAL
    {
#ifdef PYCLRAY_HAS_BOUNDED
        if (hit && best_q >= 0) {  /* the winner's own ray, as it was tested */
            double s0;
            bool near;
            ray = moved_ray(&ray, anchors[best_q], &s0, &near);
        }
#endif
        vec3v normal = v3(0, 0, 0);
        if (hit) { PYCLRAY_SHAPES(PYCLRAY_CAST_NORMAL) }
        normal_out[3 * index] = normal.x;
        normal_out[3 * index + 1] = normal.y;
        normal_out[3 * index + 2] = normal.z;
    }
#endif
#ifdef PYCLRAY_AOV_ID
    {
        int best_id;
        PYCLRAY_CAST_ID(best_id, hit ? best_kind : KIND_NONE, best_k)
        id_out[index] = best_id;
    }
#endif
}

PYCLRAY_KERNELS_BEGIN
/* one work-item per group of CAST_GROUP places of the order: its rays' traversals interleaved where
 * the program has a type whose leaves are blocks (PYCLRAY_CAST_INTERLEAVE: programs.py), on PoCL's
 * CPU device (PYCLRAY_INLINE_BUILTINS): a GPU hides a ray's misses behind its other work-items', and
 * the group's 8 states (17 KB with their stacks) would not fit its private memory */
PYCLRAY_WORK_ITEM_FUNCTION void cast_group(const int group, __global const Camera* camera
                                           PYCLRAY_CAST_ARGS(PYCLRAY_DECLARE, PYCLRAY_SHAPE_PARAMETERS))
{
    PYCLRAY_CAST_GROUP_SETUP
#if defined(PYCLRAY_CAST_INTERLEAVE) && defined(PYCLRAY_HAS_BOUNDED) && defined(PYCLRAY_INLINE_BUILTINS)
    CastRay state[CAST_GROUP];
    for (int l = 0; l < in_group; ++l)
        cast_start(&state[l], rays[l], &directions_of[l], camera PYCLRAY_CAST_ARGS(PYCLRAY_PASS, PYCLRAY_SHAPE_PASSED));
    /* a step of each ray still traversing, until none is (cast's limit never falls below 0) */
    for (bool going = true; going;) {
        going = false;
        for (int l = 0; l < in_group; ++l) {
            if (state[l].top_ > 0) {
                cast_step(&state[l], camera PYCLRAY_CAST_ARGS(PYCLRAY_PASS, PYCLRAY_SHAPE_PASSED));
                going = true;
            }
        }
    }
    for (int l = 0; l < in_group; ++l)
        cast_end(&state[l], camera PYCLRAY_CAST_ARGS(PYCLRAY_PASS, PYCLRAY_SHAPE_PASSED));
#else
    /* one ray after the other (no block types: spheres' short paths through data that the caches
     * hold gained nothing from interleaving and lost 7-17% of their CPU time on 16,384 spheres) */
    for (int l = 0; l < in_group; ++l) {
        CastRay one;
        cast_start(&one, rays[l], &directions_of[l], camera PYCLRAY_CAST_ARGS(PYCLRAY_PASS, PYCLRAY_SHAPE_PASSED));
#ifdef PYCLRAY_HAS_BOUNDED
        while (one.top_ > 0) cast_step(&one, camera PYCLRAY_CAST_ARGS(PYCLRAY_PASS, PYCLRAY_SHAPE_PASSED));
#endif
        cast_end(&one, camera PYCLRAY_CAST_ARGS(PYCLRAY_PASS, PYCLRAY_SHAPE_PASSED));
    }
#endif
}

__kernel void cast(__global const Camera* camera PYCLRAY_CAST_ARGS(PYCLRAY_DECLARE, PYCLRAY_SHAPE_PARAMETERS))
{
    const int group = get_global_id(0);
    if (group * CAST_GROUP < n_rays) cast_group(group, camera PYCLRAY_CAST_ARGS(PYCLRAY_PASS, PYCLRAY_SHAPE_PASSED));
}

#else

/* Whether any shape is hit at a distance up to t_max: the search stops at the first such hit. */
#define PYCLRAY_CAST_TAKE(t, id, kind, k, q) found = found || ((t) <= t_max && (t) < INFINITY);
#define PYCLRAY_CAST_LIMIT if (found) limit = -INFINITY;
#define PYCLRAY_CAST_REACH t_max

/* the occluded kernel's arguments after the first (SHAPE as for render) */
#define PYCLRAY_OCCLUDED_ARGS(P, SHAPE)                                               \
    P(__global const int*, order) P(const int, ordered)                               \
    P(__global const double*, origins) P(const int, origin_stride)                    \
    P(__global const double*, directions) P(__global const double*, limits)           \
    P(const int, limit_stride) P(const double4, scene_anchor)                         \
    PYCLRAY_BVH_ARGS(P) PYCLRAY_SHAPES(SHAPE) P(__global char*, occluded_out)

PYCLRAY_KERNELS_BEGIN
inline void occluded_ray(const int r, const CastDirection* direction, const int n_rays
                         PYCLRAY_OCCLUDED_ARGS(PYCLRAY_DECLARE, PYCLRAY_SHAPE_PARAMETERS))
{
    PYCLRAY_CAST_RAY
    bool found = false;
    PYCLRAY_UNBOUNDED(PYCLRAY_CAST_LINEAR)
#ifdef PYCLRAY_HAS_BOUNDED
    if (!found) {
        PYCLRAY_CAST_BOX
        float limit = float_above_wide(t_max);
        PYCLRAY_CAST_BOUNDED(PYCLRAY_CAST_VISIT, PYCLRAY_TRAVERSE(nodes, box, limit, PYCLRAY_CAST_LEAF_MASK, PYCLRAY_CAST_VISIT))
    }
#endif
    occluded_out[r] = found ? 1 : 0;
}

PYCLRAY_WORK_ITEM_FUNCTION void occluded_group(const int group, const int n_rays
                                               PYCLRAY_OCCLUDED_ARGS(PYCLRAY_DECLARE, PYCLRAY_SHAPE_PARAMETERS))
{
    PYCLRAY_CAST_GROUP_SETUP
    for (int l = 0; l < in_group; ++l)
        occluded_ray(rays[l], &directions_of[l], n_rays PYCLRAY_OCCLUDED_ARGS(PYCLRAY_PASS, PYCLRAY_SHAPE_PASSED));
}

__kernel void occluded(const int n_rays PYCLRAY_OCCLUDED_ARGS(PYCLRAY_DECLARE, PYCLRAY_SHAPE_PARAMETERS))
{
    const int group = get_global_id(0);
    if (group * CAST_GROUP < n_rays) occluded_group(group, n_rays PYCLRAY_OCCLUDED_ARGS(PYCLRAY_PASS, PYCLRAY_SHAPE_PASSED));
}

#endif

#endif
