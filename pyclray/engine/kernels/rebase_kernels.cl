/* The per-view pass's kernels (see rebase.cl): one per shape type present; and an animation's scatter. */

#define PYCLRAY_REBASE_KERNEL(Type, type)                                                        \
    __kernel void rebase_##type(__global const Type##World* world, __global Type* out, const int n, \
                                const double4 origin, const double4 u, const double4 v, const double4 w) \
    {                                                                                            \
        const int k = get_global_id(0);                                                          \
        if (k >= n) return;                                                                      \
        const Space space = {origin.xyz, u.xyz, v.xyz, w.xyz};                                   \
        type##_rebase(&world[k], &out[k], &space);                                               \
    }
PYCLRAY_SHAPES(PYCLRAY_REBASE_KERNEL)

/* The vertices of indexed triangles (pyclray/engine/scene/indexed.py) in the space, w = 0: the per-view pass
 * of a from-world scene's meshes, each vertex rebased as mesh_rebase rebases a triangle's corners. */
__kernel void rebase_vertices(__global const double4* world, __global real4* out, const int n, const double4 origin,
                              const double4 u, const double4 v, const double4 w)
{
    const int k = get_global_id(0);
    if (k >= n) return;
    const Space space = {origin.xyz, u.xyz, v.xyz, w.xyz};
    out[k] = (real4)(to_space(&space, world[k].xyz - space.origin), 0);
}

/* An animation frame's changed entries (pyclray.engine.scene.prepared.PreparedScene.update): rows of width
 * 16-byte words each (a world or space struct, or a BVH node) written at their indices. */
__kernel void scatter_rows(__global uint4* out, __global const int* index, __global const uint4* rows,
                           const int n, const int width)
{
    const int k = get_global_id(0);
    if (k >= n) return;
    for (int c = 0; c < width; ++c) out[(size_t)index[k] * width + c] = rows[(size_t)k * width + c];
}
