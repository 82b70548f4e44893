/* A triangle's nearest point (the closest-point query: PYCLRAY_CLOSEST, kernels/closest.cl). */

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
