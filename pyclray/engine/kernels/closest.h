/* What every shape's closest-point function returns, and the helpers they share (the closest-point
 * query: kernels/closest.cl, pyclray/engine/queries/closest.py). Float64 throughout, from the point
 * as given and the shapes' float64 world entries: no rebasing, no lanes (one point per work-item).
 *
 * Each shape's kernel file defines, under PYCLRAY_CLOSEST,
 *   ClosestPoint type_closest(__global const TypeWorld* world, double3 p)   the nearest point of its surface
 *   int type_inside(__global const TypeWorld* world, double3 p)             1 where p is in the solid
 *                                                                          (on its surface included), else 0
 * (a shape without an inside, or one decided otherwise, a mesh's by parity or winding, returns 0). */

typedef struct {
    double3 position;     /* the nearest point of the surface */
    double3 normal;       /* the surface's unit geometric normal there (outward, never flipped) */
    double d2;            /* |p - position|^2, or the shape's better conditioned square (a plane's s^2) */
    double2 barycentric;  /* a triangle's (u, v): position = (1 - u - v) a + u b + v c; 0 elsewhere */
} ClosestPoint;

inline double closest_dot(const double3 a, const double3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline double closest_norm2(const double3 a) { return closest_dot(a, a); }

/* a ClosestPoint at q with normal n (d2 measured from p) */
inline ClosestPoint closest_at(const double3 p, const double3 q, const double3 n)
{
    ClosestPoint c;
    c.position = q;
    c.normal = n;
    c.d2 = closest_norm2(p - q);
    c.barycentric = (double2)(0.0, 0.0);
    return c;
}

/* the point of segment a-b nearest p, and its parameter t in [0, 1] (a degenerate segment: a) */
inline double3 closest_on_segment(const double3 p, const double3 a, const double3 b, double* t)
{
    const double3 e = b - a;
    const double e2 = closest_norm2(e);
    double s = e2 > 0.0 ? closest_dot(p - a, e) / e2 : 0.0;
    s = s < 0.0 ? 0.0 : (s > 1.0 ? 1.0 : s);
    *t = s;
    return s == 1.0 ? b : a + s * e;  /* the end itself where clamped to it: no rounding */
}

/* a unit vector perpendicular to the unit vector n (any: for a point on an axis, where every
 * direction of the surface is equally near), chosen from n alone so that it is the same for every point */
inline double3 closest_perpendicular(const double3 n)
{
    const double3 other = fabs(n.x) < 0.5 ? (double3)(1.0, 0.0, 0.0) : (double3)(0.0, 1.0, 0.0);
    const double3 u = cross(n, other);
    return u / sqrt(closest_norm2(u));
}
