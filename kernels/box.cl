/* Box: the slab test in the box's own axes e_k. A ray origin + s D is inside slab k where
 * lo_k <= s (D . e_k) <= hi_k, with lo_k, hi_k = (C - origin) . e_k -+ size_k / 2 computed on the
 * host in float64 for the frame origin (an eye next to a face keeps its distance to it). The
 * entry is the largest slab entry, the exit the smallest slab exit.
 *
 * Exact for rays parallel to a face: D . e_k = +-0 turns lo_k / 0 and hi_k / 0 into infinities of
 * the right signs (the whole line inside the slab, or none of it); only an origin exactly on a
 * face plane, running along it, gives 0 / 0 = NaN, which fmin and fmax drop (an edge case where
 * either answer is right). A ray starting inside has entry <= 0 < exit and sees the far side. */

typedef struct {
    real entry, exit;  /* along the ray, in units of its (unit) direction */
    int entry_axis, exit_axis;
    real3 dots;  /* D . e_k */
} BoxSlabs;

/* one slab: the entry and exit distances along the ray (low, high: its offsets from the origin) */
#define BOX_SLAB(k, low, high, along)                                                     \
    {                                                                                     \
        const real t_low = (low) / (along), t_high = (high) / (along);                   \
        const real near = fmin(t_low, t_high), far = fmax(t_low, t_high);                \
        if (k == 0 || near > slabs.entry) { slabs.entry = near; slabs.entry_axis = k; }   \
        if (k == 0 || far < slabs.exit) { slabs.exit = far; slabs.exit_axis = k; }        \
    }

inline BoxSlabs box_slabs(__global const Box* box, const Ray* ray)
{
    const real3 D = ray->dir;
    BoxSlabs slabs;
    slabs.dots = (real3)(dot(D, box->axis0.xyz), dot(D, box->axis1.xyz), dot(D, box->axis2.xyz));
#ifdef PYCLRAY_CAST
    const real3 o = (real3)(dot(ray->origin, box->axis0.xyz), dot(ray->origin, box->axis1.xyz),
                            dot(ray->origin, box->axis2.xyz));
#else
    const real3 o = (real3)(0, 0, 0);  /* camera rays start at the frame origin: the offsets as packed */
#endif
    /* the largest entry and the smallest exit, and the slabs they come from (first on a tie; a NaN
     * entry or exit of a ray along a face plane is never taken over another slab's) */
    slabs.entry = -MISS; slabs.exit = MISS; slabs.entry_axis = 0; slabs.exit_axis = 0;
    BOX_SLAB(0, box->axis0.w - o.x, box->high.x - o.x, slabs.dots.x)
    BOX_SLAB(1, box->axis1.w - o.y, box->high.y - o.y, slabs.dots.y)
    BOX_SLAB(2, box->axis2.w - o.z, box->high.z - o.z, slabs.dots.z)
    return slabs;
}
#undef BOX_SLAB

/* The entry if it lies ahead, else the exit (from inside: the far side); MISS if the slabs do not
 * overlap ahead. */
inline real box_hit(__global const Box* box, const Ray* ray)
{
    const BoxSlabs slabs = box_slabs(box, ray);
    const real s = slabs.entry > 0 ? slabs.entry : slabs.exit;
    return (slabs.entry <= slabs.exit && s > 0) ? s : MISS;
}

/* The outward normal of the face hit: against the ray along the entry slab's axis, with it along
 * the exit slab's; the box's world axes are packed as is, so an unrotated box's normals are exact. */
inline real3 box_normal(__global const Box* box, const Ray* ray, __global const Camera* camera)
{
    const BoxSlabs slabs = box_slabs(box, ray);
    const bool entering = slabs.entry > 0;
    const int k = entering ? slabs.entry_axis : slabs.exit_axis;
    const real along = k == 0 ? slabs.dots.x : (k == 1 ? slabs.dots.y : slabs.dots.z);
    const real3 e = k == 0 ? box->world_axis0.xyz : (k == 1 ? box->world_axis1.xyz : box->world_axis2.xyz);
    const real sign = (along > 0) == entering ? (real)-1 : (real)1;
    return sign * e;
}
