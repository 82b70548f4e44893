/* Triangle (one entry of pyclray.Mesh): vertices a, b, c in the frame, its unit world normal in w.
 *
 * The watertight test of Woop, Benthin and Wald (2013), as pbrt-v4's IntersectTriangle: the vertices
 * relative to the ray's origin, the axes permuted (per lane) so that the ray's largest component is
 * z, sheared so that the ray runs along z, then three 2D edge functions whose signs say which side
 * of each edge the ray passes. A shared edge gives its two triangles the same edge function with the
 * opposite sign, bit for bit (products commute and a - b = -(b - a) in IEEE arithmetic), so a ray is
 * never let through between them; an edge function that rounds to 0 is recomputed exactly (float
 * products are exact in double) before its sign is trusted.
 *
 * The shear is written without division (homogeneous form): with the permuted direction (dx, dy, dz),
 * each vertex p projects to (px dz - pz dx, py dz - pz dy), which is dz times pbrt's sheared (x, y);
 * the edge functions are dz^2 times pbrt's and the distance is
 *     s = (e0 a.z + e1 b.z + e2 c.z) / (dz (e0 + e1 + e2)),
 * the same quotient as pbrt's (e0 a'z + e1 b'z + e2 c'z) / det with a'z = a.z / dz. The projection
 * of a vertex depends on the vertex and the ray only, which is what watertightness needs.
 *
 * The vertices come from float64 world coordinates minus the frame's origin (the eye, or a cast's
 * anchor of the whole mesh), rounded once: far from the world's origin a triangle keeps float32's
 * relative precision, and a vertex shared by two triangles has the same bits in both. */

#if defined(PYCLRAY_REBASE) || defined(PYCLRAY_CAST)

/* the triangle in a frame: the per-view pass's (the eye, the camera's axes) or a cast's (the ray's
 * origin moved next to the mesh's anchor, the same for all its triangles: kernels/cast.h) */
inline void mesh_rebase(__global const TriangleWorld* world, PYCLRAY_FRAME_OUT Triangle* out, const Frame* frame)
{
    out->a = (real4)(to_frame(frame, world->a.xyz - frame->origin), (real)world->a.w);
    out->b = (real4)(to_frame(frame, world->b.xyz - frame->origin), (real)world->b.w);
    out->c = (real4)(to_frame(frame, world->c.xyz - frame->origin), (real)world->c.w);
}

#endif

#if !defined(PYCLRAY_REBASE) && !defined(PYCLRAY_CLOSEST)  /* the ray tests (none in the closest-point query) */

/* where the mesh functions read a triangle: an indexed program's are assembled in private memory
 * where tested (PYCLRAY_INDEXED: every indexed type of the program is), the others' where SHAPE_SPACE says */
#ifdef PYCLRAY_INDEXED
#define MESH_SPACE
#else
#define MESH_SPACE SHAPE_SPACE
#endif

/* a shadow ray leaving a triangle on either side never meets that triangle again (flat); its
 * neighbours are tested as every other shape is */
#define PYCLRAY_FLAT_mesh 1

#if !defined(PYCLRAY_FP64) && defined(cl_khr_fp64)
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#define PYCLRAY_MESH_EXACT 1  /* float edge functions that round to 0 are recomputed in double */

/* one lane's three edge functions from its projected vertices, exactly signed: float products are
 * exact in double, so each difference rounds once and keeps its sign; scaled by the largest, so that
 * none underflows back in float (a common factor changes neither the signs nor the distance) */
inline void mesh_exact_lane(const float ax, const float ay, const float bx, const float by, const float cx,
                            const float cy, float* e0, float* e1, float* e2)
{
    const double d0 = (double)bx * (double)cy - (double)by * (double)cx;
    const double d1 = (double)cx * (double)ay - (double)cy * (double)ax;
    const double d2 = (double)ax * (double)by - (double)ay * (double)bx;
    const double m0 = d0 < 0 ? -d0 : d0, m1 = d1 < 0 ? -d1 : d1, m2 = d2 < 0 ? -d2 : d2;
    const double largest = m0 > m1 ? (m0 > m2 ? m0 : m2) : (m1 > m2 ? m1 : m2);
    const double inverse = largest > 0 ? 1.0 / largest : 1.0;
    *e0 = (float)(d0 * inverse);
    *e1 = (float)(d1 * inverse);
    *e2 = (float)(d2 * inverse);
#ifdef PYCLRAY_TIE_RULE
    /* a sign the scaling would lose (below float's least subnormal): kept, for the tie rule */
    if (*e0 == 0 && d0 != 0) *e0 = d0 > 0 ? 0x1p-149f : -0x1p-149f;
    if (*e1 == 0 && d1 != 0) *e1 = d1 > 0 ? 0x1p-149f : -0x1p-149f;
    if (*e2 == 0 && d2 != 0) *e2 = d2 > 0 ? 0x1p-149f : -0x1p-149f;
#endif
}

#endif
#if defined(PYCLRAY_MESH_EXACT) || (defined(PYCLRAY_TIE_RULE) && defined(PYCLRAY_FP64))
/* a packet's lanes as an array (the double path goes lane by lane: PoCL's code generator rejects
 * 8-wide double conversions) */
typedef union {
    realv v;
    real s[LANES];
} MeshLanes;
#endif

#ifdef PYCLRAY_TIE_RULE
/* The tie rule of the hit counts (count_hits, all_hits: kernels/allhits.cl), so that each crossing of
 * a mesh's surface counts once. The ray's projected point (0, 0) is taken as moved by (eps, eps^2),
 * eps infinitesimal, in the projected plane (simulation of simplicity, the rasterizer's top-left
 * rule): an edge function e = p x q (p, q its projected endpoints in the triangle's order) that is
 * exactly 0 takes the sign of its change, (q - p) x (eps, eps^2) = -(qy - py) eps + (qx - px) eps^2:
 * that of py - qy, or where py == qy of qx - px (comparisons: exact). Every triangle sees the same
 * moved point, the edge of two triangles has the same endpoints (opposite order) in both, so a ray
 * through a shared edge is inside exactly one of two triangles that lie on both sides of it (two or
 * none where both lie on one side: a silhouette), and a ray through a shared vertex inside exactly
 * one triangle of a fan around it: the count is that of a ray in general position. An edge whose
 * endpoints project to one point never counts (its triangles have no projected area). The signs
 * themselves are exact (see mesh_exact_lane and mesh_exact_edge64). */
#define MESH_TIE_POSITIVE(e, px, py, qx, qy) ((e) > 0 || ((e) == 0 && ((py) > (qy) || ((py) == (qy) && (qx) > (px)))))
#define MESH_TIE_NEGATIVE(e, px, py, qx, qy) ((e) < 0 || ((e) == 0 && ((py) < (qy) || ((py) == (qy) && (qx) < (px)))))
/* all three edge functions (e0: b to c, e1: c to a, e2: a to b) of one sign under the rule */
#define MESH_TIE_INSIDE(e0, e1, e2, ax, ay, bx, by, cx, cy)                                              \
    ((MESH_TIE_POSITIVE(e0, bx, by, cx, cy) && MESH_TIE_POSITIVE(e1, cx, cy, ax, ay) && MESH_TIE_POSITIVE(e2, ax, ay, bx, by)) \
     || (MESH_TIE_NEGATIVE(e0, bx, by, cx, cy) && MESH_TIE_NEGATIVE(e1, cx, cy, ax, ay) && MESH_TIE_NEGATIVE(e2, ax, ay, bx, by)))
#ifdef PYCLRAY_FP64
/* px qy - py qx where its float64 form rounded to 0 (the products are then equal): the difference of
 * the products' exact rounding errors (fused multiply-adds), which is the exact value rounded once,
 * its sign exact; the other triangle of the edge computes its negation, bit for bit */
#ifdef PYCLRAY_INLINE_BUILTINS
#define MESH_FMA(a, b, c) __builtin_fma(a, b, c)
#else
#define MESH_FMA(a, b, c) fma(a, b, c)
#endif
inline double mesh_exact_edge64(const double px, const double py, const double qx, const double qy)
{
    const double product = px * qy;
    return MESH_FMA(px, qy, -product) - MESH_FMA(py, qx, -product);
}
#endif
#endif

#if defined(PYCLRAY_FP64) || defined(cl_khr_fp64)
/* A triangle's unit normal normalize(cross(b - a, c - a)) from its float64 vertices:
 * pyclray.model.shapes.Mesh's face_normals, the same operations in the same order (numpy's cross
 * product, its norm summed x, y, z), no contraction of a * b + c into an fma (here, whatever the rest
 * of the program does): the bits the per-view copy carries. The winner's normal of an indexed mesh
 * (mesh_world_normal), of cast's blocks (mesh_block_normal) and of mesh instances, in object space
 * (kernels/instance.cl). The square root is the compiler's on PoCL's CPU device (the library's is a
 * call there: kernels/lanes.h's v_sqrt), with the same IEEE result. */
inline double3 mesh_unit_normal(const double3 a, const double3 b, const double3 c)
{
#pragma OPENCL FP_CONTRACT OFF
    const double3 e1 = b - a, e2 = c - a;
    const double3 n = (double3)(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x);
#ifdef PYCLRAY_INLINE_BUILTINS
    return n / __builtin_sqrt((n.x * n.x + n.y * n.y) + n.z * n.z);
#else
    return n / sqrt((n.x * n.x + n.y * n.y) + n.z * n.z);
#endif
}
#endif

/* kz = 0: (y, z, x); kz = 1: (z, x, y); kz = 2: as is (cyclic: the handedness is kept) */
inline vec3v mesh_permute(const vec3v v, const intv z_is_x, const intv z_is_y)
{
    return v3(z_is_x ? v.y : (z_is_y ? v.z : v.x), z_is_x ? v.z : (z_is_y ? v.x : v.y),
              z_is_x ? v.x : (z_is_y ? v.y : v.z));
}

/* The edge functions e0, e1, e2 (e_k: of the edge facing vertex k), their sum det, the numerator
 * of the distance, and dz; a lane misses where the signs differ or det is 0. */
typedef struct {
    realv e0, e1, e2, det, numerator, dz;
#ifdef PYCLRAY_TIE_RULE
    intv inside;  /* the tie rule's (MESH_TIE_INSIDE) */
#endif
} MeshEdges;

/* (the triangle's vertices by value: mesh instances frame theirs in private memory, kernels/instance.cl) */
inline MeshEdges mesh_edges_of(const real4 a, const real4 b, const real4 c, const RayPacket* ray)
{
    vec3v A = v3_splat(a), B = v3_splat(b), C = v3_splat(c), D = ray->dir;
    if (!FROM_EYE(ray)) {  /* camera rays start at the frame's origin: the vertices are relative to it */
        A = v3_sub(A, ray->origin);
        B = v3_sub(B, ray->origin);
        C = v3_sub(C, ray->origin);
    }
    /* the largest |component| of the direction becomes z (pbrt's MaxComponentIndex: ties go to z, then y) */
    const realv ax = v_abs(D.x), ay = v_abs(D.y), az = v_abs(D.z);
    const intv z_is_x = ax > ay && ax > az;
    const intv z_is_y = !(ax > ay) && ay > az;
    if (ANY(z_is_x || z_is_y)) {  /* most camera packets look along z: no selects for them */
        A = mesh_permute(A, z_is_x, z_is_y);
        B = mesh_permute(B, z_is_x, z_is_y);
        C = mesh_permute(C, z_is_x, z_is_y);
        D = mesh_permute(D, z_is_x, z_is_y);
    }
    /* the homogeneous shear: dz times pbrt's sheared x and y */
    const realv ax_ = A.x * D.z - A.z * D.x, ay_ = A.y * D.z - A.z * D.y;
    const realv bx_ = B.x * D.z - B.z * D.x, by_ = B.y * D.z - B.z * D.y;
    const realv cx_ = C.x * D.z - C.z * D.x, cy_ = C.y * D.z - C.z * D.y;
    MeshEdges e;
    e.e0 = bx_ * cy_ - by_ * cx_;
    e.e1 = cx_ * ay_ - cy_ * ax_;
    e.e2 = ax_ * by_ - ay_ * bx_;
#ifdef PYCLRAY_MESH_EXACT
    if (ANY(e.e0 == 0 || e.e1 == 0 || e.e2 == 0)) {
        /* those lanes only (as cast's blocks): a lane's bits never depend on the other lanes' rays
         * (rescaled because another lane's edge function rounded to 0, a pixel's s could differ
         * from the same ray's in a packet of other rays: on a device of another lane width) */
        MeshLanes Ax, Ay, Bx, By, Cx, Cy, E0, E1, E2;
        Ax.v = ax_; Ay.v = ay_; Bx.v = bx_; By.v = by_; Cx.v = cx_; Cy.v = cy_;
        E0.v = e.e0; E1.v = e.e1; E2.v = e.e2;
        for (int l = 0; l < LANES; ++l)
            if (E0.s[l] == 0 || E1.s[l] == 0 || E2.s[l] == 0)
                mesh_exact_lane(Ax.s[l], Ay.s[l], Bx.s[l], By.s[l], Cx.s[l], Cy.s[l], &E0.s[l], &E1.s[l], &E2.s[l]);
        e.e0 = E0.v;
        e.e1 = E1.v;
        e.e2 = E2.v;
    }
#endif
#if defined(PYCLRAY_TIE_RULE) && defined(PYCLRAY_FP64)
    if (ANY(e.e0 == 0 || e.e1 == 0 || e.e2 == 0)) {  /* those lanes' zeros exactly signed */
        MeshLanes Ax, Ay, Bx, By, Cx, Cy, E0, E1, E2;
        Ax.v = ax_; Ay.v = ay_; Bx.v = bx_; By.v = by_; Cx.v = cx_; Cy.v = cy_;
        E0.v = e.e0; E1.v = e.e1; E2.v = e.e2;
        for (int l = 0; l < LANES; ++l) {
            if (E0.s[l] == 0) E0.s[l] = mesh_exact_edge64(Bx.s[l], By.s[l], Cx.s[l], Cy.s[l]);
            if (E1.s[l] == 0) E1.s[l] = mesh_exact_edge64(Cx.s[l], Cy.s[l], Ax.s[l], Ay.s[l]);
            if (E2.s[l] == 0) E2.s[l] = mesh_exact_edge64(Ax.s[l], Ay.s[l], Bx.s[l], By.s[l]);
        }
        e.e0 = E0.v;
        e.e1 = E1.v;
        e.e2 = E2.v;
    }
#endif
#ifdef PYCLRAY_TIE_RULE
    e.inside = MESH_TIE_INSIDE(e.e0, e.e1, e.e2, ax_, ay_, bx_, by_, cx_, cy_);
#endif
    e.det = (e.e0 + e.e1) + e.e2;
    e.numerator = (e.e0 * A.z + e.e1 * B.z) + e.e2 * C.z;
    e.dz = D.z;
    return e;
}

inline MeshEdges mesh_edges(MESH_SPACE const Triangle* tri, const RayPacket* ray)
{
    return mesh_edges_of(tri->a, tri->b, tri->c, ray);
}

/* Per lane the distance s > 0 along ray->dir, or MISS. Zero-area triangles (a zero world normal)
 * are never hit; no lane divides by 0 (det != 0, and dz, the largest component, is not 0). */
inline realv mesh_hit_of(const real4 a, const real4 b, const real4 c, const RayPacket* ray)
{
    if (a.w == 0 && b.w == 0 && c.w == 0) return SPLAT(MISS);
    const MeshEdges e = mesh_edges_of(a, b, c, ray);
#ifdef PYCLRAY_TIE_RULE
    const intv inside = e.inside && e.det != 0;
#else
    const intv negative = e.e0 < 0 || e.e1 < 0 || e.e2 < 0;
    const intv positive = e.e0 > 0 || e.e1 > 0 || e.e2 > 0;
    const intv inside = !(negative && positive) && e.det != 0;
#endif
    if (!ANY(inside)) return SPLAT(MISS);  /* most tests of a packet miss: no division for them */
    const realv s = e.numerator / (inside ? e.det * e.dz : SPLAT(1));
    return inside && s > 0 ? s : SPLAT(MISS);
}

inline realv mesh_hit(MESH_SPACE const Triangle* tri, const RayPacket* ray)
{
    return mesh_hit_of(tri->a, tri->b, tri->c, ray);
}

#ifdef PYCLRAY_INDEXED
/* An indexed triangle (pyclray/engine/scene/indexed.py) in the frame: its face's vertices as the per-view
 * pass framed them, w 1 (0 for a zero-area triangle, whose face holds ~index: never hit); the world
 * normal in w is the winner's only (mesh_world_normal). */
inline void mesh_assemble(const int4 face, __global const real4* vertices, Triangle* out)
{
    const real valid = face.w >= 0 ? 1 : 0;
    out->a = (real4)(vertices[face.x].xyz, valid);
    out->b = (real4)(vertices[face.y].xyz, valid);
    out->c = (real4)(vertices[face.z].xyz, valid);
}

/* The winner's unit world normal in w, from its float64 world vertices (mesh_unit_normal) */
inline void mesh_world_normal(Triangle* tri, const int4 face, __global const double4* world)
{
    const double3 n = mesh_unit_normal(world[face.x].xyz, world[face.y].xyz, world[face.z].xyz);
    tri->a.w = (real)n.x;
    tri->b.w = (real)n.y;
    tri->c.w = (real)n.z;
}
#ifdef PYCLRAY_SMOOTH
/* an indexed triangle's vertex normals (smooth shading: one per shared vertex, zero for a flat mesh's) */
inline TriangleNormals mesh_smooth_of(const int4 face, __global const real4* normals)
{
    TriangleNormals out;
    out.a = normals[face.x];
    out.b = normals[face.y];
    out.c = normals[face.z];
    return out;
}
#endif
#endif

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
 * kernels/mesh.cl as cast runs it on a framed copy: its vertices minus the ray's moved origin in
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

/* Per lane the triangle's s > 0 along ray->dir from ray->world (the moved origin), else MISS; the
 * lanes hit, as bits, in *hits. */
inline blockv mesh_block_hits(__global const double* block, const RayPacket* ray, int* hits)
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
    if (!*hits) return (blockv)(MISS);  /* most blocks a ray reaches it misses: no division */
    const blockv numerator = (e0 * Az + e1 * Bz) + e2 * Cz;
    const blockv s = numerator / (inside ? det * Dz : (blockv)(1));
    const blockmask hit = inside && s > (blockv)(0);
    *hits &= mesh_block_bits(hit);
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

/* kernels/rays.h's cast visit of a block (PYCLRAY_CAST_MODE_<type> BLOCKS): its lanes hit, in
 * lane order (the leaf's order: the same winner on an exact tie as one by one) */
#define MESH_BLOCKS(type) ((__global const double*)type##_worlds)
#define PYCLRAY_CAST_TEST_BLOCKS(Type, type)                                        \
    {                                                                               \
        __global const double* block = MESH_BLOCKS(type) + 8 * (size_t)k;           \
        int hits;                                                                   \
        MeshBlockLanes lane_s;                                                      \
        lane_s.v = mesh_block_hits(block, &moved, &hits);                           \
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
#endif

/* The unit world normal normalize(cross(b - a, c - a)), computed in float64 on the host. */
inline vec3v mesh_normal(MESH_SPACE const Triangle* tri, const RayPacket* ray, const Basis* basis)
{
    return v3(SPLAT(tri->a.w), SPLAT(tri->b.w), SPLAT(tri->c.w));
}

/* The barycentric coordinates (u, v) of the hit, hit = (1 - u - v) a + u b + v c: e1 / det, e2 / det. */
inline void mesh_barycentric_of(const real4 a, const real4 b, const real4 c, const RayPacket* ray, realv* u, realv* v)
{
    const MeshEdges e = mesh_edges_of(a, b, c, ray);
    const realv det = e.det != 0 ? e.det : SPLAT(1);
    *u = e.e1 / det;
    *v = e.e2 / det;
}

inline void mesh_barycentric(MESH_SPACE const Triangle* tri, const RayPacket* ray, realv* u, realv* v)
{
    mesh_barycentric_of(tri->a, tri->b, tri->c, ray, u, v);
}

#ifdef PYCLRAY_CAST
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

#ifdef PYCLRAY_SMOOTH
/* Smooth shading: the unit world vertex normals interpolated at the hit's barycentrics,
 * (1 - u - v) n_a + u n_b + v n_c, normalized; (0, 0, 0) (the geometric normal lights) where the
 * mesh is flat (its normals are 0) or the interpolation is 0 (opposite vertex normals). */
inline vec3v mesh_shading_normal(MESH_SPACE const Triangle* tri, const RayPacket* ray, const TriangleNormals* normals)
{
    realv u, v;
    mesh_barycentric(tri, ray, &u, &v);
    const realv w = (SPLAT(1) - u) - v;
    const real4 na = normals->a, nb = normals->b, nc = normals->c;
    const vec3v n = v3((w * na.x + u * nb.x) + v * nc.x, (w * na.y + u * nb.y) + v * nc.y, (w * na.z + u * nb.z) + v * nc.z);
    const realv length2 = v3_dot(n, n);
    return v3_scale(n, length2 > 0 ? SPLAT(1) / v_sqrt(length2) : SPLAT(0));
}
#endif

#endif

#ifdef PYCLRAY_CLOSEST
/* A triangle's nearest point (Ericson, Real-Time Collision Detection, 5.1.5): which of its Voronoi
 * regions p lies in (a vertex, an edge, the face), from the signs of dot products of p - vertex with
 * the edges, and there the nearest point with its barycentrics (u, v): (1 - u - v) a + u b + v c.
 * A zero-area triangle (its normal in w is 0) is its three edges as segments. The normal is the
 * triangle's unit world normal (w of its vertices), whichever region. */
inline ClosestPoint mesh_closest(__global const TriangleWorld* t, const double3 p)
{
    const double3 a = t->a.xyz, b = t->b.xyz, c = t->c.xyz;
    const double3 n = (double3)(t->a.w, t->b.w, t->c.w);
    ClosestPoint out;
    if (n.x == 0.0 && n.y == 0.0 && n.z == 0.0) {  /* degenerate: the nearest of its edges */
        double s0, s1, s2;
        const double3 q0 = closest_on_segment(p, a, b, &s0), q1 = closest_on_segment(p, b, c, &s1),
                      q2 = closest_on_segment(p, c, a, &s2);
        out = closest_at(p, q0, n);
        out.barycentric = (double2)(s0, 0.0);
        const double d1 = closest_norm2(p - q1), d2 = closest_norm2(p - q2);
        if (d1 < out.d2) { out.position = q1; out.d2 = d1; out.barycentric = (double2)(1.0 - s1, s1); }
        if (d2 < out.d2) { out.position = q2; out.d2 = d2; out.barycentric = (double2)(0.0, 1.0 - s2); }
        return out;
    }
    const double3 ab = b - a, ac = c - a, ap = p - a;
    double u, v;
    const double d1 = closest_dot(ab, ap), d2 = closest_dot(ac, ap);
    if (d1 <= 0.0 && d2 <= 0.0) { u = 0.0; v = 0.0; }  /* vertex a */
    else {
        const double3 bp = p - b;
        const double d3 = closest_dot(ab, bp), d4 = closest_dot(ac, bp);
        const double3 cp = p - c;
        const double d5 = closest_dot(ab, cp), d6 = closest_dot(ac, cp);
        const double vc = d1 * d4 - d3 * d2, vb = d5 * d2 - d1 * d6, va = d3 * d6 - d5 * d4;
        if (d3 >= 0.0 && d4 <= d3) { u = 1.0; v = 0.0; }  /* vertex b */
        else if (d6 >= 0.0 && d5 <= d6) { u = 0.0; v = 1.0; }  /* vertex c */
        else if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) { u = d1 / (d1 - d3); v = 0.0; }  /* edge ab */
        else if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) { u = 0.0; v = d2 / (d2 - d6); }  /* edge ac */
        else if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {  /* edge bc */
            v = (d4 - d3) / ((d4 - d3) + (d5 - d6));
            u = 1.0 - v;
        } else {  /* the face */
            const double denominator = 1.0 / (va + vb + vc);
            u = vb * denominator;
            v = vc * denominator;
        }
    }
    /* the vertices themselves in their regions (no rounding there) */
    const double3 q = (u == 0.0 && v == 0.0) ? a : (u == 1.0 ? b : (v == 1.0 ? c : a + u * ab + v * ac));
    out = closest_at(p, q, n);
    out.barycentric = (double2)(u, v);
    if (u > 0.0 && v > 0.0 && u + v < 1.0) {  /* over the face: the plane's distance, better conditioned */
        const double s = closest_dot(ap, n);
        out.d2 = s * s;
    }
    return out;
}

inline int mesh_inside(__global const TriangleWorld* t, const double3 p) { return 0; }  /* by parity or winding */

/* The solid angle of the triangle seen from p, signed (positive where p is behind its outward
 * normal), van Oosterom and Strackee (1983): 2 atan2(a.(b x c), |a||b||c| + (a.b)|c| + (b.c)|a| + (c.a)|b|)
 * with a, b, c the vertices from p. The generalized winding number is the sum over 4 pi. */
inline double mesh_solid_angle(__global const TriangleWorld* t, const double3 p)
{
    const double3 a = t->a.xyz - p, b = t->b.xyz - p, c = t->c.xyz - p;
    const double la = sqrt(closest_norm2(a)), lb = sqrt(closest_norm2(b)), lc = sqrt(closest_norm2(c));
    const double numerator = closest_dot(a, cross(b, c));
    const double denominator = la * lb * lc + closest_dot(a, b) * lc + closest_dot(b, c) * la + closest_dot(c, a) * lb;
    return 2.0 * atan2(numerator, denominator);
}
#endif
