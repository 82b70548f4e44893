"""Render a scene: one ray per pixel centre of its camera, the images asked for."""
from __future__ import annotations

import numpy as np

from dataclasses import replace

from ..model.aovs import AOVS, RENDER_AOVS, kernel_aovs
from ..model.camera import Camera
from ..model.errors import PyclrayError, RequestError, SceneError
from ..model.loader import as_scene
from ..model.animation import scene_at
from ..model.scene import Scene, checked_time
from . import culling
from .device import context_for
from .labels import with_labels
from .memory import check_images_fit
from .prepared import prepared_scene
from .views import acceleration_for, check_renderable_once, render_inputs
from .programs import Variant, lanes_for, packet_shape
from .request import Frame, check_request, enqueue_kernel


def _window(scene: Scene, window) -> tuple[int, int, int, int]:
    """(col0, row0, cols, rows) of the part of the image to render: the whole image by default."""
    width, height = scene.image.width, scene.image.height
    if window is None:
        return 0, 0, width, height
    try:
        col0, row0, cols, rows = (int(v) for v in window)
    except (TypeError, ValueError):
        raise PyclrayError(f"window: expected (x0, y0, width, height) integers, got {window!r}") from None
    if not (0 <= col0 and 0 <= row0 and cols >= 1 and rows >= 1 and col0 + cols <= width and row0 + rows <= height):
        raise PyclrayError(
            f"window: expected (x0, y0, width, height) inside the {width}x{height} image, got {tuple(window)!r}"
        )
    return col0, row0, cols, rows


def render(scene: Scene, aovs=AOVS, precision: str = "fp32", device=None, window=None, acceleration: str = "auto",
           camera=None) -> Frame:
    """Render the scene's depth, normal and id images (see Frame) with one ray per pixel centre.

    scene: a Scene or the path of a scene file; geometry beyond the precision's range is a
    SceneError (see scene.check_renderable).
    aovs: which images (a subset of depth, normal, id, zdepth, position, shaded, primitive, label: only those
    are computed; shaded casts shadow rays where the scene's [shading] asks for them; label, each
    shape's label, is looked up from the id image);
    precision: "fp32" or "fp64"; device: a pyopencl Device, a selector string, or None (default);
    window: (x0, y0, width, height), a part of the image (column x0 and row y0 from the top left),
    rendered into images of that size, the same pixels as in the whole image; default: all of it;
    acceleration: how the kernel skips the shapes a ray cannot hit, "tiles" (screen-space tile
    lists), "bvh" (the bounding volume hierarchy) or "auto" (tiles for a few shapes, else the BVH).
    The images do not depend on it, bit for bit.
    camera: a pyclray.Camera to render the scene's shapes from instead of its own (the same as
    rendering ``dataclasses.replace(scene, camera=camera)``).

    The scene's shapes are prepared on the device once and kept (pyclray.engine.prepared): a view
    from another camera uploads the camera only, whatever the number of shapes.
    """
    return _start(scene, aovs, precision, device, window, acceleration, camera)()


def _start(scene: Scene, aovs=AOVS, precision: str = "fp32", device=None, window=None, acceleration: str = "auto",
           camera=None):
    """render's work up to the kernel's launch (the checks, the per-view pass, the kernel, enqueued on
    the device's in-order queue): a callable that waits for this view's kernel and returns its Frame."""
    scene = as_scene(scene)
    if camera is not None:
        scene = with_camera(scene, camera)
    ctx = context_for(device)
    asked = check_request(aovs, precision, ctx, RENDER_AOVS)
    aovs = kernel_aovs(asked)  # what the kernel makes (label comes from id, after it: with_labels)
    prepared = prepared_scene(ctx, scene, precision)
    check_renderable_once(scene, precision, prepared)
    acceleration = acceleration_for(scene, acceleration, prepared)
    col0, row0, cols, rows = _window(scene, window)
    check_images_fit(tuple(dict.fromkeys(aovs + asked)), precision, cols, rows)  # a clear error before any allocation
    _, inputs = render_inputs(ctx, scene, precision, acceleration)
    lanes = lanes_for(ctx.device, precision)
    shadows = "shaded" in aovs and scene.shading.shadows
    smooth = prepared.smooth if "shaded" in aovs else ()  # compiled in only with a smooth shape, shaded
    variant = Variant("render", prepared.types, aovs, precision, lanes, shadows, bvh=acceleration == "bvh", smooth=smooth,
                      framed=prepared.framed, indexed=prepared.indexed)
    tile = culling.TILE
    # the kernel's arguments by name (engine/signatures.py: the render kernel's), but for the images' buffers
    args = {"camera": inputs.camera, "col0": np.int32(col0), "row0": np.int32(row0), "cols": np.int32(cols),
            "rows": np.int32(rows), "tile_shift": np.int32(tile.bit_length() - 1),
            "tiles_x": np.int32(-(-scene.image.width // tile)), **inputs.shape_args(prepared, acceleration, shadows)}
    if "position" in aovs:
        args["eye_high"], args["eye_low"] = inputs.eye_parts()
    if "shaded" in aovs:
        args.update(inputs.lighting(prepared))
        args.update({f"{t}_smooth": prepared.kinds[t].smooth for t in smooth})
    global_size, local_size = launch_size(lanes, col0, row0, cols, rows, ctx.device.max_work_group_size)
    # the frame buffers hold this view from its pass to its kernel: both enqueued under the lock, on the
    # device's one in-order queue, which runs another view's pass only after this kernel
    with prepared.lock:
        uploads = prepared.rebase(inputs.eye, inputs.rows)
        pending = enqueue_kernel(ctx, variant, args, global_size, cols * rows, aovs, precision, (rows, cols), local_size)
    # until it has run: what it reads (a CPU device reads the host arrays themselves, which a
    # pyclray.clear_cache() between two frames of render_views would otherwise free)
    pending.keep = (pending.keep, uploads, prepared, inputs, args)

    def frame() -> Frame:
        return Frame(with_labels(scene, pending.result(), asked), precision=precision, device=ctx.device.name.strip(),
                     view=(scene.camera, scene.image.width, scene.image.height, col0, row0))

    return frame


def launch_size(lanes: int, col0: int, row0: int, cols: int, rows: int, max_group: int):
    """(global size, local size or None) of the render kernel over a window: one packet of
    programs.packet_shape(lanes) pixels per work-item, packets aligned to multiples of that shape in
    the image (kernels/render.cl: render_packet); work-groups of one tile's packets where the device
    allows (the kernel needs none)."""
    width, height = packet_shape(lanes)
    tile = culling.TILE
    packets = (-(-(col0 + cols) // width) - col0 // width, -(-(row0 + rows) // height) - row0 // height)
    group = (tile // width, tile // height)
    global_size = tuple(-(-n // g) * g for n, g in zip(packets, group))
    return global_size, (group if max_group >= group[0] * group[1] else None)


def with_camera(scene: Scene, camera) -> Scene:
    """The scene seen from another camera (its shapes tuple kept: the prepared scene serves it)."""
    if not isinstance(camera, Camera):
        raise RequestError(f"camera: expected a pyclray.Camera, got {type(camera).__name__}")
    return replace(scene, camera=camera)


def render_views(scene: Scene, cameras, aovs=AOVS, precision: str = "fp32", device=None, acceleration: str = "auto"):
    """Yield the Frame of each camera (a pyclray.Camera, or a Scene whose camera and image size are
    taken) in order: many views of one scene's shapes, prepared on the device once (a data set of
    depth, normal and id maps from hundreds of poses). Each frame is exactly
    ``render(scene, aovs, precision, device, camera=camera)``.

    The next view is enqueued before a frame is returned: the host's work for it (checks, camera,
    the per-view pass's launch) and the return of this one overlap the device's run of this one,
    and the device goes from one view's kernel to the next without waiting for the host. An error
    of a view is raised after the frames before it."""
    scene = as_scene(scene)
    pending = None
    try:
        for camera in cameras:
            view = replace(scene, camera=camera.camera, image=camera.image) if isinstance(camera, Scene) else camera
            try:
                if isinstance(view, Scene):
                    started = _start(view, aovs, precision, device, acceleration=acceleration)
                else:
                    started = _start(scene, aovs, precision, device, acceleration=acceleration, camera=view)
            except Exception:
                if pending is not None:  # the frames before it first
                    frame, pending = pending(), None
                    yield frame
                raise
            if pending is not None:
                frame, pending = pending(), None
                yield frame
            pending = started
        if pending is not None:
            frame, pending = pending(), None
            yield frame
    finally:
        if pending is not None:  # left early: the last view's kernel still writes into its arrays
            pending()


def render_animation(scene, aovs=AOVS, precision: str = "fp32", device=None, frames=None):
    """Yield (t, Frame) for each frame of the scene's animation: frame k at t = k / fps is
    exactly ``render(scene.at(t), aovs, precision, device)``. frames: the frame indices (a range
    or any iterable of ints; default all of them)."""
    animation = scene.animation
    if animation is None:
        raise SceneError("the scene has no [animation] table", file=scene.source)
    for k in range(animation.frame_count()) if frames is None else frames:
        t = animation.frame_time(k)
        # scene.at(t) with its shapes held as the animated scene's and the changes (O(K) work)
        yield t, render(scene_at(scene, checked_time(t), lazy=True), aovs=aovs, precision=precision, device=device)
