/* A render's images: where a packet's pixels lie in them, the stores that write them, and what each
 * image writes (only the images asked for: PYCLRAY_AOV_<name>, from the host).
 *
 * A render's packet covers PYCLRAY_PACKET_W x PYCLRAY_PACKET_H pixels (pyclray/engine/launch/programs.py:
 * packet_shape): lane l is column l % W, row l / W of it, element index + (l / W) stride + l % W of
 * the images. A packet cut by the border of the window writes its columns first <= c < end of its
 * rows row_first <= r < row_end only; a whole row of W lanes with one vector store. */
#if LANES == 1
#define PYCLRAY_INT32V int
#else
#define PYCLRAY_INT32V PYCLRAY_CAT(int, LANES)
#endif

typedef struct {
    long index;   /* the element of the packet's lane 0 (before the window's first row: < 0 there) */
    long stride;  /* elements from one row of the images to the next */
    int row_first, row_end;
} PacketPlace;

inline bool packet_lane_written(const PacketPlace place, const int l, const int first, const int end)
{
    const int column = l % PYCLRAY_PACKET_W, row = l / PYCLRAY_PACKET_W;
    return first <= column && column < end && place.row_first <= row && row < place.row_end;
}
inline long packet_lane_index(const PacketPlace place, const int l)
{
    return place.index + (l / PYCLRAY_PACKET_W) * place.stride + l % PYCLRAY_PACKET_W;
}

/* one row of a packet: W lanes (the whole packet where it is one row) */
#if PYCLRAY_PACKET_W == 1
typedef real realw;
typedef int int32w;
#else
typedef PYCLRAY_CAT(PYCLRAY_REAL_NAME, PYCLRAY_PACKET_W) realw;
typedef PYCLRAY_CAT(int, PYCLRAY_PACKET_W) int32w;
#endif

/* W lanes stored at p (the first lane's element): one move instruction through a vector type of the
 * element's alignment on PoCL's CPU device (see v_sqrt in kernels/lanes.h), else vstoren */
#if PYCLRAY_PACKET_W == 1
#define STORE_ROW_REALS(v, p) (*(p) = (v))
#define STORE_ROW_INT32S(v, p) (*(p) = (v))
#elif defined(PYCLRAY_INLINE_BUILTINS)
typedef realw realw_unaligned __attribute__((aligned(sizeof(real))));
typedef int32w int32w_unaligned __attribute__((aligned(sizeof(int))));
#define STORE_ROW_REALS(v, p) (*(__global realw_unaligned*)(p) = (v))
#define STORE_ROW_INT32S(v, p) (*(__global int32w_unaligned*)(p) = (v))
#else
#define STORE_ROW_REALS(v, p) PYCLRAY_CAT(vstore, PYCLRAY_PACKET_W)((v), 0, (p))
#define STORE_ROW_INT32S(v, p) PYCLRAY_CAT(vstore, PYCLRAY_PACKET_W)((v), 0, (p))
#endif

/* interleaved x, y, z of a whole row of W lanes at p */
inline void store_row_vec3s(const realw x, const realw y, const realw z, __global real* p)
{
#if PYCLRAY_PACKET_W == 8
    STORE_ROW_REALS((realw)(x.s0, y.s0, z.s0, x.s1, y.s1, z.s1, x.s2, y.s2), p);
    STORE_ROW_REALS((realw)(z.s2, x.s3, y.s3, z.s3, x.s4, y.s4, z.s4, x.s5), p + 8);
    STORE_ROW_REALS((realw)(y.s5, z.s5, x.s6, y.s6, z.s6, x.s7, y.s7, z.s7), p + 16);
#elif PYCLRAY_PACKET_W == 4
    STORE_ROW_REALS((realw)(x.s0, y.s0, z.s0, x.s1), p);
    STORE_ROW_REALS((realw)(y.s1, z.s1, x.s2, y.s2), p + 4);
    STORE_ROW_REALS((realw)(z.s2, x.s3, y.s3, z.s3), p + 8);
#elif PYCLRAY_PACKET_W == 2
    STORE_ROW_REALS((realw)(x.s0, y.s0), p);
    STORE_ROW_REALS((realw)(z.s0, x.s1), p + 2);
    STORE_ROW_REALS((realw)(y.s1, z.s1), p + 4);
#else
    p[0] = x;
    p[1] = y;
    p[2] = z;
#endif
}

/* A whole packet (every lane in the window) with a vector store per row; a packet cut by the border
 * of the window lane by lane. Row 0 of the packet is its lanes' low half, row 1 the high half. */
#if PYCLRAY_PACKET_H == 1
#define PYCLRAY_PACKET_ROWS(STORE, v, place) STORE(v, (place).index)
#else
#define PYCLRAY_PACKET_ROWS(STORE, v, place) STORE((v).lo, (place).index) STORE((v).hi, (place).index + (place).stride)
#endif
#define PYCLRAY_WHOLE_PACKET(place, first, end) \
    ((first) == 0 && (end) == PYCLRAY_PACKET_W && (place).row_first == 0 && (place).row_end == PYCLRAY_PACKET_H)
#define PYCLRAY_STORE_LANE(l, c) \
    if (packet_lane_written(place, l, first, end)) out[packet_lane_index(place, l)] = v.c;
#define PYCLRAY_STORE_VEC3_LANE(l, c)                                                 \
    if (packet_lane_written(place, l, first, end)) {                                  \
        const long at = 3 * packet_lane_index(place, l);                              \
        out[at] = v.x.c;                                                              \
        out[at + 1] = v.y.c;                                                          \
        out[at + 2] = v.z.c;                                                          \
    }

inline void write_reals(const realv v, const PacketPlace place, const int first, const int end, __global real* out)
{
#if LANES == 1
    out[place.index] = v;
#else
    if (PYCLRAY_WHOLE_PACKET(place, first, end)) {
#define PYCLRAY_ROW(row, at) STORE_ROW_REALS(row, out + (at));
        PYCLRAY_PACKET_ROWS(PYCLRAY_ROW, v, place)
#undef PYCLRAY_ROW
    } else {
        PYCLRAY_EACH_LANE(PYCLRAY_STORE_LANE)
    }
#endif
}

inline void write_ints(const PYCLRAY_INT32V v, const PacketPlace place, const int first, const int end, __global int* out)
{
#if LANES == 1
    out[place.index] = v;
#else
    if (PYCLRAY_WHOLE_PACKET(place, first, end)) {
#define PYCLRAY_ROW(row, at) STORE_ROW_INT32S(row, out + (at));
        PYCLRAY_PACKET_ROWS(PYCLRAY_ROW, v, place)
#undef PYCLRAY_ROW
    } else {
        PYCLRAY_EACH_LANE(PYCLRAY_STORE_LANE)
    }
#endif
}

/* interleaved x, y, z per element */
inline void write_vec3s(const vec3v v, const PacketPlace place, const int first, const int end, __global real* out)
{
#if LANES == 1
    out[3 * place.index] = v.x;
    out[3 * place.index + 1] = v.y;
    out[3 * place.index + 2] = v.z;
#else
    if (PYCLRAY_WHOLE_PACKET(place, first, end)) {
#if PYCLRAY_PACKET_H == 1
        store_row_vec3s(v.x, v.y, v.z, out + 3 * place.index);
#else
        store_row_vec3s(v.x.lo, v.y.lo, v.z.lo, out + 3 * place.index);
        store_row_vec3s(v.x.hi, v.y.hi, v.z.hi, out + 3 * (place.index + place.stride));
#endif
    } else {
        PYCLRAY_EACH_LANE(PYCLRAY_STORE_VEC3_LANE)
    }
#endif
}

/* The images: distance along the unit ray, the winner's world normal, its id, ...;
 * MISS (+inf), (0, 0, 0) and -1 on a miss. Lane l of the packet is element index + l of the images,
 * written for the lanes first <= l < end inside the image (or window): a whole packet with vector
 * stores, the ends of a row lane by lane. */
#ifdef PYCLRAY_AOV_DEPTH
#define PYCLRAY_WRITE_DEPTH(index, first, end) \
    write_reals(best < MISS ? best * v_sqrt(ray.a) : SPLAT(MISS), index, first, end, depth_out);
#else
#define PYCLRAY_WRITE_DEPTH(index, first, end)
#endif

#ifdef PYCLRAY_AOV_NORMAL
#define PYCLRAY_WRITE_NORMAL(index, first, end) write_vec3s(normal, index, first, end, normal_out);
#else
#define PYCLRAY_WRITE_NORMAL(index, first, end)
#endif

#ifdef PYCLRAY_AOV_ID
#define PYCLRAY_WRITE_ID(index, first, end) write_ints(TO_INT32V(best_id), index, first, end, id_out);
#else
#define PYCLRAY_WRITE_ID(index, first, end)
#endif

/* depth along the optical axis, the space's z axis (w): the ray's s times its z */
#ifdef PYCLRAY_AOV_ZDEPTH
#define PYCLRAY_WRITE_ZDEPTH(index, first, end) \
    write_reals(best < MISS ? best * ray.dir.z : SPLAT(MISS), index, first, end, zdepth_out);
#else
#define PYCLRAY_WRITE_ZDEPTH(index, first, end)
#endif

/* the world hit point, eye + world_from_space(s D). The eye comes as a float64 sum
 * eye_high + eye_low of two reals, added to the (small) offset from the eye high part first, so that
 * a scene far from the world's origin loses no more than the output's own rounding. */
#ifdef PYCLRAY_AOV_POSITION
#define PYCLRAY_WRITE_POSITION(index, first, end)                                     \
    {                                                                                 \
        const intv hit = best < MISS;                                                 \
        const vec3v offset = world_from_space(camera, v3_scale(ray.dir, hit ? best : SPLAT(0))); \
        const vec3v world = v3_add(v3_add(v3_splat(eye_high), offset), v3_splat(eye_low)); \
        const vec3v zero = v3(SPLAT(0), SPLAT(0), SPLAT(0));                          \
        write_vec3s(v3_select(zero, world, hit), index, first, end, position_out);    \
    }
#else
#define PYCLRAY_WRITE_POSITION(index, first, end)
#endif

/* the winner's primitive index within its shape */
#ifdef PYCLRAY_AOV_PRIMITIVE
#define PYCLRAY_WRITE_PRIMITIVE(index, first, end) write_ints(TO_INT32V(primitive), index, first, end, primitive_out);
#else
#define PYCLRAY_WRITE_PRIMITIVE(index, first, end)
#endif

/* the winner's barycentric (u, v), interleaved per pixel */
#ifdef PYCLRAY_AOV_BARYCENTRIC
/* lane l of the packet is pixel (l % PYCLRAY_PACKET_W, l / PYCLRAY_PACKET_W) of it (see PacketPlace) */
#define PYCLRAY_STORE_UV_LANE(l, c)                                                   \
    if (packet_lane_written(bary_place, l, bary_first, bary_end)) {                   \
        const long at = packet_lane_index(bary_place, l);                             \
        barycentric_out[2 * at] = bary_u.c;                                           \
        barycentric_out[2 * at + 1] = bary_v.c;                                       \
    }
#if LANES == 1
#define PYCLRAY_WRITE_BARYCENTRIC(place, first, end) \
    { barycentric_out[2 * (place).index] = bary_u; barycentric_out[2 * (place).index + 1] = bary_v; }
#else
#define PYCLRAY_WRITE_BARYCENTRIC(place, first, end)                                 \
    {                                                                                 \
        const PacketPlace bary_place = (place);                                       \
        const int bary_first = (first), bary_end = (end);                             \
        PYCLRAY_EACH_LANE(PYCLRAY_STORE_UV_LANE)                                      \
    }
#endif
#else
#define PYCLRAY_WRITE_BARYCENTRIC(index, first, end)
#endif

/* the winners' attributes (kernels/nearest.h), then each image asked for */
#define PYCLRAY_WRITE_IMAGES(index, first, end) \
    PYCLRAY_WINNERS \
    PYCLRAY_WRITE_DEPTH(index, first, end) PYCLRAY_WRITE_NORMAL(index, first, end) PYCLRAY_WRITE_ID(index, first, end) \
    PYCLRAY_WRITE_ZDEPTH(index, first, end) PYCLRAY_WRITE_POSITION(index, first, end) PYCLRAY_WRITE_SHADED(index, first, end) \
    PYCLRAY_WRITE_PRIMITIVE(index, first, end) PYCLRAY_WRITE_BARYCENTRIC(index, first, end)
