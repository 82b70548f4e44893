"""`pyclray animate`: every frame of a scene's [animation] to a video, a GIF or a folder of EXR and
PNG files (pyclray.io.video), rendered here or on a Dask cluster.

One warm program renders every frame: a frame changes only the scene's values, never the shape
types, AOVs or precision that select the program, so the first frame builds it (or reads it from
the caches) and the others reuse it.
"""
from __future__ import annotations

import os
import time
from contextlib import ExitStack, closing
from pathlib import Path

from ...io import video
from ...io.files import check_target, reason, replace_together
from ...io.progress import progress, seconds
from ...model.aovs import AOVS, RENDER_AOVS
from ...model.errors import OutputError
from .options import BadInput, add_cluster_options, aov_list, cluster_module, image_size, load

# the image a video or GIF shows unless --aov says otherwise (the contract's default)
DEFAULT_AOV = "shaded"


def frame_range(text: str, count: int | None) -> range:
    """--frames A:B (A..B-1, either end may be left out, as a Python slice) or K (frame K alone);
    with count None only its form is checked."""
    try:
        if ":" in text:
            first, _, last = text.partition(":")
            start = int(first) if first.strip() else 0
            stop = int(last) if last.strip() else (count or 0)
        else:
            start = int(text)
            stop = start + 1
    except ValueError:
        raise BadInput(f"--frames: expected A:B (frames A to B-1) or K, got {text!r}") from None
    if count is None:  # the form alone (the animation's length is not known yet)
        return range(0)
    if not 0 <= start < stop <= count:
        raise BadInput(f"--frames: expected 0 <= A < B <= {count} (the animation has {count} frames), got {text!r}")
    return range(start, stop)


# -- the command -------------------------------------------------------------------------------
def _output_kind(out: Path, text: str) -> str:
    """"mp4", "gif" or "folder" from -o; raises (exit status 2) for another suffix and for an
    output that cannot be one (a missing folder; a file where a folder is meant, or the reverse;
    a folder holding other files, which replacing it would delete)."""

    suffix = out.suffix.lower()
    if suffix in video.VIDEO_SUFFIXES:
        check_target(out)
        return suffix[1:]
    if not (text.endswith(("/", os.sep)) or out.is_dir() or not suffix):
        raise BadInput(f"-o {text}: expected OUT.mp4, OUT.gif or a folder OUTDIR/")
    if not out.parent.is_dir():
        raise OutputError(f"cannot write {out}: the folder {out.parent} does not exist; nothing was replaced")
    if out.exists() and not out.is_dir():
        raise OutputError(f"cannot write the folder {out}: it is a file; nothing was replaced")
    if out.exists():
        foreign = sorted(p.name for p in out.iterdir() if not video.FRAME_NAME.fullmatch(p.name))
        if foreign:
            raise OutputError(f"cannot replace the folder {out}: it holds files animate did not write (e.g. "
                              f"{foreign[0]}); give a new or empty folder; nothing was replaced")
    return "folder"


def add_command(subparsers) -> None:
    parser = subparsers.add_parser(
        "animate",
        help="render every frame of a scene's [animation] to a video, a GIF or a folder of EXR/PNG files",
        description="Render every frame k of SCENE's animation (t = k / fps) and write OUT.mp4 (H.264) or "
        "OUT.gif of one image's preview, or a folder OUTDIR/ holding frame_NNNNN.exr (every image asked, "
        "channels as for `pyclray render`) and frame_NNNNN.AOV.png previews. The output is complete or "
        "absent: it is written under a temporary name and renamed at the end; Ctrl-C removes it (exit 130).",
    )
    parser.add_argument("scene", metavar="SCENE", help="scene file (TOML) with an [animation] table")
    parser.add_argument("-o", "--output", required=True, metavar="OUT.mp4|OUT.gif|OUTDIR/",
                        help="a video (.mp4), a GIF (.gif), or a folder (a name ending in / or without a suffix)")
    parser.add_argument("--aov", type=aov_list, metavar="LIST",
                        help=f"images to compute: one for a video or GIF (default {DEFAULT_AOV}); any of "
                        f"{','.join(RENDER_AOVS)} for a folder (default {','.join(AOVS)})")
    parser.add_argument("--frames", metavar="A:B", help="render frames A to B-1 only (either end may be left out), or K")
    parser.add_argument("--precision", choices=("fp32", "fp64"), default="fp32", help="kernel precision (default fp32)")
    parser.add_argument("--size", type=image_size, metavar="WxH", help="override the scene's image size")
    parser.add_argument("--device", metavar="DEV", help="OpenCL device (as for pyclray render)")
    add_cluster_options(parser, "the frames")
    parser.set_defaults(run=run)


def run(args) -> int:
    # every option that can be checked alone is checked first, before the scene is read and before
    # any slow import (Dask, pyopencl): a typo costs nothing
    out = Path(args.output)
    kind = _output_kind(out, args.output)
    if kind == "folder":
        aovs = args.aov or AOVS
    else:
        aovs = args.aov or (DEFAULT_AOV,)
        if len(aovs) != 1 or not video.has_preview(aovs[0]):
            with_preview = [a for a in RENDER_AOVS if video.has_preview(a)]
            raise BadInput(f"--aov: a {kind} shows one image with a preview ({', '.join(with_preview)}), got {','.join(aovs)}")
    if args.frames:
        frame_range(args.frames, None)  # its form; its range once the animation's length is known
    try:
        if kind == "mp4":
            import imageio_ffmpeg  # noqa: F401
        if kind == "gif":
            import PIL  # noqa: F401
    except ModuleNotFoundError as error:
        raise BadInput(f"writing .{kind} needs {error.name}: pip install 'pyclray[video]'") from None
    if args.workers is not None or args.scheduler is not None:
        cluster_module()  # installed? (before the scene: it says what to install)
    scene = load(args.scene, args.size)
    animation = scene.animation
    if animation is None:
        raise BadInput(f"{args.scene}: the scene has no [animation] table to animate")
    frames = frame_range(args.frames, animation.frame_count()) if args.frames else range(animation.frame_count())

    def sink(tmp):
        if kind == "folder":
            digits = max(5, len(str(animation.frame_count() - 1)))
            return video.Folder(out, digits, comment=f"pyclray animate of {args.scene}")
        if kind == "mp4":
            return video.Video(tmp, out, aovs[0], animation.fps, scene.image.width, scene.image.height)
        return video.Gif(tmp, aovs[0], animation.fps)

    return _animate(args, scene, frames, aovs, sink, out, kind)


def _animate(args, scene, frames, aovs, make_sink, out, kind) -> int:
    """Render the frames in this thread and write them in a writer thread. A video or GIF is
    written at a temporary beside it that files.replace_together renames at the end; a folder
    manages its own temporary folder (video.Folder). On any error or Ctrl-C both threads stop and the
    temporaries go: nothing partial is left, and an earlier output stays as it was."""
    from ...engine.api import render_animation

    on_cluster = args.workers is not None or args.scheduler is not None
    cluster = cluster_module() if on_cluster else None
    sink = writer = None
    render_time = start_time = 0.0
    start = time.perf_counter()
    with ExitStack() as files:
        tmp = None if kind == "folder" else files.enter_context(replace_together([out]))[0]
        try:
            sink = make_sink(tmp)
            writer = video.Writer(sink, encoded=on_cluster)
            writer.start()
            with progress(len(frames), desc="pyclray animate", unit="frame") as bar:
                if on_cluster:
                    # the workers render and encode each frame (sink.encoder()); this thread hands
                    # the encoded frames over in order and the writer stores them
                    with cluster.connect(args.workers, args.scheduler) as client:
                        start_time = time.perf_counter() - start
                        where = cluster.describe(client)
                        before = time.perf_counter()
                        sequence = cluster.render_animation(client, scene, aovs, args.precision, args.device, frames,
                                                            encode=sink.encoder(), progress=bar)
                        with closing(sequence):  # on an error here: the tasks in flight are cancelled
                            for k, (_, encoded) in zip(frames, sequence):
                                writer.put(k, encoded)
                        render_time = time.perf_counter() - before
                else:
                    sequence = render_animation(scene, aovs, args.precision, args.device, frames)
                    for k in frames:
                        before = time.perf_counter()
                        _, frame = next(sequence)
                        render_time += time.perf_counter() - before
                        writer.put(k, frame)
                        bar.update()
                writer.close()
                finish_start = time.perf_counter()
                sink.finish()
        except BaseException as error:
            if writer is not None:
                writer.stop()
            if sink is not None:
                sink.abort()
            if kind == "folder" and isinstance(error, OSError) and not isinstance(error, (OutputError, InterruptedError)):
                raise OutputError(f"cannot write {out}{os.sep}: {reason(error)}; nothing was replaced") from None
            if on_cluster and isinstance(error, cluster.ClusterError):
                raise BadInput(str(error)) from None
            raise
    finish_time = time.perf_counter() - finish_start  # with the rename of a video or GIF
    total = time.perf_counter() - start
    count = len(frames)
    rate = f"{count / render_time:.1f} frames/s"
    if on_cluster:
        work = (f"cluster start {seconds(start_time)} ({where}), render and encode on the workers "
                f"{seconds(render_time)} ({rate}), write {seconds(writer.busy + finish_time)} "
                f"({seconds(writer.busy)} alongside, {seconds(finish_time)} at the end)")
    else:
        work = (f"render {seconds(render_time)} ({rate}), {'write' if kind == 'folder' else 'encode'} "
                f"{seconds(writer.busy + finish_time)} ({seconds(writer.busy)} alongside the renders, "
                f"{seconds(finish_time)} at the end)")
    print(
        f"animated {args.scene}: {count} frame{'s' if count != 1 else ''} ({frames.start}:{frames.stop}) of "
        f"{scene.image.width}x{scene.image.height} {','.join(aovs)} in {seconds(total)} ({count / total:.1f} frames/s): "
        f"{work}; wrote {out}"
    )
    return 0
