/* Box: the slab test in the box's own axes e_k. A ray origin + s D is inside slab k where
 * lo_k <= s (D . e_k) <= hi_k, with lo_k, hi_k = (C - origin) . e_k -+ size_k / 2 computed on the
 * host in float64 for the space origin (an eye next to a face keeps its distance to it). The
 * entry is the largest slab entry, the exit the smallest slab exit: which slabs those are, and
 * whether the ray meets the box, is decided from the ray's point nearest the centre (see
 * box_slabs); the distances come from the packed offsets.
 *
 * Exact for rays parallel to a face: D . e_k = +-0 turns lo_k / 0 and hi_k / 0 into infinities of
 * the right signs (the whole line inside the slab, or none of it). Only an origin exactly on a face
 * plane, running along it, gives 0 / 0 = NaN for one end of that slab: the slab's other end is
 * taken (an edge case where either answer is right). A ray starting inside has entry <= 0 < exit
 * and sees the far side. */

#if defined(PYCLRAY_REBASE) || defined(PYCLRAY_CAST)

/* The box in the camera's space: its centre and axes along the space's axes, and its slabs'
 * offsets (C - origin) . e_k -+ h_k from error-free sums (an eye next to a face keeps its distance). */
inline void box_rebase(__global const BoxWorld* world, PYCLRAY_REBASE_OUT Box* out, const Space* space)
{
    const double3 F = world->center.xyz - space->origin;
    const double3 h = world->half_size.xyz;
    const double3 e0 = world->axis0.xyz, e1 = world->axis1.xyz, e2 = world->axis2.xyz;
    out->center = (real4)(to_space(space, F), 0);
    out->half_size = (real4)(convert_real3(h), 0);
    out->axis0 = (real4)(to_space(space, e0), (real)dot2_4((double4)(F, -h.x), (double4)(e0, 1.0)));
    out->axis1 = (real4)(to_space(space, e1), (real)dot2_4((double4)(F, -h.y), (double4)(e1, 1.0)));
    out->axis2 = (real4)(to_space(space, e2), (real)dot2_4((double4)(F, -h.z), (double4)(e2, 1.0)));
    out->high = (real4)((real)dot2_4((double4)(F, h.x), (double4)(e0, 1.0)),
                        (real)dot2_4((double4)(F, h.y), (double4)(e1, 1.0)),
                        (real)dot2_4((double4)(F, h.z), (double4)(e2, 1.0)), 0);
    out->axis_low0 = (real4)(to_space_low(space, e0), 0);
    out->axis_low1 = (real4)(to_space_low(space, e1), 0);
    out->axis_low2 = (real4)(to_space_low(space, e2), 0);
    out->world_axis0 = (real4)(convert_real3(e0), 0);
    out->world_axis1 = (real4)(convert_real3(e1), 0);
    out->world_axis2 = (real4)(convert_real3(e2), 0);
}

#endif

#if !defined(PYCLRAY_REBASE) && !defined(PYCLRAY_CLOSEST)  /* the ray tests (none in the closest-point query) */

/* a shadow ray leaving its outer side toward the light never meets it again (convex) */
#define PYCLRAY_FLAT_box 0


typedef struct {
    realv entry, exit;  /* along the ray, from the packed offsets (exact for camera rays) */
    intv entry_axis, exit_axis, overlap;
    vec3v along;  /* D . e_k */
} BoxSlabs;

/* one slab k, in the decision's terms (t: along the ray from its point nearest the centre):
 * its entry and exit kept where they are the largest entry and the smallest exit so far (the first
 * slab on a tie) */
inline void box_slab(realv* entry, realv* exit, intv* entry_axis, intv* exit_axis, const int k,
                     const realv low, const realv high, const realv along)
{
    const realv t_low = low / along, t_high = high / along;
    /* the nearer and the farther end; a NaN end (0 / 0) gives way to the other */
    const realv near = (t_low < t_high || t_high != t_high) ? t_low : t_high;
    const realv far = (t_low > t_high || t_high != t_high) ? t_low : t_high;
    const intv later = SPLAT_INT(k == 0) || near > *entry;
    const intv sooner = SPLAT_INT(k == 0) || far < *exit;
    *entry = later ? near : *entry;
    *entry_axis = later ? SPLAT_INT(k) : *entry_axis;
    *exit = sooner ? far : *exit;
    *exit_axis = sooner ? SPLAT_INT(k) : *exit_axis;
}

/* the distance along the ray to face k's plane (the low or the high one) from the packed offsets */
inline realv box_plane(const realv low, const realv high, const realv along, const intv high_side)
{
    return (high_side ? high : low) / along;
}

inline BoxSlabs box_slabs(SHAPE_SPACE const Box* box, const RayPacket* ray)
{
    const vec3v D = ray->dir;
    const vec3v e0 = v3_splat(box->axis0), e1 = v3_splat(box->axis1), e2 = v3_splat(box->axis2);
    BoxSlabs slabs;
    /* D . e_k (a camera ray's face seen at a grazing angle has its distance again from the exact
     * product: box_pixel_distance) */
    slabs.along = v3(v3_dot(D, e0), v3_dot(D, e1), v3_dot(D, e2));
    /* camera rays (from the space's origin): the offsets as packed; cast and shadow rays: their origin's */
    const vec3v zero = v3(SPLAT(0), SPLAT(0), SPLAT(0));
    const vec3v F = FROM_EYE(ray) ? v3_splat(box->center) : v3_sub(v3_splat(box->center), ray->origin);
    const vec3v o = FROM_EYE(ray) ? zero : v3(v3_dot(ray->origin, e0), v3_dot(ray->origin, e1), v3_dot(ray->origin, e2));
    /* Which faces the ray enters and leaves by, and whether it meets the box at all, decided from
     * the ray's point nearest the centre, P = -D x (F x D) / a (from the centre): small coordinates
     * that keep the camera space's digits, where the slab offsets of a far box are large numbers
     * whose rounding would blur its edges. */
    const vec3v P = v3_scale(v3_cross(D, v3_cross(F, D)), SPLAT(-1) / ray->a);
    const vec3v nearest = v3(v3_dot(P, e0), v3_dot(P, e1), v3_dot(P, e2));
    realv t_entry = SPLAT(-MISS), t_exit = SPLAT(MISS);
    slabs.entry_axis = slabs.exit_axis = SPLAT_INT(0);
    box_slab(&t_entry, &t_exit, &slabs.entry_axis, &slabs.exit_axis, 0, SPLAT(-box->half_size.x) - nearest.x, SPLAT(box->half_size.x) - nearest.x, slabs.along.x);
    box_slab(&t_entry, &t_exit, &slabs.entry_axis, &slabs.exit_axis, 1, SPLAT(-box->half_size.y) - nearest.y, SPLAT(box->half_size.y) - nearest.y, slabs.along.y);
    box_slab(&t_entry, &t_exit, &slabs.entry_axis, &slabs.exit_axis, 2, SPLAT(-box->half_size.z) - nearest.z, SPLAT(box->half_size.z) - nearest.z, slabs.along.z);
    slabs.overlap = t_entry <= t_exit;
    /* The distances: the entry and exit faces' planes from the packed offsets (exact for camera
     * rays: an eye next to a face keeps its distance to it). Moving along +e_k the ray enters by the
     * low face and leaves by the high one. */
    const realv along_in = slabs.entry_axis == SPLAT_INT(0) ? slabs.along.x : (slabs.entry_axis == SPLAT_INT(1) ? slabs.along.y : slabs.along.z);
    const realv along_out = slabs.exit_axis == SPLAT_INT(0) ? slabs.along.x : (slabs.exit_axis == SPLAT_INT(1) ? slabs.along.y : slabs.along.z);
    const realv low0 = SPLAT(box->axis0.w) - o.x, low1 = SPLAT(box->axis1.w) - o.y, low2 = SPLAT(box->axis2.w) - o.z;
    const realv high0 = SPLAT(box->high.x) - o.x, high1 = SPLAT(box->high.y) - o.y, high2 = SPLAT(box->high.z) - o.z;
    const realv low_in = slabs.entry_axis == SPLAT_INT(0) ? low0 : (slabs.entry_axis == SPLAT_INT(1) ? low1 : low2);
    const realv high_in = slabs.entry_axis == SPLAT_INT(0) ? high0 : (slabs.entry_axis == SPLAT_INT(1) ? high1 : high2);
    const realv low_out = slabs.exit_axis == SPLAT_INT(0) ? low0 : (slabs.exit_axis == SPLAT_INT(1) ? low1 : low2);
    const realv high_out = slabs.exit_axis == SPLAT_INT(0) ? high0 : (slabs.exit_axis == SPLAT_INT(1) ? high1 : high2);
    slabs.entry = box_plane(low_in, high_in, along_in, along_in < 0);
    slabs.exit = box_plane(low_out, high_out, along_out, along_out > 0);
    return slabs;
}

#ifdef PYCLRAY_PIXEL_EXACT
/* A camera ray's distance s to the face it meets (entering: the entry slab's face, else the exit
 * slab's), again with that slab's D . e_k exact (kernels/lanes.h: pixel_dot) in the lanes where it
 * is below PIXEL_EXACT_COS, as a plane's: a face seen at a grazing angle within a few roundings of
 * its distance. Only the face met pays for it (one product, not the three slabs'): which face that
 * is, and whether the ray meets the box, stay decided by the plain products, which choose otherwise
 * than the exact ones only for a ray within rounding of an edge, where either face is right. */
inline realv box_pixel_distance(SHAPE_SPACE const Box* box, const RayPacket* ray, const BoxSlabs* slabs,
                                const intv entering, const realv s)
{
    const intv k = entering ? slabs->entry_axis : slabs->exit_axis;
    const intv k0 = k == SPLAT_INT(0), k1 = k == SPLAT_INT(1);
    const realv along = k0 ? slabs->along.x : (k1 ? slabs->along.y : slabs->along.z);
    const intv grazing = slabs->overlap && v_abs(along) < SPLAT(PIXEL_EXACT_COS);
    if (!ANY(grazing)) return s;
    const vec3v high = v3_select(v3_select(v3_splat(box->axis2), v3_splat(box->axis1), k1), v3_splat(box->axis0), k0);
    const vec3v low = v3_select(v3_select(v3_splat(box->axis_low2), v3_splat(box->axis_low1), k1), v3_splat(box->axis_low0), k0);
    const realv exact = pixel_dot_lanes(ray, high, low);
    /* the face's offset, as box_slabs takes it: moving along +e_k the ray enters by the low face */
    const intv high_side = entering ? along < 0 : along > 0;
    const realv offset_low = k0 ? SPLAT(box->axis0.w) : (k1 ? SPLAT(box->axis1.w) : SPLAT(box->axis2.w));
    const realv offset_high = k0 ? SPLAT(box->high.x) : (k1 ? SPLAT(box->high.y) : SPLAT(box->high.z));
    /* a lane whose exact product has not the plain one's sign (a ray along the face) keeps the plain s */
    const intv taken = grazing && ((exact > 0) == (along > 0)) && exact != 0;
    return taken ? box_plane(offset_low, offset_high, exact, high_side) : s;
}
#endif

/* The entry if it lies ahead, else the exit (from inside: the far side); MISS if the slabs do not
 * overlap or lie behind. */
inline realv box_hit(SHAPE_SPACE const Box* box, const RayPacket* ray)
{
    const BoxSlabs slabs = box_slabs(box, ray);
    const intv entering = slabs.entry > 0;
    realv s = entering ? slabs.entry : slabs.exit;
#ifdef PYCLRAY_PIXEL_EXACT
    if (FROM_EYE(ray)) s = box_pixel_distance(box, ray, &slabs, entering, s);
#endif
    return (slabs.overlap && s > 0 && s < MISS) ? s : SPLAT(MISS);
}
/* The outward normal of the face hit: against the ray along the entry slab's axis, with it along
 * the exit slab's; the box's world axes are packed as is, so an unrotated box's normals are exact. */
inline vec3v box_normal(SHAPE_SPACE const Box* box, const RayPacket* ray, const Basis* basis)
{
    const BoxSlabs slabs = box_slabs(box, ray);
    const intv entering = slabs.entry > 0;
    const intv k = entering ? slabs.entry_axis : slabs.exit_axis;
    const realv along = k == SPLAT_INT(0) ? slabs.along.x : (k == SPLAT_INT(1) ? slabs.along.y : slabs.along.z);
    const vec3v e = v3_select(v3_select(v3_splat(box->world_axis2), v3_splat(box->world_axis1), k == SPLAT_INT(1)),
                              v3_splat(box->world_axis0), k == SPLAT_INT(0));
    /* entering while moving along +e (or leaving while moving along -e): the -e face */
    const realv sign = (along > 0) == entering ? SPLAT(-1) : SPLAT(1);
    return v3_scale(e, sign);
}

#ifdef PYCLRAY_ALL_HITS
/* Every hit s > 0 along the ray (count_hits, all_hits: kernels/allhits.cl): the entry and the exit
 * where the slabs overlap with entry < exit, none where they do not or only touch (a ray grazing an
 * edge or a corner counts 0, never 1); one behind the origin (from inside: the entry) is MISS. */
inline void box_hits(SHAPE_SPACE const Box* box, const RayPacket* ray, realv* first, realv* second)
{
    const BoxSlabs slabs = box_slabs(box, ray);
    const intv crosses = slabs.overlap && slabs.entry < slabs.exit;
    *first = crosses && slabs.entry > 0 ? slabs.entry : SPLAT(MISS);
    *second = crosses && slabs.exit > 0 && slabs.exit < MISS ? slabs.exit : SPLAT(MISS);
}
#endif

#endif

#ifdef PYCLRAY_CLOSEST
/* The box's nearest point, in its own axes (l_k = (p - C).e_k): outside, each coordinate clamped to
 * [-h_k, h_k]; inside, moved onto the nearest face. The normal is the face's along which p lies
 * farthest beyond (or least within) its half size, |l_k| - h_k largest (the lowest axis on a tie),
 * on the side of l_k (+ for 0). */
inline ClosestPoint box_closest(__global const BoxWorld* world, const double3 p)
{
    const double3 F = p - world->center.xyz, h = world->half_size.xyz;
    const double3 e0 = world->axis0.xyz, e1 = world->axis1.xyz, e2 = world->axis2.xyz;
    double3 l = (double3)(closest_dot(F, e0), closest_dot(F, e1), closest_dot(F, e2));
    const double3 beyond = fabs(l) - h;
    const int face = beyond.x >= beyond.y ? (beyond.x >= beyond.z ? 0 : 2) : (beyond.y >= beyond.z ? 1 : 2);
    const double sign_x = l.x < 0.0 ? -1.0 : 1.0, sign_y = l.y < 0.0 ? -1.0 : 1.0, sign_z = l.z < 0.0 ? -1.0 : 1.0;
    const bool inside = beyond.x <= 0.0 && beyond.y <= 0.0 && beyond.z <= 0.0;
    double3 q = clamp(l, -h, h);
    double3 n;
    if (face == 0) { n = sign_x * e0; if (inside) q.x = sign_x * h.x; }
    else if (face == 1) { n = sign_y * e1; if (inside) q.y = sign_y * h.y; }
    else { n = sign_z * e2; if (inside) q.z = sign_z * h.z; }
    ClosestPoint c = closest_at(p, world->center.xyz + (q.x * e0 + q.y * e1) + q.z * e2, n);
    if (inside) {  /* the nearest face's distance itself, better conditioned */
        const double d = face == 0 ? beyond.x : (face == 1 ? beyond.y : beyond.z);
        c.d2 = d * d;
    } else {
        const double3 out = fmax(beyond, (double3)(0.0));
        c.d2 = closest_norm2(out);
    }
    return c;
}

inline int box_inside(__global const BoxWorld* world, const double3 p)
{
    const double3 F = p - world->center.xyz, h = world->half_size.xyz;
    return fabs(closest_dot(F, world->axis0.xyz)) <= h.x && fabs(closest_dot(F, world->axis1.xyz)) <= h.y
        && fabs(closest_dot(F, world->axis2.xyz)) <= h.z;
}
#endif
