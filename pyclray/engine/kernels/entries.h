/* A render's shape entries: where it reads each type's (PYCLRAY_MODE_<type>), and which a packet
 * visits (tile lists, or the BVH's leaves).
 *
 * A render's shapes in the eye's space (origin the eye, the camera's axes: what the shape tests
 * take) come from one of three places, chosen per type (PYCLRAY_MODE_<type>, from the host: in a
 * from-world scene, pyclray.engine.scene.prepared's FROM_WORLD_FROM, Shape.tested_from_world and Shape.indexed):
 * - FROM_WORLD (devices with float64): each shape is rebased where it is tested, from its float64 world
 *   entry (type##_worlds), on the eye's space (space_origin, space_u, space_v, space_w), by its <type>_rebase (the per-view pass's function, compiled without contraction as
 *   there: the same bits) into a private copy; its id and its index within its shape come from
 *   their own arrays. The scene holds its world entries only: no copy per view, no pass over them
 *   when the camera moves (pyclray.engine.scene.prepared).
 * - COPIED: the per-view pass's buffer of the entries in the space (type##s), ids included (in a
 *   rebased program, copied to private memory where tested: the shape functions take one space).
 * PYCLRAY_SHAPE_OF(Type, type, k, name) declares name, a pointer to shape k of its type in the space;
 * PYCLRAY_ID_OF(type, k) and PYCLRAY_PRIMITIVE_AT(type, k) are its id and its index in its shape.
 * The kernel's parameters of each mode: pyclray/engine/launch/signatures.py. */
#define PYCLRAY_SHAPE_FROM_WORLD(Type, type, k, name)                                 \
    Type name##_from_world;                                                           \
    type##_rebase(&type##_worlds[k], &name##_from_world, &view_space);                \
    const Type* const name = &name##_from_world;
#define PYCLRAY_ID_FROM_WORLD(type, k) type##_ids[k]
#define PYCLRAY_PRIMITIVE_FROM_WORLD(type, k) type##_primitives[k]
#ifdef PYCLRAY_FROM_WORLD
#define PYCLRAY_SHAPE_COPIED(Type, type, k, name)                                     \
    const Type name##_copy = type##s[k];                                              \
    const Type* const name = &name##_copy;
#else
#define PYCLRAY_SHAPE_COPIED(Type, type, k, name) SHAPE_SPACE const Type* const name = &type##s[k];
#endif
#define PYCLRAY_ID_COPIED(type, k) type##s[k].id
#define PYCLRAY_PRIMITIVE_COPIED(type, k) type##s[k].primitive
/* - INDEXED (a from-world scene's triangles, pyclray/engine/scene/indexed.py): each triangle assembled from its face
 * (type##_faces) and the per-view pass's vertices (type##_vertices: <type>_assemble), its id from its own array, its index in its
 * shape from its face; the winner's world normal from the float64 vertices (<type>_world_normal) */
#define PYCLRAY_SHAPE_INDEXED(Type, type, k, name)                                    \
    Type name##_from_world;                                                           \
    type##_assemble(type##_faces[k], type##_vertices, &name##_from_world);            \
    const Type* const name = &name##_from_world;
#define PYCLRAY_ID_INDEXED(type, k) type##_ids[k]
#define PYCLRAY_PRIMITIVE_INDEXED(type, k) type##_faces[k].w
/* what a winner needs besides its shape in the space: an indexed triangle's world normal */
#define PYCLRAY_WINNER_FROM_WORLD(type, k, name)
#define PYCLRAY_WINNER_COPIED(type, k, name)
#define PYCLRAY_WINNER_INDEXED(type, k, name) type##_world_normal(&name##_from_world, type##_faces[k], type##_world_vertices);
#define PYCLRAY_WINNER_OF(type, k, name) PYCLRAY_CAT(PYCLRAY_WINNER_, PYCLRAY_MODE_##type)(type, k, name)
/* a smooth shape's shading normals (kernels/shading.h): its entry's, or an indexed triangle's vertices' */
#define PYCLRAY_SMOOTH_FROM_WORLD(type, k) type##_smooth[k]
#define PYCLRAY_SMOOTH_COPIED(type, k) type##_smooth[k]
#define PYCLRAY_SMOOTH_INDEXED(type, k) type##_smooth_of(type##_faces[k], type##_smooth)
#define PYCLRAY_SMOOTH_AT(type, k) PYCLRAY_CAT(PYCLRAY_SMOOTH_, PYCLRAY_MODE_##type)(type, k)
#define PYCLRAY_SHAPE_OF(Type, type, k, name) PYCLRAY_CAT(PYCLRAY_SHAPE_, PYCLRAY_MODE_##type)(Type, type, k, name)
#define PYCLRAY_ID_OF(type, k) PYCLRAY_CAT(PYCLRAY_ID_, PYCLRAY_MODE_##type)(type, k)
#define PYCLRAY_PRIMITIVE_AT(type, k) PYCLRAY_CAT(PYCLRAY_PRIMITIVE_, PYCLRAY_MODE_##type)(type, k)

#ifdef PYCLRAY_BVH
/* the bounded types' shapes are reached through the BVH's leaves, the others (planes) are each
 * tested by every ray */
#define PYCLRAY_FIRST(type) 0
#define PYCLRAY_END(type) n_##type##s
#define PYCLRAY_SHAPE_AT(type, q) (q)
#define PYCLRAY_LINEAR(X) PYCLRAY_UNBOUNDED(X)
#else
/* per shape type, for each tile of the image the shapes that can be seen in it
 * (type##_tile_list[type##_tile_start[tile] .. type##_tile_start[tile + 1]], increasing; the host's
 * conservative screen bounds, pyclray/engine/bvh/tiles.py): the others miss every ray there */
#define PYCLRAY_FIRST(type) type##_tile_start[tile]
#define PYCLRAY_END(type) type##_tile_start[tile + 1]
#define PYCLRAY_SHAPE_AT(type, q) type##_tile_list[q]
#define PYCLRAY_LINEAR(X) PYCLRAY_SHAPES(X)
#endif
