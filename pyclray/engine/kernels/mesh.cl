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

#ifndef PYCLRAY_REBASE

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
}

/* a packet's lanes as an array (the double path goes lane by lane: PoCL's code generator rejects
 * 8-wide double conversions) */
typedef union {
    realv v;
    real s[LANES];
} MeshLanes;
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
        MeshLanes Ax, Ay, Bx, By, Cx, Cy, E0, E1, E2;
        Ax.v = ax_; Ay.v = ay_; Bx.v = bx_; By.v = by_; Cx.v = cx_; Cy.v = cy_;
        for (int l = 0; l < LANES; ++l)
            mesh_exact_lane(Ax.s[l], Ay.s[l], Bx.s[l], By.s[l], Cx.s[l], Cy.s[l], &E0.s[l], &E1.s[l], &E2.s[l]);
        e.e0 = E0.v;
        e.e1 = E1.v;
        e.e2 = E2.v;
    }
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
    const intv negative = e.e0 < 0 || e.e1 < 0 || e.e2 < 0;
    const intv positive = e.e0 > 0 || e.e1 > 0 || e.e2 > 0;
    const intv inside = !(negative && positive) && e.det != 0;
    if (!ANY(inside)) return SPLAT(MISS);  /* most tests of a packet miss: no division for them */
    const realv s = e.numerator / (inside ? e.det * e.dz : SPLAT(1));
    return inside && s > 0 ? s : SPLAT(MISS);
}

inline realv mesh_hit(MESH_SPACE const Triangle* tri, const RayPacket* ray)
{
    return mesh_hit_of(tri->a, tri->b, tri->c, ray);
}

#ifdef PYCLRAY_INDEXED
/* An indexed triangle (pyclray/engine/indexed.py) in the frame: its face's vertices as the per-view
 * pass framed them, w 1 (0 for a zero-area triangle, whose face holds ~index: never hit); the world
 * normal in w is the winner's only (mesh_world_normal). */
inline void mesh_assemble(const int4 face, __global const real4* vertices, Triangle* out)
{
    const real valid = face.w >= 0 ? 1 : 0;
    out->a = (real4)(vertices[face.x].xyz, valid);
    out->b = (real4)(vertices[face.y].xyz, valid);
    out->c = (real4)(vertices[face.z].xyz, valid);
}

/* The winner's unit world normal in w, from its float64 world vertices: pyclray.model.shapes.Mesh's
 * face_normals, the same operations in the same order (numpy's cross product, its norm summed x, y,
 * z), no contraction of a * b + c into an fma (here, whatever the rest of the program does): the bits
 * the per-view copy carries. */
inline void mesh_world_normal(Triangle* tri, const int4 face, __global const double4* world)
{
#pragma OPENCL FP_CONTRACT OFF
    const double3 a = world[face.x].xyz, e1 = world[face.y].xyz - a, e2 = world[face.z].xyz - a;
    const double3 n = (double3)(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x);
    const double length = sqrt((n.x * n.x + n.y * n.y) + n.z * n.z);
    tri->a.w = (real)(n.x / length);
    tri->b.w = (real)(n.y / length);
    tri->c.w = (real)(n.z / length);
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
inline vec3v mesh_normal(MESH_SPACE const Triangle* tri, const RayPacket* ray, __global const Camera* camera)
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
