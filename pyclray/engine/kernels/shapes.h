/* The shape types a program has (PYCLRAY_SHAPES(X): X(Type, type) for each, from the host) and how
 * a shape plugs into the queries: two functions of its kernel file, both over a packet of rays,
 *   realv type_hit(shape, ray)             per lane, the nearest s > 0 along ray->dir, or MISS
 *   vec3v type_normal(shape, ray, basis)   the unit world normal, used in the lanes the shape won
 * called through PYCLRAY_HIT_<type>, PYCLRAY_NORMAL_<type>, PYCLRAY_PRIMITIVE_<type> and
 * PYCLRAY_BARYCENTRIC_<type> (pyclray/engine/launch/programs.py writes them for each type; a type with
 * arrays shared by its entries, Shape.shared, defines its own: mesh instances, kernels/instance.cl,
 * which also take the lanes' best so far and keep each lane's triangle).
 *
 * Each type present is a kind, 1 + its place in PYCLRAY_SHAPES: the BVH's refs and the queries'
 * winners name a shape as 16 k + kind (k its index in its type's array). */
#define PYCLRAY_KIND(Type, type) KIND_##type,
enum { KIND_NONE = 0, PYCLRAY_SHAPES(PYCLRAY_KIND) KIND_COUNT };

/* The axes of the space a shape is tested in, in world coordinates (the columns of world_from_space):
 * a render's are the camera's (kernels/camera.h: camera_basis), cast's and any-hit's the world's own
 * (kernels/cast.h). A normal function turns what it computes in the space into the world with them. */
typedef struct {
    real4 u, v, w;
} Basis;

/* n (a direction of the space of axes u, v, w) in world coordinates */
inline vec3v world_from_axes(const real4 u, const real4 v, const real4 w, const vec3v n)
{
    return v3((n.x * u.x + n.y * v.x) + n.z * w.x,
              (n.x * u.y + n.y * v.y) + n.z * w.y,
              (n.x * u.z + n.y * v.z) + n.z * w.z);
}

inline vec3v world_from_basis(const Basis* basis, const vec3v n) { return world_from_axes(basis->u, basis->v, basis->w, n); }
