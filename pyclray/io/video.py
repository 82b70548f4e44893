"""Where an animation's frames go: a video (.mp4, H.264 through the ffmpeg of imageio-ffmpeg), a
GIF (Pillow) or a folder of per-frame EXR and PNG files, each written by a writer thread fed through
a short queue while the next frames render.

Outputs are complete or absent: a video is written to a temporary file beside it and a folder to a
temporary folder beside it, renamed into place only after the last frame; an error or Ctrl-C removes
them.
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
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..model.errors import OutputError
from .bands import frame_bands, camera_of, write_images
from .files import reason
from .png import PREVIEWS, preview


VIDEO_SUFFIXES = (".mp4", ".gif")
FRAME_NAME = re.compile(r"frame_\d+(\.[a-z]+)?\.(exr|png)")  # what an animate folder holds
VIDEO_CRF = 18  # H.264 constant rate factor: 18 is visually lossless for these flat previews
# x264's ultrafast preset: it encodes a frame in about the time one renders, where slower presets take
# several times that; its files are larger but still small, since the previews of a ray caster are
# smooth and noiseless (docs/benchmarks.md, "Why the engine does what it does")
VIDEO_PRESET = "ultrafast"
QUEUE_FRAMES = 4  # frames rendered ahead of the writer: enough to keep it busy, little memory


def has_preview(aov: str) -> bool:
    return aov in PREVIEWS


# -- sinks: where frames go --------------------------------------------------------------------
# A sink writes a frame with write(k, frame). Its encoder() is a picklable function of a Frame alone
# (the compression and the previews, most of a frame's writing time), and store(k, encoder()(frame))
# does what write(k, frame) does: a cluster's workers encode (pyclray/apps/cluster.py), the client stores.
@dataclass(frozen=True)
class FrameFiles:
    """A frame's files in an animate folder: FRAME.exr (every AOV asked) and its previews FRAME.AOV.png,
    as `pyclray render --png` writes them. Called on a Frame: [(suffix, bytes)] of those files,
    written by the same writer into a scratch folder and read back: the stored files are the same bytes."""

    comment: str

    def write(self, exr: Path, frame):
        height, width = next(iter(frame.values())).shape[:2]
        write_images(exr, frame_bands(frame), width=width, height=height, aovs=tuple(frame),
                            previews=True, comment=self.comment, camera=camera_of(frame))

    def __call__(self, frame) -> list[tuple[str, bytes]]:
        with tempfile.TemporaryDirectory(prefix="pyclray-frame-") as scratch:
            self.write(Path(scratch, "frame.exr"), frame)
            return [(name[len("frame"):], Path(scratch, name).read_bytes()) for name in sorted(os.listdir(scratch))]


class Folder:
    """Per-frame EXR (every AOV asked) and a PNG preview of each AOV that has one, in a temporary
    folder beside OUTDIR that replaces OUTDIR at the end."""

    def __init__(self, out: Path, digits: int, comment: str):
        self.out, self.digits, self.comment = out, digits, comment
        self.tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))

    def _stem(self, k) -> str:
        return str(self.tmp / f"frame_{k:0{self.digits}d}")

    def encoder(self):
        return FrameFiles(self.comment)

    def write(self, k, frame):
        # frame_K.exr and its previews frame_K.AOV.png, as `pyclray render --png` writes them
        with self._named():
            self.encoder().write(Path(self._stem(k) + ".exr"), frame)

    def store(self, k, files):
        with self._named():
            for suffix, data in files:
                with open(self._stem(k) + suffix, "xb") as file:  # mode 0666 less the umask, as the writer's
                    file.write(data)
                    file.flush()
                    os.fsync(file.fileno())  # on disk before the folder is renamed, as write_images leaves its files

    @contextmanager
    def _named(self):
        """A failed write (a full disk) said of OUTDIR/frame_K..., the name the user gave, not of the
        hidden temporary folder the frames go to first."""
        try:
            yield
        except OutputError as error:
            raise OutputError(str(error).replace(str(self.tmp), str(self.out))) from None
        except OSError as error:
            name = Path(error.filename).name if getattr(error, "filename", None) else ""
            raise OutputError(f"cannot write {self.out / name if name else str(self.out) + os.sep}: "
                              f"{reason(error)}; nothing was replaced") from None

    def finish(self):
        os.chmod(self.tmp, 0o777 & ~umask())  # as an ordinary new folder, not mkdtemp's 0700
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


class Video:
    """An H.264 .mp4 through the ffmpeg that imageio-ffmpeg ships, fed raw RGB frames on a pipe,
    written at ``tmp`` (a temporary beside the output, renamed by files.replace_together)."""

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
        return PreviewOf(self.aov)

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


class Gif:
    """A looping GIF through Pillow, written at ``tmp`` (renamed by files.replace_together): each frame
    is turned into a palette image as it arrives (grey previews exactly; colour ones by Pillow's fast
    octree, quicker than median cut and closer; docs/benchmarks.md, "Why the engine does what it does");
    all are saved at the end."""

    def __init__(self, tmp: str, aov: str, fps: float):
        self.tmp, self.aov = tmp, aov
        # GIF delays are whole centiseconds, and viewers slow delays below 2 to 10: an fps that
        # divides 100 up to 50 (25, 20, 10, ...) plays exactly, others at the nearest such delay
        self.duration_ms = 10 * max(2, round(100 / fps))
        self.images = []

    def encoder(self):
        return PaletteImageOf(self.aov)

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
class PreviewOf:
    """A frame's preview of one AOV: (H, W, 3) uint8, contiguous (a video's raw frame)."""

    aov: str

    def __call__(self, frame) -> np.ndarray:
        return preview(self.aov, frame[self.aov])


@dataclass(frozen=True)
class PaletteImageOf:
    """A frame's preview of one AOV as a GIF frame: a Pillow image of 256 grey levels, or a palette."""

    aov: str

    def __call__(self, frame):
        from PIL import Image

        rgb = preview(self.aov, frame[self.aov])
        if (rgb == rgb[..., :1]).all():
            return Image.fromarray(rgb[..., 0], mode="L")  # grey: 256 levels, exact
        return Image.fromarray(rgb, mode="RGB").quantize(256, method=Image.Quantize.FASTOCTREE)


def umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


class Writer(threading.Thread):
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
