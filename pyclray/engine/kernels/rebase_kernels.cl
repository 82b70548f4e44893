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
/* x rounded to float toward -inf (below) or +inf, and kept finite: the nearest float, stepped once
 * the other way where it lies beyond x (convert_float_rtn and _rtp would be calls into PoCL's
 * library); the same floats as the host's outward32. */
inline float float_outward(const double x, const bool below)
{
    const float f = (float)x;
    /* the next float toward -inf (below) or +inf from f, through its bits: for f > 0 the next
     * larger float has bits + 1, for f < 0 bits - 1; from 0 the smallest subnormal */
    const int bits = as_int(f);
    const bool up = !below;
    const int step = ((f > 0) == up) ? 1 : -1;
    const float next = f == 0.0f ? (up ? 0x1p-149f : -0x1p-149f) : as_float(bits + step);
    const float out = (below ? (double)f > x : (double)f < x) ? next : f;
    return out < -FLT_MAX ? -FLT_MAX : (out > FLT_MAX ? FLT_MAX : out);
}

__kernel void rebase_nodes(__global const double4* world, __global BvhNode* out, const int n, const double4 origin)
{
    const int k = get_global_id(0);
    if (k >= n) return;
    const double3 lo = world[2 * k].xyz - origin.xyz, hi = world[2 * k + 1].xyz - origin.xyz;
    const float4 old_lo = out[k].lo, old_hi = out[k].hi;  /* w: first and count, kept */
    out[k].lo = (float4)(float_outward(lo.x, true), float_outward(lo.y, true), float_outward(lo.z, true), old_lo.w);
    out[k].hi = (float4)(float_outward(hi.x, false), float_outward(hi.y, false), float_outward(hi.z, false), old_hi.w);
}

/* An animation frame's changed entries (pyclray.engine.prepared.PreparedScene.update): rows of width
 * 16-byte words each (a world or frame struct, or a BVH node) written at their indices. */
__kernel void scatter_rows(__global uint4* out, __global const int* index, __global const uint4* rows,
                           const int n, const int width)
{
    const int k = get_global_id(0);
    if (k >= n) return;
    for (int c = 0; c < width; ++c) out[(size_t)index[k] * width + c] = rows[(size_t)k * width + c];
}
