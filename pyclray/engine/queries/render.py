"""A render on a scene handle: one ray per pixel centre of the view's camera, the images asked for."""
from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from ...model.aovs import RENDER_AOVS, kernel_aovs
from ...model.cameras import CAMERAS, CameraModel
from ...model.errors import PyclrayWarning, RequestError
from ...model.scene import Scene
from ..bvh import tiles
from ..launch.programs import Variant, lanes_for, packet_shape, pairs_for
from ..launch.run import enqueue_kernel
from .labels import with_labels
from .motion import MOTION_AOVS, Motion, with_motion
from .memory import check_images_fit
from .requests import Frame, check_request


def _window(scene: Scene, window) -> tuple[int, int, int, int]:
    """(col0, row0, cols, rows) of the part of the image to render: the whole image by default."""
    width, height = scene.image.width, scene.image.height
    if window is None:
        return 0, 0, width, height
    try:
        col0, row0, cols, rows = (int(v) for v in window)
    except (TypeError, ValueError):
        raise RequestError(f"window: expected (x0, y0, width, height) integers, got {window!r}") from None
    if not (0 <= col0 and 0 <= row0 and cols >= 1 and rows >= 1 and col0 + cols <= width and row0 + rows <= height):
        raise RequestError(
            f"window: expected (x0, y0, width, height) inside the {width}x{height} image, got {tuple(window)!r}"
        )
    return col0, row0, cols, rows


def start(tracer, view: Scene, aovs, window, acceleration: str, motion: Motion | None = None, warn_pose: bool = True):
    """A render's work up to the kernel's launch on a scene handle (engine/tracer.py), for a view of
    its shapes (view: a Scene with the handle's shapes and the camera, image, lights and shading to
    render; the checks, the per-view pass, the kernel, enqueued on the device's in-order queue): a
    callable that waits for this view's kernel and returns its Frame. motion: the next frame, for
    flow (engine/queries/motion.py; its camera None: the view's). warn_pose: warn (LOOKS_AWAY) when
    nothing is hit and every shape lies behind the camera; off for renders of a part of a scene
    whose emptiness says nothing of the pose (a data set's objects alone)."""
    ctx, precision = tracer.ctx, tracer.precision
    asked = check_request(aovs, precision, ctx, RENDER_AOVS)
    if "zdepth" in asked and not view.camera.has_zdepth:
        raise RequestError(f"aovs: zdepth is the depth along the optical axis, which the {view.camera.model} camera "
                           "model has not; ask for depth")
    if "flow" in asked and motion is None and view.animation is not None:  # (a handle of an animated scene)
        raise RequestError("flow: an animated scene's flow is to its next frame: render the scene at a time "
                           "(pyclray.render(scene, ..., time=t)), or give the handle's render_views a motion")
    if not view.camera.rays_from_eye:  # rays from many origins (orthographic): cast, not the camera packets
        return start_cast_view(tracer, view, asked, window, motion)
    aovs = kernel_aovs(asked)  # what the kernel makes (label comes from id, after it: with_labels)
    prepared = tracer.prepared
    state = tracer.view_state(view)
    state.check_renderable(view, precision, prepared)
    acceleration = state.acceleration(view, acceleration, prepared)
    col0, row0, cols, rows = _window(view, window)
    check_images_fit(tuple(dict.fromkeys(aovs + asked)), precision, cols, rows)  # a clear error before any allocation
    inputs = state.inputs_for(ctx, view, prepared, acceleration)
    lanes = lanes_for(ctx.device, precision)
    shadows = "shaded" in aovs and view.shading.shadows
    smooth = prepared.smooth if "shaded" in aovs else ()  # compiled in only with a smooth shape, shaded
    variant = Variant("render", prepared.types, aovs, precision, lanes, shadows, bvh=acceleration == "bvh", smooth=smooth,
                      from_world=prepared.from_world, indexed=prepared.indexed, camera_table=inputs.table_format,
                      pairs=pairs_for(lanes) and acceleration == "bvh")
    tile = tiles.TILE
    # the kernel's arguments by name (engine/launch/signatures.py: the render kernel's), but for the images' buffers
    args = {"camera": inputs.camera, "col0": np.int32(col0), "row0": np.int32(row0), "cols": np.int32(cols),
            "rows": np.int32(rows), "tile_shift": np.int32(tile.bit_length() - 1),
            "tiles_x": np.int32(-(-view.image.width // tile)), **inputs.shape_args(prepared, acceleration, shadows, variant.through_pairs())}
    if inputs.table is not None:  # in this program's packets
        args["camera_directions"] = inputs.directions_for(lanes)
    if "position" in aovs:
        args["eye_high"], args["eye_low"] = inputs.eye_parts()
    if "shaded" in aovs:
        args.update(inputs.lighting(prepared))
        args.update({f"{t}_smooth": prepared.kinds[t].smooth for t in smooth})
    global_size, local_size = launch_size(lanes, col0, row0, cols, rows, ctx.device.max_work_group_size)
    # the view buffers hold this view from its pass to its kernel: both enqueued under the lock, on the
    # device's one in-order queue, which runs another view's pass only after this kernel
    with prepared.lock:
        uploads = prepared.rebase(inputs.eye, inputs.rows)
        pending = enqueue_kernel(ctx, variant, args, global_size, cols * rows, aovs, precision, (rows, cols), tracer.outputs,
                                 local_size)
    # until it has run: what it reads (a CPU device reads the host arrays themselves, which a handle
    # closed or a cache cleared between two frames of render_views would otherwise free)
    pending.keep = (pending.keep, uploads, prepared, inputs, args)

    if motion is not None and motion.camera is None:
        motion = Motion(motion.shapes, view.camera)

    def frame() -> Frame:
        images = pending.result()
        if warn_pose and _all_missed(images) and _behind_the_camera(view.camera, prepared):
            warnings.warn(LOOKS_AWAY, PyclrayWarning, stacklevel=2)
        if any(name in MOTION_AOVS for name in asked):  # derived on the host, then only what was asked
            images = with_motion(view, images, motion, asked)
            images = images if "label" in asked else {name: images[name] for name in asked}
        return Frame(with_labels(view, images, asked), precision=precision, device=ctx.device.name.strip(),
                     view=(view.camera, view.image.width, view.image.height, col0, row0))

    return frame


LOOKS_AWAY = ("every pixel is a miss and every shape lies behind the camera: is the pose in OpenGL's convention "
              "(y up, z backwards)? pyclray's pose is OpenCV's (x right, y down, z forward): "
              "flip its y and z axes (pose @ diag(1, -1, -1, 1))")
# the images that tell a miss apart from a hit, and the value a miss holds (model/aovs.py's TABLE)
_MISS = (("id", -1), ("depth", np.inf), ("zdepth", np.inf), ("primitive", -1))


def _all_missed(images: dict) -> bool:
    """True if the render's images say no pixel hit (False where none of them can tell)."""
    for name, miss in _MISS:
        if name in images:
            image = images[name].reshape(-1)
            # a sample first: an image that hits anywhere mostly hits in it, without a pass over all
            return bool((image[::997] == miss).all() and (image == miss).all())
    return False


def _behind_the_camera(camera, prepared) -> bool:
    """True if the scene has bounded shapes and every corner of every one's box has camera z <= 0
    (OpenCV's pose: z forward), where no pixel's ray can reach it. Asked only of an all-miss image."""
    bounds = prepared.bvh.given_bounds
    if not len(bounds):
        return False  # planes only: no bounds to be behind
    pose = camera.pose()
    forward, eye = pose[:3, 2], pose[:3, 3]

    def all_behind(boxes) -> bool:
        with np.errstate(over="ignore", invalid="ignore"):
            # a box's most forward corner: per axis the larger of its two faces' terms
            terms = np.maximum((boxes[:, 0] - eye) * forward, (boxes[:, 1] - eye) * forward)
            return bool((terms.sum(axis=1) <= 0).all())

    # a sample first: one box in front answers, without a pass over every primitive's (a window that
    # misses a large mesh in front of the camera, as a data set's renders of an object alone do)
    return all_behind(bounds[::997]) and all_behind(bounds)


def start_cast_view(tracer, view: Scene, asked, window, motion: Motion | None = None):
    """A render of a camera whose rays do not share the eye (orthographic): its float64 pixel-centre
    rays (CameraModel.rays) cast on the handle (the same exact tests as any cast ray), the images
    assembled: depth, normal, id, primitive, barycentric and label from cast; zdepth (depth along the
    view direction: the same, the rays being parallel to it), position (origin + depth dir, float64)
    and shaded (the shading model of the hits, its shadow rays cast: engine/queries/shade.py) on the
    host; object_coordinates and flow from position, id and primitive as a render's
    (engine/queries/motion.py)."""
    from .shade import shade, shading_aovs

    col0, row0, cols, rows = _window(view, window)
    state = tracer.view_state(view)
    state.check_renderable(view, tracer.precision, tracer.prepared)
    check_images_fit(asked, tracer.precision, cols, rows)
    if motion is not None and motion.camera is None:
        motion = Motion(motion.shapes, view.camera)
    # the images to make: those asked, and what the motion images are derived from
    making = tuple(dict.fromkeys(tuple(a for a in asked if a not in MOTION_AOVS)
                                 + (("position", "id", "primitive") if any(a in MOTION_AOVS for a in asked) else ())))
    origins, directions = view.camera.rays(view.image.width, view.image.height, (col0, row0, cols, rows))
    origins, directions = origins.reshape(-1, 3), directions.reshape(-1, 3)
    cast_aovs = ("depth",) + tuple(a for a in making if a in ("normal", "id", "label", "primitive", "barycentric"))
    if "shaded" in making:
        cast_aovs += shading_aovs(view)
    hits = tracer.cast(origins, directions, aovs=tuple(dict.fromkeys(cast_aovs)))
    images = {}
    depth = hits["depth"].reshape(rows, cols)
    for aov in making:
        if aov in ("depth", "zdepth"):
            images[aov] = depth.copy() if aov == "zdepth" else depth
        elif aov == "position":
            hit = np.isfinite(depth)[..., None]
            points = origins.reshape(rows, cols, 3) + np.where(hit, depth[..., None], 0.0) * directions.reshape(rows, cols, 3)
            images[aov] = np.where(hit, points, 0.0).astype(depth.dtype)
        elif aov == "shaded":
            images[aov] = shade(tracer, view, origins, directions, hits).reshape(rows, cols, 3)
        else:  # cast's own (label: cast's too)
            images[aov] = hits[aov].reshape((rows, cols) + hits[aov].shape[1:])
    if any(a in MOTION_AOVS for a in asked):
        images = with_motion(view, images, motion, asked)
    frame = Frame({name: images[name] for name in asked}, precision=tracer.precision,
                  device=tracer.ctx.device.name.strip(), view=(view.camera, view.image.width, view.image.height, col0, row0))
    return lambda: frame


def launch_size(lanes: int, col0: int, row0: int, cols: int, rows: int, max_group: int):
    """(global size, local size or None) of the render kernel over a window: one packet of
    programs.packet_shape(lanes) pixels per work-item, packets aligned to multiples of that shape in
    the image (kernels/render.cl: render_packet); work-groups of one tile's packets where the device
    allows (the kernel needs none)."""
    width, height = packet_shape(lanes)
    tile = tiles.TILE
    packets = (-(-(col0 + cols) // width) - col0 // width, -(-(row0 + rows) // height) - row0 // height)
    group = (tile // width, tile // height)
    global_size = tuple(-(-n // g) * g for n, g in zip(packets, group))
    return global_size, (group if max_group >= group[0] * group[1] else None)


def with_camera(scene: Scene, camera) -> Scene:
    """The scene seen from another camera (its shapes tuple kept: the prepared scene serves it)."""
    if not isinstance(camera, CameraModel):
        models = ", ".join(f"pyclray.{cls.__name__}" for cls in CAMERAS.values())  # pyclray.Camera first
        raise RequestError(f"camera: expected a {models}, got {type(camera).__name__}")
    return replace(scene, camera=camera)
