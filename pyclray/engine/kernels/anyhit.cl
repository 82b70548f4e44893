/* The any-hit query (occluded): whether each ray of a batch given in world coordinates meets any
 * shape up to its limit (pyclray/engine/queries/cast.py). The host puts before this file common.h, lanes.h,
 * the generated struct header, shapes.h, the BVH's headers, cast.h, the file of each shape
 * type present and rays.h. */

/* Whether any shape is hit at a distance below t_max (tmin < t < tmax, open at both ends): the
 * search stops at the first such hit. */
#define PYCLRAY_CAST_TAKE(t, id, kind, k, q) found = found || ((t) < t_max && (t) > t_min);
#define PYCLRAY_CAST_LIMIT if (found) limit = -INFINITY;
#define PYCLRAY_CAST_REACH t_max
#define PYCLRAY_CAST_PREFETCH_WINNER(Type, type, k)  /* no winner is kept */

PYCLRAY_KERNELS_BEGIN
inline void occluded_ray(const int r, const CastDirection* direction, PYCLRAY_PARAMETERS)
{
    PYCLRAY_CAST_RAY
    bool found = false;
    PYCLRAY_UNBOUNDED(PYCLRAY_CAST_LINEAR)
#ifdef PYCLRAY_HAS_BOUNDED
    if (!found) {
        PYCLRAY_CAST_BOX
        float limit = float_above_wide(t_max);
        PYCLRAY_CAST_BOUNDED(PYCLRAY_CAST_VISIT, PYCLRAY_TRAVERSE(nodes, box, limit, 0, PYCLRAY_CAST_LEAF_MASK, PYCLRAY_CAST_VISIT))
    }
#endif
    occluded_out[r] = found ? 1 : 0;
}

PYCLRAY_WORK_ITEM_FUNCTION void occluded_group(const int group, PYCLRAY_PARAMETERS)
{
    PYCLRAY_CAST_GROUP_SETUP
    for (int l = 0; l < in_group; ++l)
        occluded_ray(rays[l], &directions_of[l], PYCLRAY_ARGUMENTS);
}

__kernel void occluded(PYCLRAY_PARAMETERS)
{
    const int group = get_global_id(0);
    if (group * CAST_GROUP < n_rays) occluded_group(group, PYCLRAY_ARGUMENTS);
}
