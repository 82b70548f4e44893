"""Rendering a data set's views on scene handles: the scene prepared once (pyclray.prepare), and for
formats with amodal masks (BOP) each labelled shape prepared alone, its view rendered beside the
scene's with the same camera.

``DatasetViews`` is the work of one run, picklable: ``prepare()`` once per process (here, or on each
Dask worker), then ``render(k)`` or ``views(ks)`` (the next view enqueued while one is returned,
render_views) gives the arrays of view k, and ``encode(k, rendered)`` turns them into the view's
files (the format's; PNG encoding is the slow part, done off the render's path). ``__call__(k)`` is
both, for a cluster's task."""
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
        for k, tracer in enumerate(tracers):
            tracer.render(aovs=self.format.aovs if k == 0 else ("id",), window=(0, 0, 1, 1))

    def close(self) -> None:
        for tracer in self._tracers or ():
            tracer.close()
        self._tracers = None

    # -- views ---------------------------------------------------------------------------------
    def views(self, indices):
        """Yield the RenderedView of each index in order; each handle has its next view enqueued
        while this one is handed over (Tracer.render_views)."""
        self.prepare()
        indices = list(indices)
        cameras = [self.cameras[k] for k in indices]
        streams = [self._tracers[0].render_views(cameras, aovs=self.format.aovs, motion=self.motion)]
        streams += [tracer.render_views(cameras, aovs=("id",)) for tracer in self._tracers[1:]]
        try:
            for k, camera, frames in zip(indices, cameras, zip(*streams)):
                yield self._assemble(k, camera, frames)
        finally:
            for stream in streams:
                stream.close()

    def render(self, k: int) -> RenderedView:
        return next(self.views([k]))

    def _assemble(self, k, camera, frames) -> RenderedView:
        images = dict(frames[0])
        alone = []
        for tracer, frame in zip(self._tracers[1:], frames[1:]):
            mask = frame["id"] >= 0
            outside = self._outside(tracer, camera, mask)
            alone.append((mask, *outside))
        return RenderedView(k, camera, images, alone)

    def _outside(self, tracer, camera, mask):
        """The object's silhouette beyond the image (BOP counts all of it: px_count_all, bbox_obj): a
        render on a canvas three times the image's size, the image in its middle (K's principal point
        moved by the image's size), where the silhouette in the image touches its border or is
        empty. Returns (pixels outside the image, their box or None)."""
        height, width = mask.shape
        if mask.any() and not (mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any()):
            return 0, None
        K = camera.intrinsics(width, height).copy()
        K[0, 2] += width
        K[1, 2] += height
        big = Camera.from_intrinsics(K, camera.pose(), 3 * width, 3 * height)
        view = replace(tracer.scene, camera=big, image=Image(3 * width, 3 * height))
        canvas = next(iter(tracer.render_views([view], aovs=("id",))))["id"] >= 0
        canvas[height:2 * height, width:2 * width] = False
        count = int(canvas.sum())
        if not count:
            return 0, None
        ys, xs = np.nonzero(canvas)
        return count, (int(xs.min()) - width, int(ys.min()) - height, int(xs.max()) - width, int(ys.max()) - height)

    def encode(self, rendered: RenderedView) -> EncodedView:
        return self.format.encode(self.scene, rendered)

    def __call__(self, k: int) -> EncodedView:
        """View k's files (a cluster's task: rendered and encoded on the worker)."""
        encoded = self.encode(self.render(k))
        encoded.files = {path: value() if callable(value) else value for path, value in encoded.files.items()}
        return encoded
