/* The per-view pass's kernels (see rebase.cl): one per shape type present, and the BVH's nodes. */

#define PYCLRAY_REBASE_KERNEL(Type, type)                                                        \
    __kernel void rebase_##type(__global const Type##World* world, __global Type* out, const int n, \
                                const double4 origin, const double4 u, const double4 v, const double4 w) \
    {                                                                                            \
        const int k = get_global_id(0);                                                          \
        if (k >= n) return;                                                                      \
        const Frame frame = {origin.xyz, u.xyz, v.xyz, w.xyz};                                   \
        type##_rebase(&world[k], &out[k], &frame);                                               \
    }
PYCLRAY_SHAPES(PYCLRAY_REBASE_KERNEL)

/* The binary BVH's boxes around the eye, in world axes: float64 corners minus the eye, rounded
 * outward to float32 and kept finite (pyclray.engine.bvh.outward32); each node's first and count
 * (the .w bits) were written once and stay. */
__kernel void rebase_nodes(__global const double4* world, __global BvhNode* out, const int n, const double4 origin)
{
    const int k = get_global_id(0);
    if (k >= n) return;
    const double3 lo = world[2 * k].xyz - origin.xyz, hi = world[2 * k + 1].xyz - origin.xyz;
    const float3 limit = (float3)(FLT_MAX);
    out[k].lo.xyz = clamp(convert_float3_rtn(lo), -limit, limit);
    out[k].hi.xyz = clamp(convert_float3_rtp(hi), -limit, limit);
}

/* An animation frame's changed entries (pyclray.engine.prepared.PreparedScene.update): rows of width
 * double4s each (a world struct, or a BVH node's two corners) written at their indices. */
__kernel void scatter_rows(__global double4* out, __global const int* index, __global const double4* rows,
                           const int n, const int width)
{
    const int k = get_global_id(0);
    if (k >= n) return;
    for (int c = 0; c < width; ++c) out[(size_t)index[k] * width + c] = rows[(size_t)k * width + c];
}
