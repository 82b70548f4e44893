/* The render query: the nearest hit of each camera ray, a packet of pixels per work-item, written
 * into the images asked for. The host (pyclray/engine/launch/programs.py) puts before this file common.h,
 * lanes.h, the generated struct header, shapes.h, camera.h (the packet's rays), the BVH's headers, the
 * file of each shape type present, shading.h (with the shaded image), entries.h, nearest.h and
 * images.h; it selects what is compiled with #defines: the precision (PYCLRAY_FP64), the lanes and
 * the packet's shape, the shape types present and where each is read (PYCLRAY_MODE_<type>), tile
 * lists or the BVH (PYCLRAY_BVH), the images asked for (PYCLRAY_AOV_<name>) and shadow rays
 * (PYCLRAY_SHADOWS); and it declares the kernel's parameters, PYCLRAY_PARAMETERS
 * (pyclray/engine/launch/signatures.py). Geometry and camera come in buffers, so moving a shape or the
 * camera never recompiles. */

#if defined(PYCLRAY_BVH) && defined(PYCLRAY_ONE_BOUNDED) && defined(PYCLRAY_INLINE_BUILTINS)
/* One bounded type (PYCLRAY_ONE_BOUNDED): leaf position q is entry q of its arrays, so a leaf's
 * entries are asked for at once where the traversal first meets the leaf
 * (kernels/bvh_wide_packet.h): the entries its tests read, in the space (COPIED), in the world (FROM_WORLD), or its faces (INDEXED: the
 * vertices they name follow when read). PoCL's CPU device only: elsewhere OpenCL's prefetch is a
 * call, or nothing. */
#define PYCLRAY_PREFETCH_RANGE(p, bytes) \
    for (int byte = 0; byte < (bytes); byte += 64) __builtin_prefetch((__global const char*)(p) + byte);
#define PYCLRAY_PREFETCH_COPIED(Type, type) PYCLRAY_PREFETCH_RANGE(&type##s[leaf_first], leaf_count * (int)sizeof(Type))
#define PYCLRAY_PREFETCH_FROM_WORLD(Type, type) \
    PYCLRAY_PREFETCH_RANGE(&type##_worlds[leaf_first], leaf_count * (int)sizeof(Type##World))
#define PYCLRAY_PREFETCH_INDEXED(Type, type) PYCLRAY_PREFETCH_RANGE(&type##_faces[leaf_first], leaf_count * (int)sizeof(int4))
#define PYCLRAY_PACKET_PREFETCH_TYPE(Type, type) PYCLRAY_CAT(PYCLRAY_PREFETCH_, PYCLRAY_MODE_##type)(Type, type)
#undef PYCLRAY_PACKET_LEAF_PREFETCH
#define PYCLRAY_PACKET_LEAF_PREFETCH(first, count)                                    \
    {                                                                                 \
        const int leaf_first = (first), leaf_count = (count);                         \
        PYCLRAY_BOUNDED(PYCLRAY_PACKET_PREFETCH_TYPE)                                 \
    }
#endif

/* One work-item per packet of PYCLRAY_PACKET_W x PYCLRAY_PACKET_H pixels: packet column
 * get_global_id(0) and row get_global_id(1), counted from the packet of the window's first pixel (a
 * render of a window of the image starts at row row0 and column col0, and writes its own
 * cols x rows images; packets start at multiples of their size in the image, so that a window's
 * pixels are the whole image's, and none straddles two tiles). Tiles are 1 << tile_shift pixels
 * square, tiles_x per image row (and the work-groups where the device allows). */
PYCLRAY_KERNELS_BEGIN
PYCLRAY_WORK_ITEM_FUNCTION void render_packet(const int packet, const int r, PYCLRAY_PARAMETERS)
{
    const int i0 = (col0 / PYCLRAY_PACKET_W + packet) * PYCLRAY_PACKET_W;
    const int j0 = (row0 / PYCLRAY_PACKET_H + r) * PYCLRAY_PACKET_H;
    if (i0 >= col0 + cols || j0 >= row0 + rows) return;
    const int tile = (j0 >> tile_shift) * tiles_x + (i0 >> tile_shift);  /* shifts: no division per packet */
    /* the columns and rows in the window (no min or max: PoCL's would be calls, see v_sqrt); lane 0
     * is element (j0 - row0) cols + (i0 - col0) of the window's images */
    const int from = col0 > i0 ? col0 - i0 : 0;
    const int to = col0 + cols - i0 < PYCLRAY_PACKET_W ? col0 + cols - i0 : PYCLRAY_PACKET_W;
    PacketPlace place;
    place.index = (long)(j0 - row0) * (long)cols + (long)(i0 - col0);
    place.stride = cols;
    place.row_first = row0 > j0 ? row0 - j0 : 0;
    place.row_end = row0 + rows - j0 < PYCLRAY_PACKET_H ? row0 + rows - j0 : PYCLRAY_PACKET_H;
#ifdef PYCLRAY_CAMERA_TABLE
    intv in_field;  /* the lanes the lens reaches: the others are misses, whatever their ray meets */
    const RayPacket ray = camera_table_rays(camera, camera_directions, i0, j0, &in_field);
#else
    const RayPacket ray = camera_rays(camera, i0, j0);
#endif
#ifdef PYCLRAY_FROM_WORLD
    const Space view_space = {space_origin.xyz, space_u.xyz, space_v.xyz, space_w.xyz};  /* the eye's */
#endif

    PYCLRAY_FIND_NEAREST
#if defined(PYCLRAY_BVH) && defined(PYCLRAY_HAS_BOUNDED)
    /* the bounded shapes through the BVH, whose boxes are in world axes around the scene's anchor */
    const BoxPacket box = box_packet(world_from_space(camera, ray.dir), camera->box_origin);
#ifdef PYCLRAY_PAIRS  /* one ray per work-item (GPUs): the pair nodes (kernels/bvh_pairs.h) */
    PYCLRAY_TRAVERSE_PAIRS(pair_nodes, box, best, PYCLRAY_VISIT)
#else
    PYCLRAY_TRAVERSE_PACKET_WIDE(wide_nodes, box, best, PYCLRAY_VISIT)
#endif
#endif
#ifdef PYCLRAY_CAMERA_TABLE
    PYCLRAY_OUT_OF_FIELD(in_field)
#endif
    PYCLRAY_WRITE_IMAGES(place, from, to)
}

/* The work-groups in a scattered order: group g of n works on the block of packets at g s mod n,
 * s the first integer from 5n/8 up that is prime to n (a bijection; consecutive groups land far
 * apart). Why: PoCL's CPU device hands its threads runs of consecutive work-groups (64 at a time
 * for a 256x256 image's 256 groups, a quarter of the image); in image order a thread that drew the
 * sky idled while the other traced the ground, and a render kept 1.5 of the 2 cores busy.
 * Scattered, each run samples the whole image and both cores stay busy. Every packet is still
 * traced once, by the same code. Not for cast and occluded: their batches come in ray order, and a
 * thread's consecutive groups reuse what the ones before brought into its caches. Nor for images
 * of SCATTERED_BELOW groups or more (a 512x512 image has 1,024): their 16 runs or more balance the
 * threads well enough, and scattering only costs the caches what neighbouring tiles share
 * (docs/benchmarks.md, "Why the engine does what it does": SCATTERED_BELOW). */
#define SCATTERED_BELOW 1024
inline int scattered_group(const int g, const int n)
{
    int s = n - n / 4 - n / 8;
    for (;; ++s) {
        int a = s, b = n;  /* Euclid's gcd(s, n) */
        while (b != 0) {
            const int t = a % b;
            a = b;
            b = t;
        }
        if (a == 1) break;
    }
    return (int)(((long)g * (long)s) % (long)n);
}

__kernel void render(PYCLRAY_PARAMETERS)
{
    const int nx = get_num_groups(0);
    const int n = nx * get_num_groups(1), in_order = get_group_id(1) * nx + get_group_id(0);
    const int g = n < SCATTERED_BELOW ? scattered_group(in_order, n) : in_order;
    render_packet((g % nx) * get_local_size(0) + get_local_id(0), (g / nx) * get_local_size(1) + get_local_id(1),
                  PYCLRAY_ARGUMENTS);
}
