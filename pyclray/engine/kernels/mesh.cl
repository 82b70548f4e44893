/* Triangle (one entry of pyclray.Mesh): vertices a, b, c in the space, its unit world normal in w.
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
 * The vertices come from float64 world coordinates minus the space's origin (the eye, or a cast's
 * anchor of the whole mesh), rounded once: far from the world's origin a triangle keeps float32's
 * relative precision, and a vertex shared by two triangles has the same bits in both. */

#if defined(PYCLRAY_REBASE) || defined(PYCLRAY_CAST)

/* the triangle in a space: the per-view pass's (the eye, the camera's axes) or a cast's (the ray's
 * origin moved next to the mesh's anchor, the same for all its triangles: kernels/cast.h) */
inline void mesh_rebase(__global const TriangleWorld* world, PYCLRAY_REBASE_OUT Triangle* out, const Space* space)
{
    out->a = (real4)(to_space(space, world->a.xyz - space->origin), (real)world->a.w);
    out->b = (real4)(to_space(space, world->b.xyz - space->origin), (real)world->b.w);
    out->c = (real4)(to_space(space, world->c.xyz - space->origin), (real)world->c.w);
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

/* (the triangle's vertices by value: mesh instances rebase theirs in private memory, kernels/instance.cl) */
inline MeshEdges mesh_edges_of(const real4 a, const real4 b, const real4 c, const RayPacket* ray)
{
    vec3v A = v3_splat(a), B = v3_splat(b), C = v3_splat(c), D = ray->dir;
    if (!FROM_EYE(ray)) {  /* camera rays start at the space's origin: the vertices are relative to it */
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
/* An indexed triangle (pyclray/engine/scene/indexed.py) in the space: its face's vertices as the per-view
 * pass rebased them, w 1 (0 for a zero-area triangle, whose face holds ~index: never hit); the world
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
