/* Box: the slab test in the box's own axes e_k. A ray origin + s D is inside slab k where
 * lo_k <= s (D . e_k) <= hi_k, with lo_k, hi_k = (C - origin) . e_k -+ size_k / 2 computed on the
 * host in float64 for the frame origin (an eye next to a face keeps its distance to it). The
 * entry is the largest slab entry, the exit the smallest slab exit.
 *
 * Exact for rays parallel to a face: D . e_k = +-0 turns lo_k / 0 and hi_k / 0 into infinities of
 * the right signs (the whole line inside the slab, or none of it). Only an origin exactly on a face
 * plane, running along it, gives 0 / 0 = NaN for one end of that slab: the slab's other end is
 * taken (an edge case where either answer is right). A ray starting inside has entry <= 0 < exit
 * and sees the far side. */

typedef struct {
    realv entry, exit;  /* along the ray, in units of its direction */
    intv entry_axis, exit_axis;
    vec3v along;  /* D . e_k */
} BoxSlabs;

/* one slab k: its entry and exit along the ray, kept where they are the largest entry and the
 * smallest exit so far (the first slab on a tie) */
inline void box_slab(BoxSlabs* slabs, const int k, const realv low, const realv high, const realv along)
{
    const realv t_low = low / along, t_high = high / along;
    /* the nearer and the farther end; a NaN end (0 / 0) gives way to the other */
    const realv near = (t_low < t_high || t_high != t_high) ? t_low : t_high;
    const realv far = (t_low > t_high || t_high != t_high) ? t_low : t_high;
    const intv later = SPLAT_INT(k == 0) || near > slabs->entry;
    const intv sooner = SPLAT_INT(k == 0) || far < slabs->exit;
    slabs->entry = later ? near : slabs->entry;
    slabs->entry_axis = later ? SPLAT_INT(k) : slabs->entry_axis;
    slabs->exit = sooner ? far : slabs->exit;
    slabs->exit_axis = sooner ? SPLAT_INT(k) : slabs->exit_axis;
}

inline BoxSlabs box_slabs(__global const Box* box, const RayPacket* ray)
{
    const vec3v D = ray->dir;
    const vec3v e0 = v3_splat(box->axis0), e1 = v3_splat(box->axis1), e2 = v3_splat(box->axis2);
    BoxSlabs slabs;
    slabs.along = v3(v3_dot(D, e0), v3_dot(D, e1), v3_dot(D, e2));
#ifdef PYCLRAY_CAST
    const vec3v o = v3(v3_dot(ray->origin, e0), v3_dot(ray->origin, e1), v3_dot(ray->origin, e2));
#else
    const vec3v o = v3(SPLAT(0), SPLAT(0), SPLAT(0));  /* camera rays: the offsets as packed */
#endif
    slabs.entry = SPLAT(-MISS);
    slabs.exit = SPLAT(MISS);
    slabs.entry_axis = slabs.exit_axis = SPLAT_INT(0);
    box_slab(&slabs, 0, SPLAT(box->axis0.w) - o.x, SPLAT(box->high.x) - o.x, slabs.along.x);
    box_slab(&slabs, 1, SPLAT(box->axis1.w) - o.y, SPLAT(box->high.y) - o.y, slabs.along.y);
    box_slab(&slabs, 2, SPLAT(box->axis2.w) - o.z, SPLAT(box->high.z) - o.z, slabs.along.z);
    return slabs;
}

/* The entry if it lies ahead, else the exit (from inside: the far side); MISS if the slabs do not
 * overlap ahead. */
inline realv box_hit(__global const Box* box, const RayPacket* ray)
{
    const BoxSlabs slabs = box_slabs(box, ray);
    const realv s = slabs.entry > 0 ? slabs.entry : slabs.exit;
    return (slabs.entry <= slabs.exit && s > 0 && s < MISS) ? s : SPLAT(MISS);
}

/* The outward normal of the face hit: against the ray along the entry slab's axis, with it along
 * the exit slab's; the box's world axes are packed as is, so an unrotated box's normals are exact. */
inline vec3v box_normal(__global const Box* box, const RayPacket* ray, __global const Camera* camera)
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
