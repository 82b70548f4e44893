/* A mesh's cast blocks (kernels/mesh.cl's triangle test, a leaf's triangles of one mesh at once):
 * cast's only (PYCLRAY_CAST), after kernels/mesh.cl, whose edge functions and barycentrics it uses. */

#if !defined(PYCLRAY_REBASE) && !defined(PYCLRAY_CLOSEST)
#ifdef PYCLRAY_CAST
/* -- cast: a leaf's triangles of one mesh tested at once, one triangle per lane (Embree's triangle8)
 *
 * cast meets a leaf's triangles of one mesh as one block (pyclray/engine/queries/cast_blocks.py groups them,
 * pyclray/model/shapes/mesh_pack.py's cast_blocks packs them): at a 64-byte boundary of the blocks
 * array (the type's world argument in cast), float64s: the header (two ints: count | unique << 8,
 * the mesh's id), the block's unique vertices (float64 world coordinates, rows x, y, z of unique
 * each: a vertex its triangles share is stored once), then the corners (rows a, b, c of count bytes:
 * each triangle's vertices among those). 44 bytes a triangle on a closed mesh (a leaf of 5 triangles
 * has about 7 vertices), read in 3 to 4 cache lines. Each lane is the triangle's test of
 * kernels/mesh.cl as cast runs it on a rebased copy: its vertices minus the ray's moved origin in
 * float64, rounded once (the same bits for a vertex shared with a triangle of another block), then
 * the watertight test with its exact fallback, the same operations in the same order (no
 * contraction: kernels/lanes.h), so every lane's s has the bits of the triangle's own test. A ref of
 * the type is the block's place in 64-byte units; a winner's key is that place times 8 plus its
 * lane. Zero-area triangles are left out of the blocks (never hit). */
#ifdef PYCLRAY_FP64
typedef double8 blockv;
typedef long8 blockmask;
#else
typedef float8 blockv;
typedef int8 blockmask;
#endif

typedef union {
    blockv v;
    real s[8];
} MeshBlockLanes;

/* the lanes' bits of a mask (one int): kernels/bvh.h's bvh_lane_bits, here for long lanes at fp64 */
inline int mesh_block_bits(const blockmask m)
{
#ifdef PYCLRAY_FP64
    const blockmask bits = m & (blockmask)(1, 2, 4, 8, 16, 32, 64, 128);
    const long4 four = bits.lo | bits.hi;
    const long2 two = four.lo | four.hi;
    return (int)(two.x | two.y);
#else
    return bvh_lane_bits(m);
#endif
}

/* Occupancy's parity band (the count from points, kernels/allhits.cl: PYCLRAY_AOV_SURFACE): the lanes
 * whose crossing's sign of s the rounding may have turned, as bits, in *doubt (MESH_BLOCK_DOUBT).
 * The test runs on the corners rounded relative to the origin and on their rounded shear, each
 * corner's own (the same for every triangle of it): an exact count on a moved copy of the mesh,
 * whose parity is the mesh's unless the moves or the rounding of s carry a crossing across s = 0.
 * With u the unit roundoff and m the largest |coordinate| of the three corners relative to the
 * origin, each corner is off by <= u m, its projected (homogeneous) coordinates, of size <= P =
 * 2 m |dz|, by <= 3 u P, each edge function by <= 16 u P^2, so the numerator N = e0 Az + e1 Bz +
 * e2 Cz is off by at most m (50 u P^2 + 5 u |det|) (the edge functions of a crossed triangle have
 * one sign: their magnitudes sum to |det|); a crossing with |N| within a bound above that,
 * MESH_BAND_N (m (256 u m^2 dz^2 + 8 u |det|)), is in doubt: its point's inside is decided
 * exactly on the host (engine/queries/closest.py). A lane whose edge functions were recomputed in
 * double (fp32: mesh_exact_lane, scaled) is in doubt wherever it crosses. */
#ifdef PYCLRAY_AOV_SURFACE
#define MESH_BLOCK_DOUBT , int* doubt, int* leaving
#ifdef PYCLRAY_FP64
#define MESH_BAND_EPSILON 0x1p-53
#else
#define MESH_BAND_EPSILON 0x1p-24f
#endif
#else
#define MESH_BLOCK_DOUBT
#endif

/* Per lane the triangle's s > 0 along ray->dir from ray->world (the moved origin), else MISS; the
 * lanes hit, as bits, in *hits. */
inline blockv mesh_block_hits(__global const double* block, const RayPacket* ray, int* hits MESH_BLOCK_DOUBT)
{
    const int head = as_int2(block[0]).x, count = head & 255, unique = head >> 8;
    __global const double* rows = block + 1;
    __global const uchar* corner = (__global const uchar*)(rows + 3 * unique);
    const real3 d = (real3)(ray->dir.x, ray->dir.y, ray->dir.z);
    /* the axes permuted as mesh_edges_of does: the largest |component| of the direction becomes z */
    const real ax = v_abs(d.x), ay = v_abs(d.y), az = v_abs(d.z);
    const int z_is_x = ax > ay && ax > az;
    const int z_is_y = !(ax > ay) && ay > az;
    const int kx = z_is_x ? 1 : (z_is_y ? 2 : 0), ky = z_is_x ? 2 : (z_is_y ? 0 : 1), kz = z_is_x ? 0 : (z_is_y ? 1 : 2);
    const real dx = z_is_x ? d.y : (z_is_y ? d.z : d.x), dy = z_is_x ? d.z : (z_is_y ? d.x : d.y);
    const real dz = z_is_x ? d.x : (z_is_y ? d.y : d.z);
    const double3 o = ray->world;
    const double ox = z_is_x ? o.y : (z_is_y ? o.z : o.x), oy = z_is_x ? o.z : (z_is_y ? o.x : o.y);
    const double oz = z_is_x ? o.x : (z_is_y ? o.y : o.z);
    __global const double* X = rows + kx * unique;
    __global const double* Y = rows + ky * unique;
    __global const double* Z = rows + kz * unique;
    /* each corner: its vertex minus the origin in float64, rounded once (mesh_rebase); lanes past
     * count stay 0 (dropped) */
    MeshBlockLanes Ax_, Ay_, Az_, Bx_, By_, Bz_, Cx_, Cy_, Cz_;
    Ax_.v = Ay_.v = Az_.v = Bx_.v = By_.v = Bz_.v = Cx_.v = Cy_.v = Cz_.v = (blockv)(0);
    for (int l = 0; l < count; ++l) {
        const int a = corner[l], b = corner[count + l], c = corner[2 * count + l];
        Ax_.s[l] = (real)(X[a] - ox); Ay_.s[l] = (real)(Y[a] - oy); Az_.s[l] = (real)(Z[a] - oz);
        Bx_.s[l] = (real)(X[b] - ox); By_.s[l] = (real)(Y[b] - oy); Bz_.s[l] = (real)(Z[b] - oz);
        Cx_.s[l] = (real)(X[c] - ox); Cy_.s[l] = (real)(Y[c] - oy); Cz_.s[l] = (real)(Z[c] - oz);
    }
    const blockv Ax = Ax_.v, Ay = Ay_.v, Az = Az_.v, Bx = Bx_.v, By = By_.v, Bz = Bz_.v, Cx = Cx_.v, Cy = Cy_.v, Cz = Cz_.v;
    const blockv Dx = (blockv)(dx), Dy = (blockv)(dy), Dz = (blockv)(dz);
    /* the homogeneous shear and the edge functions (mesh_edges_of) */
    const blockv ax_ = Ax * Dz - Az * Dx, ay_ = Ay * Dz - Az * Dy;
    const blockv bx_ = Bx * Dz - Bz * Dx, by_ = By * Dz - Bz * Dy;
    const blockv cx_ = Cx * Dz - Cz * Dx, cy_ = Cy * Dz - Cz * Dy;
    blockv e0 = bx_ * cy_ - by_ * cx_;
    blockv e1 = cx_ * ay_ - cy_ * ax_;
    blockv e2 = ax_ * by_ - ay_ * bx_;
    const int lanes = (1 << count) - 1;
#ifdef PYCLRAY_MESH_EXACT
    const int zero = mesh_block_bits(e0 == (blockv)(0) || e1 == (blockv)(0) || e2 == (blockv)(0)) & lanes;
#ifdef PYCLRAY_AOV_SURFACE
    const int rescaled = zero;
#endif
    if (zero) {  /* those lanes' edge functions exactly signed, in double */
        MeshBlockLanes Sax, Say, Sbx, Sby, Scx, Scy, E0, E1, E2;
        Sax.v = ax_; Say.v = ay_; Sbx.v = bx_; Sby.v = by_; Scx.v = cx_; Scy.v = cy_;
        E0.v = e0; E1.v = e1; E2.v = e2;
        for (int mask = zero; mask != 0; mask &= mask - 1) {
            const int l = BVH_LOWEST_BIT(mask);
            mesh_exact_lane(Sax.s[l], Say.s[l], Sbx.s[l], Sby.s[l], Scx.s[l], Scy.s[l], &E0.s[l], &E1.s[l], &E2.s[l]);
        }
        e0 = E0.v;
        e1 = E1.v;
        e2 = E2.v;
    }
#endif
#if defined(PYCLRAY_TIE_RULE) && defined(PYCLRAY_FP64)
    const int zero = mesh_block_bits(e0 == (blockv)(0) || e1 == (blockv)(0) || e2 == (blockv)(0)) & lanes;
    if (zero) {  /* those lanes' zeros exactly signed (mesh_exact_edge64) */
        MeshBlockLanes Sax, Say, Sbx, Sby, Scx, Scy, E0, E1, E2;
        Sax.v = ax_; Say.v = ay_; Sbx.v = bx_; Sby.v = by_; Scx.v = cx_; Scy.v = cy_;
        E0.v = e0; E1.v = e1; E2.v = e2;
        for (int mask = zero; mask != 0; mask &= mask - 1) {
            const int l = BVH_LOWEST_BIT(mask);
            if (E0.s[l] == 0) E0.s[l] = mesh_exact_edge64(Sbx.s[l], Sby.s[l], Scx.s[l], Scy.s[l]);
            if (E1.s[l] == 0) E1.s[l] = mesh_exact_edge64(Scx.s[l], Scy.s[l], Sax.s[l], Say.s[l]);
            if (E2.s[l] == 0) E2.s[l] = mesh_exact_edge64(Sax.s[l], Say.s[l], Sbx.s[l], Sby.s[l]);
        }
        e0 = E0.v;
        e1 = E1.v;
        e2 = E2.v;
    }
#endif
    const blockv det = (e0 + e1) + e2;
#ifdef PYCLRAY_TIE_RULE
    /* the tie rule where some lane's edge function is 0 (rare), else the strict signs (the same there) */
    blockmask inside = (e0 > (blockv)(0) && e1 > (blockv)(0) && e2 > (blockv)(0))
                       || (e0 < (blockv)(0) && e1 < (blockv)(0) && e2 < (blockv)(0));
    if (mesh_block_bits(e0 == (blockv)(0) || e1 == (blockv)(0) || e2 == (blockv)(0)) & lanes)
        inside = MESH_TIE_INSIDE(e0, e1, e2, ax_, ay_, bx_, by_, cx_, cy_) && det != (blockv)(0);
#else
    const blockmask negative = e0 < (blockv)(0) || e1 < (blockv)(0) || e2 < (blockv)(0);
    const blockmask positive = e0 > (blockv)(0) || e1 > (blockv)(0) || e2 > (blockv)(0);
    const blockmask inside = !(negative && positive) && det != (blockv)(0);
#endif
    *hits = mesh_block_bits(inside) & lanes;
#ifdef PYCLRAY_AOV_SURFACE
    *doubt = *leaving = 0;
#endif
    if (!*hits) return (blockv)(MISS);  /* most blocks a ray reaches it misses: no division */
    const blockv numerator = (e0 * Az + e1 * Bz) + e2 * Cz;
#ifdef PYCLRAY_AOV_SURFACE
    {  /* the crossings in doubt (MESH_BLOCK_DOUBT), lane by lane (a few a ray): each corner's
        * coordinates as rounded above, read again (the lanes' vectors stay in registers) */
        MeshBlockLanes N, Det;
        N.v = numerator;
        Det.v = det;
        for (int mask = *hits; mask != 0; mask &= mask - 1) {
            const int l = BVH_LOWEST_BIT(mask);
            real largest = 0;
            for (int v = 0; v < 3; ++v) {
                const int i = corner[v * count + l];
                largest = fmax(largest, fmax(fmax(fabs((real)(X[i] - ox)), fabs((real)(Y[i] - oy))), fabs((real)(Z[i] - oz))));
            }
            const real scaled = largest * dz;
            const real band = largest * (MESH_BAND_EPSILON * ((real)256 * (scaled * scaled) + (real)8 * fabs(Det.s[l])));
            if (!(fabs(N.s[l]) > band)) *doubt |= 1 << l;
        }
#ifdef PYCLRAY_MESH_EXACT
        *doubt |= rescaled & *hits;
#endif
    }
#endif
    const blockv s = numerator / (inside ? det * Dz : (blockv)(1));
    const blockmask hit = inside && s > (blockv)(0);
    *hits &= mesh_block_bits(hit);
#ifdef PYCLRAY_AOV_SURFACE
    /* the crossings out of the mesh: its outward normal along the ray, n . d = det dz (the
     * projected triangle's signed area along the ray, of the homogeneous shear's scale dz^2) > 0 */
    *leaving = mesh_block_bits(det * Dz > (blockv)(0)) & *hits;
#endif
    return hit ? s : (blockv)(MISS);
}

/* the winner's unit world normal from its float64 vertices (mesh_unit_normal) */
inline vec3v mesh_block_normal(__global const double* block, const int lane)
{
    const int head = as_int2(block[0]).x, count = head & 255, unique = head >> 8;
    __global const double* rows = block + 1;
    __global const uchar* corner = (__global const uchar*)(rows + 3 * unique) + lane;
#define MESH_BLOCK_VERTEX(v) (double3)(rows[corner[(v) * count]], rows[unique + corner[(v) * count]], rows[2 * unique + corner[(v) * count]])
    const double3 n = mesh_unit_normal(MESH_BLOCK_VERTEX(0), MESH_BLOCK_VERTEX(1), MESH_BLOCK_VERTEX(2));
#undef MESH_BLOCK_VERTEX
    return v3((real)n.x, (real)n.y, (real)n.z);
}

/* occupancy's count: a block's crossings in doubt from the ray's own origin (s0 = 0: a moved ray
 * starts before all of the mesh, where no crossing is near 0) make the ray's point undecided
 * (kernels/allhits.cl: HITS_UNDECIDED); its crossings signed, +1 out of the mesh and -1 into it,
 * summed (HITS_SIGNED: the winding number of closed meshes; every hit of a ray from a point
 * counts, its t_max infinite) */
#ifdef PYCLRAY_AOV_SURFACE
#define MESH_BLOCK_DOUBT_STATE , doubt, leaving
#define MESH_BLOCK_DOUBT_ARGUMENT , &doubt, &leaving
#define MESH_BLOCK_DOUBT_TAKE                                                       \
    if (doubt != 0 && s0 == 0.0) HITS_UNDECIDED;                                    \
    HITS_SIGNED(2 * popcount(leaving) - popcount(hits))
#else
#define MESH_BLOCK_DOUBT_STATE
#define MESH_BLOCK_DOUBT_ARGUMENT
#define MESH_BLOCK_DOUBT_TAKE
#endif
/* kernels/rays.h's cast visit of a block (PYCLRAY_CAST_MODE_<type> BLOCKS): its lanes hit, in
 * lane order (the leaf's order: the same winner on an exact tie as one by one) */
#define MESH_BLOCKS(type) ((__global const double*)type##_worlds)
#define PYCLRAY_CAST_TEST_BLOCKS(Type, type)                                        \
    {                                                                               \
        __global const double* block = MESH_BLOCKS(type) + 8 * (size_t)k;           \
        int hits MESH_BLOCK_DOUBT_STATE;                                            \
        MeshBlockLanes lane_s;                                                      \
        lane_s.v = mesh_block_hits(block, &moved, &hits MESH_BLOCK_DOUBT_ARGUMENT); \
        MESH_BLOCK_DOUBT_TAKE                                                       \
        for (; hits != 0; hits &= hits - 1) {                                       \
            const int lane = BVH_LOWEST_BIT(hits);                                  \
            const double t = s0 + (double)lane_s.s[lane] * ray_length;              \
            PYCLRAY_CAST_TAKE(t, as_int2(block[0]).y, KIND_##type, k * 8 + lane, q) \
        }                                                                           \
    }
#define PYCLRAY_CAST_ID_BLOCKS(type, key) as_int2(MESH_BLOCKS(type)[8 * (size_t)((key) >> 3)]).y
#define PYCLRAY_CAST_NORMAL_BLOCKS(Type, type) \
    normal = mesh_block_normal(MESH_BLOCKS(type) + 8 * (size_t)(best_k >> 3), best_k & 7);
/* a leaf's block as it is pushed: 4 cache lines (5 triangles and 7 vertices take 3.4 on average) */
#define PYCLRAY_CAST_PREFETCH_BLOCKS(Type, type) CAST_PREFETCH(MESH_BLOCKS(type) + 8 * (size_t)leaf_k, 256)

/* The barycentrics (u, v) of lane's triangle of a block for the ray (cast's winner): its corners
 * as mesh_block_hits frames them (each vertex minus the moved origin in float64, rounded once) and
 * mesh_barycentric_of's edge functions over their sum. */
inline void mesh_block_barycentric(__global const double* block, const int lane, const RayPacket* ray, real* u, real* v)
{
    const int head = as_int2(block[0]).x, count = head & 255, unique = head >> 8;
    __global const double* rows = block + 1;
    __global const uchar* corner = (__global const uchar*)(rows + 3 * unique) + lane;
    const double3 o = ray->world;
#define MESH_BLOCK_CORNER(k) (real4)((real)(rows[corner[(k) * count]] - o.x), (real)(rows[unique + corner[(k) * count]] - o.y), \
                                     (real)(rows[2 * unique + corner[(k) * count]] - o.z), 1)
    mesh_barycentric_of(MESH_BLOCK_CORNER(0), MESH_BLOCK_CORNER(1), MESH_BLOCK_CORNER(2), ray, u, v);
#undef MESH_BLOCK_CORNER
}
#endif
#endif
