/* The kernels' argument lists, each written once as P(type, name) for each argument:
 * PYCLRAY_DECLARE makes it a list of parameters (", type name" each), PYCLRAY_PASS the arguments of
 * a call (", name" each). */
#define PYCLRAY_DECLARE(type, name) , type name
#define PYCLRAY_PASS(type, name) , name

#ifdef PYCLRAY_FRAMED
/* the eye's frame, float64: its origin and axes */
#define PYCLRAY_FRAME_ARGS(P) P(const double4, frame_origin) P(const double4, frame_u) P(const double4, frame_v) P(const double4, frame_w)
#else
#define PYCLRAY_FRAME_ARGS(P)
#endif

#ifdef PYCLRAY_CAST
/* one argument pair per shape type present: the packed array and its length; the bounded types'
 * shapes are reached through the BVH's leaves, the others (planes) are each tested by every ray.
 * cast adds the float64 world entries, on which it frames each shape it tests (kernels/cast.h). */
#define PYCLRAY_SHAPE_ARGS(P, Type, type)                                             \
    P(__global const Type*, type##s) P(__global const Type##World*, type##_worlds)    \
    PYCLRAY_SHARED_ARGS_##type(P) P(const int, n_##type##s)
#ifdef PYCLRAY_HAS_BOUNDED
/* the wide BVH, per leaf position its shape's anchor in world coordinates (xyz) and bounding
 * radius (w), the same as the leaf pre-test takes them (box_anchors: xyz the anchor from the
 * scene's anchor, w the radius, each rounded once to float: cast_may_pass), and the box of the
 * root's children (lo xyz, hi xyz; PYCLRAY_CAST_BOUNDED) */
#define PYCLRAY_BVH_ARGS(P) P(__global const WideNode*, nodes) P(__global const int*, refs) P(__global const double4*, anchors) \
    P(__global const float4*, box_anchors) P(const float8, root_box)
#else
#define PYCLRAY_BVH_ARGS(P)
#endif
#elif defined(PYCLRAY_BVH)
#define PYCLRAY_SHAPE_ARGS(P, Type, type) \
    PYCLRAY_ENTRIES(P, Type, type) PYCLRAY_SHARED_ARGS_##type(P) P(const int, n_##type##s)
#ifdef PYCLRAY_HAS_BOUNDED
#ifdef PYCLRAY_SHADOWS
/* the wide BVH (camera packets traverse it: kernels/bvh_wide_packet.h's PYCLRAY_TRAVERSE_PACKET_WIDE), and the
 * binary one of the same boxes for shadow rays (kernels/shading.h) */
#define PYCLRAY_BVH_ARGS(P) P(__global const WideNode*, wide_nodes) P(__global const BvhNode*, nodes) P(__global const int*, refs)
#else
#define PYCLRAY_BVH_ARGS(P) P(__global const WideNode*, wide_nodes) P(__global const int*, refs)
#endif
#else
#define PYCLRAY_BVH_ARGS(P)
#endif
#else
/* per shape type: the packed array, and for each tile of the image the shapes that can be seen
 * in it (type##_tile_list[type##_tile_start[tile] .. type##_tile_start[tile + 1]], increasing;
 * the host's conservative screen bounds, pyclray/engine/culling.py): the others miss every ray there */
#ifdef PYCLRAY_SHADOWS
/* shadow rays go anywhere: they test every shape of the type (n_##type##s of them) */
#define PYCLRAY_SHAPE_ARGS(P, Type, type)                                             \
    PYCLRAY_ENTRIES(P, Type, type) PYCLRAY_SHARED_ARGS_##type(P)                      \
    P(__global const int*, type##_tile_start)                                         \
    P(__global const int*, type##_tile_list) P(const int, n_##type##s)
#else
#define PYCLRAY_SHAPE_ARGS(P, Type, type)                                             \
    PYCLRAY_ENTRIES(P, Type, type) PYCLRAY_SHARED_ARGS_##type(P)                      \
    P(__global const int*, type##_tile_start)                                         \
    P(__global const int*, type##_tile_list)
#endif
#define PYCLRAY_BVH_ARGS(P)
#endif

/* the images' buffers (and the position's eye) */
#ifdef PYCLRAY_AOV_DEPTH
#define PYCLRAY_DEPTH_ARG(P) P(__global real*, depth)
#else
#define PYCLRAY_DEPTH_ARG(P)
#endif
#ifdef PYCLRAY_AOV_NORMAL
#define PYCLRAY_NORMAL_ARG(P) P(__global real*, normal_out)
#else
#define PYCLRAY_NORMAL_ARG(P)
#endif
#ifdef PYCLRAY_AOV_ID
#define PYCLRAY_ID_ARG(P) P(__global int*, id_out)
#else
#define PYCLRAY_ID_ARG(P)
#endif
#ifdef PYCLRAY_AOV_ZDEPTH
#define PYCLRAY_ZDEPTH_ARG(P) P(__global real*, zdepth_out)
#else
#define PYCLRAY_ZDEPTH_ARG(P)
#endif
#ifdef PYCLRAY_AOV_POSITION
#define PYCLRAY_POSITION_ARG(P) P(const real4, eye_high) P(const real4, eye_low) P(__global real*, position_out)
#else
#define PYCLRAY_POSITION_ARG(P)
#endif
#ifdef PYCLRAY_AOV_PRIMITIVE
#define PYCLRAY_PRIMITIVE_ARG(P) P(__global int*, primitive_out)
#else
#define PYCLRAY_PRIMITIVE_ARG(P)
#endif
#ifdef PYCLRAY_AOV_BARYCENTRIC
#define PYCLRAY_BARYCENTRIC_ARG(P) P(__global real*, barycentric_out)
#else
#define PYCLRAY_BARYCENTRIC_ARG(P)
#endif
#define PYCLRAY_OUTPUT_ARGS(P) PYCLRAY_DEPTH_ARG(P) PYCLRAY_NORMAL_ARG(P) PYCLRAY_ID_ARG(P)
#define PYCLRAY_RENDER_OUTPUT_ARGS(P) \
    PYCLRAY_OUTPUT_ARGS(P) PYCLRAY_ZDEPTH_ARG(P) PYCLRAY_POSITION_ARG(P) PYCLRAY_SHADED_ARGS(P) PYCLRAY_PRIMITIVE_ARG(P) \
    PYCLRAY_BARYCENTRIC_ARG(P)
/* the shapes' arguments as parameters and as the arguments of a call */
#define PYCLRAY_SHAPE_PARAMETERS(Type, type) PYCLRAY_SHAPE_ARGS(PYCLRAY_DECLARE, Type, type)
#define PYCLRAY_SHAPE_PASSED(Type, type) PYCLRAY_SHAPE_ARGS(PYCLRAY_PASS, Type, type)
