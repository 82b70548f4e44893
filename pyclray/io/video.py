"""Rendering an animation: the frames as an iterator, and `pyclray animate` writing them to a video
(.mp4), a GIF or a folder of per-frame EXR and PNG files.

One warm program renders every frame: a frame changes only the scene's values (pyclray/animation.py),
never the shape types, AOVs or precision that select the program, so the first frame builds it
(or reads it from the caches) and the others reuse it; see render.py for what each frame uploads.

Outputs are complete or absent: a video is written to a temporary file beside it and a folder to a
temporary folder beside it, renamed into place only after the last frame; an error or Ctrl-C removes
them. Encoding runs in a writer thread fed through a short queue, alongside the next frames' renders.
"""
from __future__ import annotations

import os
import queue
import re
import shutil
import subprocess
import tempfile
import threading
import time
from contextlib import ExitStack, closing
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .device import AOVS, RENDER_AOVS

# the image a video or GIF shows unless --aov says otherwise (the contract's default)
DEFAULT_AOV = "shaded"

VIDEO_SUFFIXES = (".mp4", ".gif")
FRAME_NAME = re.compile(r"frame_\d+(\.[a-z]+)?\.(exr|png)")  # what an animate folder holds
VIDEO_CRF = 18  # H.264 constant rate factor: 18 is visually lossless for these flat previews
# x264's ultrafast preset: with the packet kernel a 512x512 frame renders in about 1.4 ms, and
# ultrafast encodes one in about 2.7 ms where veryfast takes 4.7 ms and medium 14 ms (one shared
# core); its files are larger (3.2 kB a frame for tp02_orbit against 1.4 kB) but still small,
# since the previews of a ray caster are smooth and noiseless
VIDEO_PRESET = "ultrafast"
QUEUE_FRAMES = 4  # frames rendered ahead of the writer: enough to keep it busy, little memory


def render_animation(scene, aovs=AOVS, precision: str = "fp32", device=None, frames=None):
    """Yield (t, Frame) for each frame of the scene's animation: frame k at t = k / fps is
    exactly ``render(scene.at(t), aovs, precision, device)``. frames: the frame indices (a range
    or any iterable of ints; default all of them)."""
    from .errors import SceneError
    from .render import render

    animation = scene.animation
    if animation is None:
        raise SceneError("the scene has no [animation] table", file=scene.source)
    for k in range(animation.frame_count()) if frames is None else frames:
        t = animation.frame_time(k)
        yield t, render(scene.at(t), aovs=aovs, precision=precision, device=device)


def frame_range(text: str, count: int) -> range:
    """--frames A:B (A..B-1, either end may be left out, as a Python slice) or K (frame K alone)."""
    from .cli import BadInput

    try:
        if ":" in text:
            first, _, last = text.partition(":")
            start = int(first) if first.strip() else 0
            stop = int(last) if last.strip() else count
        else:
            start = int(text)
            stop = start + 1
    except ValueError:
        raise BadInput(f"--frames: expected A:B (frames A to B-1) or K, got {text!r}") from None
    if not 0 <= start < stop <= count:
        raise BadInput(f"--frames: expected 0 <= A < B <= {count} (the animation has {count} frames), got {text!r}")
    return range(start, stop)


def _has_preview(aov: str) -> bool:
    from . import output

    return aov in output.PREVIEWS


def _preview(aov: str, image) -> np.ndarray:
    from . import output

    return output.preview(aov, image)


# -- sinks: where frames go --------------------------------------------------------------------
# A sink writes a frame with write(k, frame). Its encoder() is a picklable function of a Frame alone
# (the compression and the previews, most of a frame's writing time), and store(k, encoder()(frame))
# does what write(k, frame) does: a cluster's workers encode (pyclray/cluster.py), the client stores.
@dataclass(frozen=True)
class _FrameFiles:
    """A frame's files in an animate folder: FRAME.exr (every AOV asked) and its previews FRAME.AOV.png,
    as `pyclray render --png` writes them. Called on a Frame: [(suffix, bytes)] of those files,
    written by the same writer into a scratch folder and read back: the stored files are the same bytes."""

    comment: str

    def write(self, exr: Path, frame):
        from . import output

        height, width = next(iter(frame.values())).shape[:2]
        output.write_images(exr, output.frame_bands(frame), width=width, height=height, aovs=tuple(frame),
                            previews=True, comment=self.comment)

    def __call__(self, frame) -> list[tuple[str, bytes]]:
        with tempfile.TemporaryDirectory(prefix="pyclray-frame-") as scratch:
            self.write(Path(scratch, "frame.exr"), frame)
            return [(name[len("frame"):], Path(scratch, name).read_bytes()) for name in sorted(os.listdir(scratch))]


class _Folder:
    """Per-frame EXR (every AOV asked) and a PNG preview of each AOV that has one, in a temporary
    folder beside OUTDIR that replaces OUTDIR at the end."""

    def __init__(self, out: Path, digits: int, comment: str):
        self.out, self.digits, self.comment = out, digits, comment
        self.tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))

    def _stem(self, k) -> str:
        return str(self.tmp / f"frame_{k:0{self.digits}d}")

    def encoder(self):
        return _FrameFiles(self.comment)

    def write(self, k, frame):
        # frame_K.exr and its previews frame_K.AOV.png, as `pyclray render --png` writes them
        self.encoder().write(Path(self._stem(k) + ".exr"), frame)

    def store(self, k, files):
        for suffix, data in files:
            with open(self._stem(k) + suffix, "xb") as file:  # mode 0666 less the umask, as the writer's
                file.write(data)
                file.flush()
                os.fsync(file.fileno())  # on disk before the folder is renamed, as write_images leaves its files

    def finish(self):
        os.chmod(self.tmp, 0o777 & ~_umask())  # as an ordinary new folder, not mkdtemp's 0700
        if self.out.exists():  # holding only an earlier animate's frames (checked again): swap, then delete
            foreign = sorted(p.name for p in self.out.iterdir() if not FRAME_NAME.fullmatch(p.name))
            if foreign:
                raise FileExistsError(f"{self.out} gained files animate did not write (e.g. {foreign[0]}) while it rendered")
            self.old = Path(tempfile.mkdtemp(dir=self.out.parent, prefix=f".{self.out.name}.", suffix=".old"))
            os.replace(self.out, self.old / "frames")
            os.replace(self.tmp, self.out)
            shutil.rmtree(self.old, ignore_errors=True)
        else:
            os.replace(self.tmp, self.out)

    def abort(self):
        old = getattr(self, "old", None)
        if old is not None and (old / "frames").is_dir() and not self.out.exists():
            os.replace(old / "frames", self.out)  # interrupted mid-swap: the earlier folder goes back
        for folder in (self.tmp, old):
            if folder is not None:
                shutil.rmtree(folder, ignore_errors=True)


class _Video:
    """An H.264 .mp4 through the ffmpeg that imageio-ffmpeg ships, fed raw RGB frames on a pipe,
    written at ``tmp`` (a temporary beside the output, renamed by output.replace_together)."""

    def __init__(self, tmp: str, out: Path, aov: str, fps: float, width: int, height: int):
        import imageio_ffmpeg

        self.out, self.aov = out, aov
        self.log = tempfile.TemporaryFile()
        command = [
            imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error",
            "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{width}x{height}", "-r", repr(fps), "-i", "-",
            "-an", "-c:v", "libx264", "-preset", VIDEO_PRESET, "-crf", str(VIDEO_CRF), "-pix_fmt", "yuv420p",
            # 4:2:0 needs even sides: an odd width or height gains one black column or row
            "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-movflags", "+faststart", "-f", "mp4", str(tmp),
        ]
        # its own session: Ctrl-C reaches pyclray only, which then stops ffmpeg
        self.process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                        stderr=self.log, start_new_session=True)

    def encoder(self):
        return _PreviewOf(self.aov)

    def write(self, k, frame):
        self.store(k, self.encoder()(frame))

    def store(self, k, rgb):
        try:
            self.process.stdin.write(rgb.data)
        except BrokenPipeError:
            raise OSError(f"ffmpeg stopped: {self._log()}") from None

    def _log(self) -> str:
        self.log.seek(0)
        lines = self.log.read().decode(errors="replace").strip().splitlines()
        return lines[-1] if lines else f"exit status {self.process.poll()}"

    def finish(self):
        self.process.stdin.close()
        if self.process.wait() != 0:
            raise OSError(f"ffmpeg failed: {self._log()}")
        self.log.close()

    def abort(self):
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait()
        for stream in (self.process.stdin, self.log):
            try:
                stream.close()
            except OSError:
                pass


class _Gif:
    """A looping GIF through Pillow, written at ``tmp`` (renamed by output.replace_together): each
    frame is turned into a palette image as it arrives (grey previews exactly; colour ones by
    Pillow's fast octree, 9 ms a frame at 512x512 and a mean error of about one level, where
    median cut takes 280 ms and errs more); all are saved at the end."""

    def __init__(self, tmp: str, aov: str, fps: float):
        self.tmp, self.aov = tmp, aov
        # GIF delays are whole centiseconds, and viewers slow delays below 2 to 10: an fps that
        # divides 100 up to 50 (25, 20, 10, ...) plays exactly, others at the nearest such delay
        self.duration_ms = 10 * max(2, round(100 / fps))
        self.images = []

    def encoder(self):
        return _PaletteImageOf(self.aov)

    def write(self, k, frame):
        self.store(k, self.encoder()(frame))

    def store(self, k, image):
        self.images.append(image)

    def finish(self):
        first, *rest = self.images
        first.save(self.tmp, format="GIF", save_all=True, append_images=rest, duration=self.duration_ms, loop=0)

    def abort(self):
        self.images.clear()


@dataclass(frozen=True)
class _PreviewOf:
    """A frame's preview of one AOV: (H, W, 3) uint8, contiguous (a video's raw frame)."""

    aov: str

    def __call__(self, frame) -> np.ndarray:
        return _preview(self.aov, frame[self.aov])


@dataclass(frozen=True)
class _PaletteImageOf:
    """A frame's preview of one AOV as a GIF frame: a Pillow image of 256 grey levels, or a palette."""

    aov: str

    def __call__(self, frame):
        from PIL import Image

        rgb = _preview(self.aov, frame[self.aov])
        if (rgb == rgb[..., :1]).all():
            return Image.fromarray(rgb[..., 0], mode="L")  # grey: 256 levels, exact
        return Image.fromarray(rgb, mode="RGB").quantize(256, method=Image.Quantize.FASTOCTREE)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


class _Writer(threading.Thread):
    """Writes frames to a sink in its own thread, so encoding overlaps the next renders; put()
    blocks while QUEUE_FRAMES frames wait, and re-raises in the caller an error of the writer."""

    def __init__(self, sink, encoded: bool = False):
        super().__init__(name="pyclray-animate-writer", daemon=True)
        self.sink = sink
        self.write = sink.store if encoded else sink.write  # encoded: items are the sink's encoder()'s
        self.frames = queue.Queue(maxsize=QUEUE_FRAMES)
        self.error = None
        self.busy = 0.0  # seconds spent writing

    def run(self):
        while (item := self.frames.get()) is not None:
            if self.error is None:
                start = time.perf_counter()
                try:
                    self.write(*item)
                except BaseException as error:  # handed to the rendering thread
                    self.error = error
                self.busy += time.perf_counter() - start

    def put(self, k, frame):
        if self.error is not None:
            raise self.error
        self.frames.put((k, frame))

    def close(self):
        """Wait for the frames in the queue to be written; raise the writer's error if it had one."""
        self.frames.put(None)
        self.join()
        if self.error is not None:
            raise self.error

    def stop(self):
        """Drop what is queued and stop (after an error or Ctrl-C in the rendering thread)."""
        self.error = self.error or InterruptedError()
        while True:
            try:
                self.frames.get_nowait()
            except queue.Empty:
                break
        self.frames.put(None)
        self.join()


# -- the command -------------------------------------------------------------------------------
def _output_kind(out: Path, text: str) -> str:
    """"mp4", "gif" or "folder" from -o; raises (exit status 2) for another suffix and for an
    output that cannot be one (a missing folder; a file where a folder is meant, or the reverse;
    a folder holding other files, which replacing it would delete)."""
    from . import output
    from .cli import BadInput
    from .errors import OutputError

    suffix = out.suffix.lower()
    if suffix in VIDEO_SUFFIXES:
        output.check_target(out)
        return suffix[1:]
    if not (text.endswith(("/", os.sep)) or out.is_dir() or not suffix):
        raise BadInput(f"-o {text}: expected OUT.mp4, OUT.gif or a folder OUTDIR/")
    if not out.parent.is_dir():
        raise OutputError(f"cannot write {out}: the folder {out.parent} does not exist; nothing was replaced")
    if out.exists() and not out.is_dir():
        raise OutputError(f"cannot write the folder {out}: it is a file; nothing was replaced")
    if out.exists():
        foreign = sorted(p.name for p in out.iterdir() if not FRAME_NAME.fullmatch(p.name))
        if foreign:
            raise OutputError(f"cannot replace the folder {out}: it holds files animate did not write (e.g. "
                              f"{foreign[0]}); give a new or empty folder; nothing was replaced")
    return "folder"


def add_command(subparsers) -> None:
    from .cli import _aovs, _size

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
    parser.add_argument("--aov", type=_aovs, metavar="LIST",
                        help=f"images to compute: one for a video or GIF (default {DEFAULT_AOV}); any of "
                        f"{','.join(RENDER_AOVS)} for a folder (default {','.join(AOVS)})")
    parser.add_argument("--frames", metavar="A:B", help="render frames A to B-1 only (either end may be left out), or K")
    parser.add_argument("--precision", choices=("fp32", "fp64"), default="fp32", help="kernel precision (default fp32)")
    parser.add_argument("--size", type=_size, metavar="WxH", help="override the scene's image size")
    parser.add_argument("--device", metavar="DEV", help="OpenCL device (as for pyclray render)")
    add_cluster_options(parser, "the frames")
    parser.set_defaults(run=run)


def add_cluster_options(parser, what: str) -> None:
    """--workers N | --scheduler ADDRESS (pyclray/cluster.py; needs the cluster extra)."""
    from .cli import _count

    group = parser.add_mutually_exclusive_group()
    group.add_argument("--workers", type=_count, metavar="N",
                       help=f"render {what} on a local Dask cluster of N worker processes (pip install 'pyclray[cluster]')")
    group.add_argument("--scheduler", metavar="ADDRESS",
                       help=f"render {what} on a running Dask cluster, e.g. tcp://host:8786 (see README, Clusters)")


def cluster_module():
    """pyclray.cluster, or a BadInput saying how to install what it needs."""
    from .cli import BadInput

    try:
        from . import cluster
    except ModuleNotFoundError as error:
        if error.name not in ("distributed", "dask"):
            raise
        raise BadInput("--workers and --scheduler need Dask distributed: pip install 'pyclray[cluster]'") from None
    return cluster


def run(args) -> int:
    from .cli import BadInput, _load

    out = Path(args.output)
    kind = _output_kind(out, args.output)
    scene = _load(args.scene, args.size)
    animation = scene.animation
    if animation is None:
        raise BadInput(f"{args.scene}: the scene has no [animation] table to animate")
    frames = frame_range(args.frames, animation.frame_count()) if args.frames else range(animation.frame_count())
    if kind == "folder":
        aovs = args.aov or AOVS
    else:
        aovs = args.aov or (DEFAULT_AOV,)
        if len(aovs) != 1 or not _has_preview(aovs[0]):
            with_preview = [a for a in RENDER_AOVS if _has_preview(a)]
            raise BadInput(f"--aov: a {kind} shows one image with a preview ({', '.join(with_preview)}), got {','.join(aovs)}")
    try:
        if kind == "mp4":
            import imageio_ffmpeg  # noqa: F401
        if kind == "gif":
            import PIL  # noqa: F401
    except ModuleNotFoundError as error:
        raise BadInput(f"writing .{kind} needs {error.name}: pip install 'pyclray[video]'") from None

    def sink(tmp):
        if kind == "folder":
            digits = max(5, len(str(animation.frame_count() - 1)))
            return _Folder(out, digits, comment=f"pyclray animate of {args.scene}")
        if kind == "mp4":
            return _Video(tmp, out, aovs[0], animation.fps, scene.image.width, scene.image.height)
        return _Gif(tmp, aovs[0], animation.fps)

    return _animate(args, scene, frames, aovs, sink, out, kind)


def _animate(args, scene, frames, aovs, make_sink, out, kind) -> int:
    """Render the frames in this thread and write them in a writer thread. A video or GIF is
    written at a temporary beside it that output.replace_together renames at the end; a folder
    manages its own temporary folder (_Folder). On any error or Ctrl-C both threads stop and the
    temporaries go: nothing partial is left, and an earlier output stays as it was."""
    from . import output
    from .cli import BadInput
    from .errors import OutputError
    from .progress import progress, seconds

    on_cluster = args.workers is not None or args.scheduler is not None
    cluster = cluster_module() if on_cluster else None
    sink = writer = None
    render_time = start_time = 0.0
    start = time.perf_counter()
    with ExitStack() as files:
        tmp = None if kind == "folder" else files.enter_context(output.replace_together([out]))[0]
        try:
            sink = make_sink(tmp)
            writer = _Writer(sink, encoded=on_cluster)
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
                raise OutputError(f"cannot write {out}: {output._reason(error)}; nothing was replaced") from None
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
