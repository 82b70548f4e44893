"""Data sets: many views of one scene written in the formats vision pipelines read (BOP with COCO
annotations, or a file of arrays per view), resumable (run.py), rendered on scene handles
(views.py), here or on a Dask cluster (pyclray.apps.cluster).

    from pyclray.io.dataset import Placement, view_cameras, make_format, write_dataset
    cameras = view_cameras(scene, Placement("hemisphere", seed=1), 100)
    write_dataset(scene, "out/", cameras, make_format("bop"))
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

from ...model.errors import RequestError
from .arrays import ArraysFormat
from .bop import BopFormat
from .images import id_image, mask_image, png_bytes
from .placement import PLACEMENTS, Placement, labelled_centre, look_pose, read_poses, view_cameras
from .run import check_output, complete_views, finish_output, remove_temporaries, start_output, write_view, ViewWriters
from .views import DatasetViews, EncodedView, RenderedView

FORMATS = ("bop", "npz", "exr")
# Views per task on a cluster: a task renders them in a row, encoding each while the next renders
# (a task of one view would leave the worker's device idle while it encodes)
REMOTE_BATCH = 4

__all__ = ["FORMATS", "PLACEMENTS", "ArraysFormat", "BopFormat", "DatasetViews", "EncodedView", "Placement",
           "RenderedView", "Written", "id_image", "labelled_centre", "look_pose", "make_format", "mask_image",
           "png_bytes", "read_poses", "view_cameras", "write_dataset"]


def make_format(kind: str, aovs=None, unit: float = 1.0, depth_scale: float = 1.0):
    """The writer of a format: "bop" (unit: metres per scene unit; depth_scale: mm per depth PNG
    level), "npz" or "exr" (aovs: the images each view's file holds)."""
    if kind == "bop":
        if aovs:
            raise RequestError("aovs: the bop format writes its own images (rgb, depth, masks); aovs are for npz and exr")
        if not (unit > 0 and depth_scale > 0):
            raise RequestError(f"unit and depth_scale: expected numbers > 0, got {unit!r} and {depth_scale!r}")
        return BopFormat(unit, depth_scale)
    if kind in ("npz", "exr"):
        return ArraysFormat(kind, tuple(aovs or ("depth", "normal", "id")))
    raise RequestError(f"format: expected one of {', '.join(FORMATS)}, got {kind!r}")


@dataclass
class Written:
    """What a run did: views rendered now, views found complete, seconds spent rendering (the loop
    here, or waiting for the cluster) and in all, the writers' busy seconds, the index files."""

    rendered: int
    skipped: int
    render_seconds: float
    total_seconds: float
    writer_seconds: float
    index_files: list


def default_writers() -> int:
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count() or 1
    return max(2, min(8, cores))


def write_dataset(scene, out, cameras, fmt, *, settings: dict | None = None, precision: str = "fp32", device=None,
                  writers: int | None = None, progress=None, remote=None, motion=None) -> Written:
    """Render every camera's view of `scene` and write it into the folder `out` in format `fmt`
    (make_format), resuming a run there: complete views are kept, the others rendered.

    settings: what a resumed run must share (JSON-ready; the format's own and the views' are
    added). progress: something with update(n) (a tqdm bar), advanced per view written. remote:
    None to render here, or a callable (work: DatasetViews, batches: lists of view indices) ->
    iterator of each batch's list of EncodedView (work(batch)), in order, which renders elsewhere (a
    Dask cluster: pyclray.apps.cluster.map_work). motion: for the
    flow AOV, the next frame's shapes (pyclray.engine.queries.motion.Motion(shapes, None): each view
    keeps its camera); None: the scene does not move."""
    out = Path(out)
    cameras = list(cameras)
    settings = {**(settings or {}), "format": fmt.name, **fmt.settings(), "views": len(cameras),
                "width": scene.image.width, "height": scene.image.height, "precision": precision}
    fmt.check(scene)
    resuming = check_output(out, settings)
    start = time.perf_counter()
    if resuming:
        remove_temporaries(out)
    start_output(out, settings, fmt, scene)
    done = complete_views(out, len(cameras))
    todo = [k for k in range(len(cameras)) if k not in done]
    work = DatasetViews(scene, cameras, fmt, precision, device, motion)
    pool = ViewWriters(writers or default_writers(), on_done=(lambda: progress.update(1)) if progress else None)
    render_seconds = 0.0
    views = None
    try:
        if remote is None:
            # the renders here, each view's encoding and files on a writer thread
            views = work.views(todo)
            for _ in todo:
                before = time.perf_counter()
                rendered = next(views)
                render_seconds += time.perf_counter() - before
                pool.submit(lambda r=rendered: write_view(out, work.encode(r)))
        else:
            before = time.perf_counter()
            batches = [todo[i:i + REMOTE_BATCH] for i in range(0, len(todo), REMOTE_BATCH)]
            for encoded_views in remote(work, batches):
                for encoded in encoded_views:
                    pool.submit(write_view, out, encoded)
            render_seconds = time.perf_counter() - before
        pool.finish()
    except BaseException:
        pool.stop()
        raise
    finally:
        if views is not None:
            views.close()  # (its last view's kernel waited for) before the handles close
        work.close()
    index = finish_output(out, fmt, scene, len(cameras))
    return Written(len(todo), len(done), render_seconds, time.perf_counter() - start, pool.busy, index)
