/* The shape types a program has (PYCLRAY_SHAPES(X): X(Type, type) for each, from the host) and how
 * a shape plugs into the queries: two functions of its kernel file, both over a packet of rays,
 *   realv type_hit(shape, ray)             per lane, the nearest s > 0 along ray->dir, or MISS
 *   vec3v type_normal(shape, ray, camera)  the unit world normal, used in the lanes the shape won
 * called through PYCLRAY_HIT_<type>, PYCLRAY_NORMAL_<type>, PYCLRAY_PRIMITIVE_<type> and
 * PYCLRAY_BARYCENTRIC_<type> (pyclray/engine/launch/programs.py writes them for each type; a type with
 * arrays shared by its entries, Shape.shared, defines its own: mesh instances, kernels/instance.cl,
 * which also take the lanes' best so far and keep each lane's triangle).
 *
 * Each type present is a kind, 1 + its place in PYCLRAY_SHAPES: the BVH's refs and the queries'
 * winners name a shape as 16 k + kind (k its index in its type's array). */
#define PYCLRAY_KIND(Type, type) KIND_##type,
enum { KIND_NONE = 0, PYCLRAY_SHAPES(PYCLRAY_KIND) KIND_COUNT };
