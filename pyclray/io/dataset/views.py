"""Rendering a data set's views on scene handles: the scene prepared once (pyclray.prepare), and for
formats with amodal masks (BOP) each labelled shape prepared alone, its view rendered beside the
scene's with the same camera, where the object may lie hidden (the rest of its amodal mask is its
visible mask: DatasetViews._start_alone).

``DatasetViews`` is the work of one run, picklable: ``prepare()`` once per process (here, or on each
Dask worker), then ``render(k)`` or ``views(ks)`` (the device's next work enqueued while a view is
read and returned) gives the arrays of view k, and ``encode(rendered)`` turns them into the view's files
(the format's; PNG encoding is the slow part, done off the render's path). ``__call__(ks)`` is both
for a few views, a cluster's task."""
from __future__ import annotations

import functools
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from ...model.camera import Camera, Image


@dataclass
class RenderedView:
    """What view k's files are made of: its camera, the scene's images, and per labelled shape (the
    format's objects) its amodal mask in the image and the pixels of its silhouette outside the
    image (a count and their box (x0, y0, x1, y1) in the image's pixel coordinates, or None)."""

    index: int
    camera: Camera
    images: dict
    alone: list = field(default_factory=list)  # per object: (mask, outside count, outside box or None)


@dataclass
class EncodedView:
    """View k's files, relative path -> bytes (or a callable writing the file at a path), and its
    record (what the data set's index files say of it, JSON-ready)."""

    index: int
    files: dict
    record: dict


class DatasetViews:
    """The work of one data set run: the scene, the views' cameras, the format (it says which images
    it needs and whether it needs each object alone), precision and device, and for flow the next
    frame's shapes (motion: engine/queries/motion.py's Motion, its camera None: each view's own)."""

    def __init__(self, scene, cameras, fmt, precision: str = "fp32", device=None, motion=None):
        self.scene, self.cameras, self.format = scene, list(cameras), fmt
        self.precision, self.device, self.motion = precision, device, motion
        self._tracers = None

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_tracers"] = None  # each process prepares its own
        state.pop("_object_boxes", None)
        state.pop("_object_ids", None)
        state.pop("_object_spaces", None)
        return state

    # -- the handles ---------------------------------------------------------------------------
    def prepare(self) -> None:
        """The scene's handle and, where the format asks, one handle per object (its shape alone),
        each built once, with their programs (a one-pixel render each)."""
        from ...engine.tracer import prepare

        if self._tracers is not None:
            return
        scene = self.scene
        tracers = [prepare(scene, self.device, self.precision)]
        if self.format.needs_alone:
            for shape in self.format.objects(scene):
                alone = replace(scene, shapes=(shape,), animation=None, lights=())
                tracers.append(prepare(alone, self.device, self.precision))
        self._tracers = tracers
        self._object_boxes = [tracer.scene.shapes[0].box() for tracer in tracers[1:]]  # for their windows
        objects = self.format.objects(scene) if self.format.needs_alone else []
        self._object_ids = [next(i for i, s in enumerate(scene.shapes) if s is shape) for shape in objects]
        self._object_spaces = [_object_space(tracer.scene.shapes[0]) for tracer in tracers[1:]]
        for k, tracer in enumerate(tracers):
            tracer.render(aovs=self.format.aovs if k == 0 else ("id",), window=(0, 0, 1, 1))

    def close(self) -> None:
        for tracer in self._tracers or ():
            tracer.close()
        self._tracers = None

    # -- views ---------------------------------------------------------------------------------
    def views(self, indices):
        """Yield the RenderedView of each index in order. The scene's renders run ahead: with
        objects alone, view k's windowed renders are enqueued once its scene render is back (their
        windows come from its id and zdepth) and the render of view k + 2 right after them, so the
        device has a view's work queued while the host reads one; without, the next view is
        enqueued while this one is handed over (Tracer.render_views)."""
        self.prepare()
        indices = list(indices)
        if self.format.needs_alone:
            yield from self._views_with_objects(indices)
            return
        cameras = [self.cameras[k] for k in indices]
        stream = self._tracers[0].render_views(cameras, aovs=self.format.aovs, motion=self.motion)
        try:
            for k, camera, frame in zip(indices, cameras, stream):
                yield RenderedView(k, camera, dict(frame))
        finally:
            stream.close()

    def _views_with_objects(self, indices):
        from ...engine.queries.render import with_camera

        tracer = self._tracers[0]
        todo = iter(indices)
        ahead = deque()  # (k, its scene render's result callable), enqueued in view order
        started = []  # a view's renders of the objects alone, in flight

        def start_next():
            k = next(todo, None)
            if k is None:
                return
            try:
                view = with_camera(tracer.scene, self.cameras[k])
                ahead.append((k, tracer.start_render(view, self.format.aovs, motion=self.motion)))
            except Exception as error:  # raised in its turn, after the views before it
                ahead.append((k, functools.partial(_raise, error)))

        try:
            start_next()
            start_next()
            while ahead:
                k, pending = ahead.popleft()
                frame = dict(pending())
                camera = self.cameras[k]
                size = next(iter(frame.values())).shape[:2]
                self._start_alone(camera, size, frame, started)
                start_next()  # queued behind them: the device's next work while the host waits and reads
                alone = self._finish_alone(started, size, frame)
                started.clear()
                yield RenderedView(k, camera, frame, alone)
        finally:  # left early: the kernels in flight still write into their arrays
            _wait(started)
            _wait(pending for _, pending in ahead)

    def render(self, k: int) -> RenderedView:
        return next(self.views([k]))

    def _start_alone(self, camera, shape, frame, started: list) -> None:
        """Enqueue the renders of the objects alone that their amodal masks need (a window's pixels
        are the whole image's, bit for bit), appending per object to started: (its window in the
        image, that render's result callable; None where none is needed, its canvas windows and
        renders' callables, or None). frame: the scene's images of the view.

        - In the image, where the frame has id and zdepth and the camera is a pinhole (the rays
          from K and the pose): only over the box of the pixels where the object may lie hidden
          (_hidden_window: another shape seen there, not beyond where the pixel's ray leaves the
          box of the object's model in its own space, _object_space). Everywhere else the object alone is hit exactly where the scene shows it
          (the same ray meets the same triangles: a pixel that sees nothing meets none of them,
          one that sees a shape beyond the object's box cannot meet the object, which would be
          nearer), so its mask there is its visible pixels (_finish_alone). Otherwise over the
          window its box projects to.
        - Beyond the image, where the box reaches out: on a canvas three times the image's size
          (the image in its middle, K's principal point moved by the image's size), over the
          parts of the box's window outside the image, as BOP's calc_gt_info counts px_count_all
          and bbox_obj."""
        height, width = shape
        K, pose = camera.intrinsics(width, height), camera.pose()
        pinhole = K is not None and camera.rays_from_eye and camera.space_directions(width, height) is None
        hidden = pinhole and frame is not None and "id" in frame and "zdepth" in frame
        canvas_camera = None
        for tracer, box, shape_id, own in zip(self._tracers[1:], self._object_boxes, self._object_ids,
                                              self._object_spaces):
            window = _projected_window(box, K, pose)  # in image pixels, or None: anywhere
            inside = _clip(window, 0, 0, width, height)
            reaches_out = window is None or inside != window
            if hidden and inside is not None:
                inside = _hidden_window(frame["id"], frame["zdepth"], shape_id, inside, own, K, pose)
            seen = replace(tracer.scene, camera=camera)
            in_image = None if inside is None else tracer.start_render(seen, ("id",), window=inside, warn_pose=False)
            beyond = None
            if reaches_out:
                if canvas_camera is None:
                    big_K = K.copy()
                    big_K[0, 2] += width
                    big_K[1, 2] += height
                    canvas_camera = Camera.from_intrinsics(big_K, pose, 3 * width, 3 * height)
                view = replace(tracer.scene, camera=canvas_camera, image=Image(3 * width, 3 * height))
                on_canvas = None if window is None else (window[0] + width, window[1] + height, window[2], window[3])
                area = _clip(on_canvas, 0, 0, 3 * width, 3 * height)
                beyond = [(part, tracer.start_render(view, ("id",), window=part, warn_pose=False))
                          for part in _around(area, width, height, width, height)]
            started.append((inside, in_image, beyond))

    def _finish_alone(self, rendered, shape, frame=None) -> list:
        """The masks and outside counts of _start_alone's renders (each waited for): each object's
        mask is its render's hits, and its visible pixels where the scene's frame has ids."""
        height, width = shape
        ids = None if frame is None else frame.get("id")
        alone = []
        for (inside, in_image, beyond), shape_id in zip(rendered, self._object_ids):
            mask = np.zeros((height, width), bool) if ids is None else ids == shape_id
            if in_image is not None:
                x, y, w, h = inside
                mask[y:y + h, x:x + w] |= in_image()["id"] >= 0
            count, corners = 0, []
            for (x, y, w, h), pending in beyond or ():
                ys, xs = np.nonzero(pending()["id"] >= 0)
                if len(xs):
                    count += len(xs)
                    xs, ys = xs + x - width, ys + y - height  # image pixel coordinates
                    corners += [(int(xs.min()), int(ys.min())), (int(xs.max()), int(ys.max()))]
            box = None
            if corners:
                box = (min(c[0] for c in corners), min(c[1] for c in corners), max(c[0] for c in corners),
                       max(c[1] for c in corners))
            alone.append((mask, count, box))
        return alone

    def encode(self, rendered: RenderedView) -> EncodedView:
        return self.format.encode(self.scene, rendered)

    def _encoded(self, rendered: RenderedView) -> EncodedView:
        encoded = self.encode(rendered)
        encoded.files = {path: value() if callable(value) else value for path, value in encoded.files.items()}
        return encoded

    def __call__(self, indices) -> list[EncodedView]:
        """The files of these views (a cluster's task: rendered and encoded on the worker), each
        view encoded on a thread of its own while the next ones render."""
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=2, thread_name_prefix="pyclray-dataset-encoder") as pool:
            encoding = [pool.submit(self._encoded, rendered) for rendered in self.views(indices)]
            return [future.result() for future in encoding]


def _projected_window(box, K, pose, margin: int = 2):
    """(x, y, width, height) in pixels holding the projection of the box's corners, a margin
    wider (rounding, and either pixel convention), or None where a corner is not in front of the
    camera (then the object may be anywhere in the image)."""
    corners = np.array([[box[i][0], box[j][1], box[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    in_camera = (corners - pose[:3, 3]) @ pose[:3, :3]
    z = in_camera[:, 2]
    if not (z > 1e-9 * max(1.0, float(np.abs(in_camera).max()))).all():
        return None
    pixels = (in_camera @ K.T)[:, :2] / z[:, None]
    low = np.floor(pixels.min(axis=0)) - margin
    high = np.ceil(pixels.max(axis=0)) + margin
    if not (np.isfinite(low).all() and np.isfinite(high).all()) or (np.abs(np.concatenate([low, high])) > 2**30).any():
        return None
    return int(low[0]), int(low[1]), int(high[0] - low[0]) + 1, int(high[1] - low[1]) + 1


def _raise(error: Exception):
    raise error


def _wait(renders) -> None:
    """Wait for renders in flight (result callables, or _start_alone's entries), their errors
    dropped (an error on the way out is already raised)."""
    for render in renders:
        calls = [render] if callable(render) else [render[1], *(pending for _, pending in render[2] or ())]
        for call in calls:
            try:
                call is None or call()
            except Exception:
                pass


def _around(area, x0: int, y0: int, width: int, height: int) -> list:
    """The parts of the window area (x, y, w, h; None: nothing) outside the rectangle at (x0, y0)
    of that size, as at most four windows: the rows above it, those below, and beside it on the
    left and on the right."""
    if area is None:
        return []
    x, y, w, h = area
    x1, y1 = x + w, y + h
    parts = [(x, y, w, min(y1, y0) - y), (x, max(y, y0 + height), w, y1 - max(y, y0 + height))]
    top, bottom = max(y, y0), min(y1, y0 + height)
    parts += [(x, top, min(x1, x0) - x, bottom - top), (max(x, x0 + width), top, x1 - max(x, x0 + width), bottom - top)]
    return [part for part in parts if part[2] > 0 and part[3] > 0]


def _clip(window, x0: int, y0: int, width: int, height: int):
    """The part of window (x, y, w, h) inside the rectangle at (x0, y0) of that size, or None; a
    window of None is the whole rectangle."""
    if window is None:
        return x0, y0, width, height
    x, y, w, h = window
    left, top = max(x, x0), max(y, y0)
    right, bottom = min(x + w, x0 + width), min(y + h, y0 + height)
    if right <= left or bottom <= top:
        return None
    return left, top, right - left, bottom - top


# how much wider the box and how much nearer the exit a pixel's ray may be counted with: the host's
# float rays and the render's fp32 depths differ from the kernel's rays and hits by far less
HIDDEN_BOX_MARGIN = 1e-3  # of the box's largest side
HIDDEN_DEPTH_MARGIN = 1e-3  # of the depth seen


def _object_space(shape):
    """(low, high, object_from_world 4x4) of the box holding the shape in its own space (its
    model's box, where it has a model and an invertible pose: tighter than the world box of a
    turned object), else its world box and the identity."""
    model, pose = shape.object_model(), shape.object_pose()
    if model is not None and pose is not None:
        vertices = np.asarray(model[0], np.float64)
        pose = np.asarray(pose, np.float64)
        if len(vertices) and abs(np.linalg.det(pose[:3, :3])) > 0:
            return vertices.min(axis=0), vertices.max(axis=0), np.linalg.inv(pose)
    box = shape.box()
    return box[0], box[1], np.eye(4)


def _hidden_window(ids, zdepth, shape_id: int, window, own, K, pose):
    """(x, y, width, height) of the pixels of window (in the image) where the object shape_id may
    lie behind what the scene's render shows there, or None where it can nowhere: where another
    shape is seen (ids, zdepth: the scene's images) and the pixel's ray leaves the object's box
    (own: _object_space's, grown by the margins) no nearer than that shape's depth. The ray of
    pixel (u, v) is R K^-1 [u, v, 1] from the eye (OpenCV's pixel centres, as K), whose parameter is
    the depth along the optical axis; taken into the object's space it keeps its parameter, so it
    compares with zdepth as it is."""
    x, y, w, h = window
    ids = ids[y:y + h, x:x + w]
    other = (ids >= 0) & (ids != shape_id)
    rows, columns = np.flatnonzero(other.any(axis=1)), np.flatnonzero(other.any(axis=0))
    if not len(rows):
        return None
    y0, y1, x0, x1 = rows[0], rows[-1] + 1, columns[0], columns[-1] + 1
    other = other[y0:y1, x0:x1]
    seen = zdepth[y + y0:y + y1, x + x0:x + x1]
    low, high, object_from_world = own
    eye = object_from_world[:3, :3] @ pose[:3, 3] + object_from_world[:3, 3]
    rays = object_from_world[:3, :3] @ pose[:3, :3] @ np.linalg.inv(K)  # row i: the ray's component i from (u, v, 1)
    u = np.arange(x + x0, x + x1, dtype=np.float64)
    v = np.arange(y + y0, y + y1, dtype=np.float64)
    grow = (HIDDEN_BOX_MARGIN * float((high - low).max())
            + 1e-6 * max(float(np.abs(low).max()), float(np.abs(high).max()), float(np.abs(eye).max())))
    near = np.full(other.shape, -np.inf, np.float32)
    far = np.full(other.shape, np.inf, np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        for i in range(3):  # the ray's slab of the box along axis i: a NaN (0 / 0) bounds nothing
            d = ((rays[i, 1] * v)[:, None] + (rays[i, 0] * u + rays[i, 2])[None, :]).astype(np.float32)
            a = np.float32(low[i] - grow - eye[i]) / d
            b = np.float32(high[i] + grow - eye[i]) / d
            np.fmax(near, np.minimum(a, b), out=near)
            np.fmin(far, np.maximum(a, b), out=far)
        hidden = other & (far >= near) & (far >= seen * np.float32(1 - HIDDEN_DEPTH_MARGIN))
    rows, columns = np.flatnonzero(hidden.any(axis=1)), np.flatnonzero(hidden.any(axis=0))
    if not len(rows):
        return None
    return (int(x + x0 + columns[0]), int(y + y0 + rows[0]), int(columns[-1] - columns[0] + 1),
            int(rows[-1] - rows[0] + 1))
