"""Rendering a data set's views on scene handles: the scene prepared once (pyclray.prepare), and for
formats with amodal masks (BOP) each labelled shape prepared alone, its view rendered beside the
scene's with the same camera.

``DatasetViews`` is the work of one run, picklable: ``prepare()`` once per process (here, or on each
Dask worker), then ``render(k)`` or ``views(ks)`` (the next view enqueued while one is returned,
render_views) gives the arrays of view k, and ``encode(rendered)`` turns them into the view's files
(the format's; PNG encoding is the slow part, done off the render's path). ``__call__(ks)`` is both
for a few views, a cluster's task."""
from __future__ import annotations

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
        for k, tracer in enumerate(tracers):
            tracer.render(aovs=self.format.aovs if k == 0 else ("id",), window=(0, 0, 1, 1))

    def close(self) -> None:
        for tracer in self._tracers or ():
            tracer.close()
        self._tracers = None

    # -- views ---------------------------------------------------------------------------------
    def views(self, indices):
        """Yield the RenderedView of each index in order; the scene's handle has its next view
        enqueued while this one is handed over (Tracer.render_views)."""
        self.prepare()
        indices = list(indices)
        cameras = [self.cameras[k] for k in indices]
        stream = self._tracers[0].render_views(cameras, aovs=self.format.aovs, motion=self.motion)
        try:
            for k, camera, frame in zip(indices, cameras, stream):
                size = next(iter(frame.values())).shape[:2]
                yield RenderedView(k, camera, dict(frame), self._alone(camera, size))
        finally:
            stream.close()

    def render(self, k: int) -> RenderedView:
        return next(self.views([k]))

    def _alone(self, camera, shape) -> list:
        """Per object, its amodal mask in the image and its silhouette beyond it (see RenderedView):
        renders of the object alone, only over the window its box projects to (a window's pixels are
        the whole image's, bit for bit), on a canvas three times the image's size (the image in its
        middle, K's principal point moved by the image's size) where that box reaches beyond the
        image, as BOP's calc_gt_info counts px_count_all and bbox_obj."""
        height, width = shape
        K, pose = camera.intrinsics(width, height), camera.pose()
        canvas_camera = None
        started = []
        for tracer, box in zip(self._tracers[1:], self._object_boxes):
            window = _projected_window(box, K, pose)  # in image pixels, or None: anywhere
            inside = _clip(window, 0, 0, width, height)
            reaches_out = window is None or inside != window
            seen = replace(tracer.scene, camera=camera)
            in_image = None if inside is None else tracer.start_render(seen, ("id",), window=inside)
            beyond = None
            if reaches_out:
                if canvas_camera is None:
                    big_K = K.copy()
                    big_K[0, 2] += width
                    big_K[1, 2] += height
                    canvas_camera = Camera.from_intrinsics(big_K, pose, 3 * width, 3 * height)
                view = replace(tracer.scene, camera=canvas_camera, image=Image(3 * width, 3 * height))
                on_canvas = None if window is None else (window[0] + width, window[1] + height, window[2], window[3])
                area = _clip(on_canvas, 0, 0, 3 * width, 3 * height) if window is not None else (0, 0, 3 * width, 3 * height)
                if area is not None:
                    beyond = (area, tracer.start_render(view, ("id",), window=area))
            started.append((inside, in_image, beyond))
        alone = []
        for inside, in_image, beyond in started:
            mask = np.zeros((height, width), bool)
            if in_image is not None:
                x, y, w, h = inside
                mask[y:y + h, x:x + w] = in_image()["id"] >= 0
            count, box = 0, None
            if beyond is not None:
                (x, y, w, h), pending = beyond
                hit = pending()["id"] >= 0
                ys, xs = np.nonzero(hit)
                xs, ys = xs + x - width, ys + y - height  # image pixel coordinates
                outside = (xs < 0) | (xs >= width) | (ys < 0) | (ys >= height)
                count = int(outside.sum())
                if count:
                    xs, ys = xs[outside], ys[outside]
                    box = (int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max()))
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
