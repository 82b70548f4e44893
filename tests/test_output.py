"""The writers: our EXR encoder read back by OpenEXR's own reader, streamed PNG previews equal to the
whole-image ones, and the files of one command replaced together or not at all (fault injection:
a target that is a folder, a read-only folder, a full disk, an interruption between writes or
between renames)."""
import errno
import os
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

import pyclray
from pyclray.io import files
from pyclray.io import png
from pyclray.model.errors import OutputError
from pyclray.io.bands import frame_bands, write_exr, write_images
from pyclray.io.exr import ExrWriter, read_exr
from pyclray.io.files import replace_together, write_together

REPO = Path(__file__).resolve().parent.parent


def read_png(path) -> np.ndarray:
    """A minimal reader for the PNGs we write (8-bit RGB, filter 0): checks every chunk's CRC."""
    data = Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    at, idat, kinds = 8, b"", []
    while at < len(data):
        (length,) = struct.unpack(">I", data[at:at + 4])
        kind, body = data[at + 4:at + 8], data[at + 8:at + 8 + length]
        assert struct.unpack(">I", data[at + 8 + length:at + 12 + length])[0] == zlib.crc32(kind + body)
        kinds.append(kind)
        if kind == b"IHDR":
            width, height, depth, colour = struct.unpack(">IIBB", body[:10])
            assert (depth, colour) == (8, 2)
        elif kind == b"IDAT":
            idat += body
        at += 12 + length
    assert kinds[0] == b"IHDR" and kinds[-1] == b"IEND"
    rows = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(height, 1 + 3 * width)
    assert not rows[:, 0].any()  # filter type 0 on every row
    return rows[:, 1:].reshape(height, width, 3)


def random_frame(height, width, seed=0, real=np.float32):
    rng = np.random.default_rng(seed)
    depth = (rng.random((height, width)) * 100).astype(real)
    depth[rng.random((height, width)) < 0.2] = np.inf
    depth.flat[:3] = [np.nan, -0.0, np.finfo(np.float32).max][: depth.size]
    normal = rng.normal(size=(height, width, 3)).astype(real)
    ids = rng.integers(-1, 7, (height, width)).astype(np.int32)
    return {"depth": depth, "normal": normal, "id": ids}


def no_temporaries(folder) -> bool:
    return not [p.name for p in Path(folder).iterdir() if p.name.startswith(".")]


# -- the EXR encoder ------------------------------------------------------------------------------
@pytest.mark.parametrize("height,width,rows", [(1, 1, 1), (15, 7, 4), (16, 16, 16), (17, 33, 5), (100, 64, 48), (70, 300, 1000)])
def test_exr_round_trips_through_openexr_bit_for_bit(tmp_path, height, width, rows):
    """Any band height, any image size (chunks are 16 rows; the last one shorter), inf, NaN, -0,
    the largest float32 and -1 ids come back as written."""
    frame = random_frame(height, width, seed=height)
    path = tmp_path / "x.exr"
    write_images(path, frame_bands(frame, rows), width=width, height=height, aovs=tuple(frame), comment="a comment")
    back = read_exr(path)
    for name in frame:
        assert back[name].dtype == frame[name].dtype
        assert np.array_equal(back[name].view(np.uint8), frame[name].view(np.uint8)), name  # bit for bit, NaN too
    import OpenEXR

    with OpenEXR.File(str(path)) as exr:
        header = dict(exr.header())  # a copy: the File clears its own on closing
    assert header.get("comment") == "a comment", header
    assert header["compression"] == OpenEXR.ZIP_COMPRESSION


def test_exr_of_incompressible_chunks_stores_them_raw(tmp_path):
    """Random bits do not compress: such chunks are stored as they are, as OpenEXR's reader expects."""
    rng = np.random.default_rng(3)
    frame = {"depth": rng.integers(0, 2**32, (40, 50), dtype=np.uint32).view(np.float32)}
    write_exr(tmp_path / "r.exr", frame)
    assert np.array_equal(read_exr(tmp_path / "r.exr")["depth"].view(np.uint32), frame["depth"].view(np.uint32))
    assert (tmp_path / "r.exr").stat().st_size > frame["depth"].nbytes  # nothing was compressed


def test_fp64_images_are_stored_as_float32(tmp_path):
    """OpenEXR has no 64-bit float channel: fp64 depth and normals are rounded to float32."""
    frame = random_frame(20, 30, real=np.float64)
    write_exr(tmp_path / "d.exr", frame)
    back = read_exr(tmp_path / "d.exr")
    assert back["depth"].dtype == np.float32
    assert np.array_equal(back["depth"], frame["depth"].astype(np.float32), equal_nan=True)
    assert np.array_equal(back["normal"], frame["normal"].astype(np.float32))


def test_exr_writer_refuses_a_short_image(tmp_path):
    with open(tmp_path / "s.exr", "wb") as handle:
        writer = ExrWriter(handle, 4, 20, {"Z": "FLOAT"})
        writer.write({"Z": np.zeros((16, 4), np.float32)})
        with pytest.raises(ValueError, match="16 of 20 rows"):
            writer.close()


# -- previews ---------------------------------------------------------------------------------------
def test_streamed_previews_equal_the_whole_image_previews(tmp_path):
    """The depth preview's scale is the whole image's even when written band by band."""
    scene = pyclray.load_scene(REPO / "scenes/tp02.toml").with_size(40, 70)
    frame = pyclray.render(scene)
    out = tmp_path / "p.exr"
    written = write_images(out, frame_bands(frame, 16), width=40, height=70, aovs=tuple(frame), previews=True)
    assert written == [out, tmp_path / "p.depth.png", tmp_path / "p.normal.png", tmp_path / "p.id.png"]
    assert np.array_equal(read_png(tmp_path / "p.depth.png"), png.preview("depth", frame["depth"]))
    assert np.array_equal(read_png(tmp_path / "p.normal.png"), png.preview("normal", frame["normal"]))
    assert np.array_equal(read_png(tmp_path / "p.id.png"), png.id_preview(frame["id"]))
    assert no_temporaries(tmp_path)  # the depth preview's spill file is gone too


# -- replaced together or not at all ----------------------------------------------------------------
def old_files(folder, names=("o.exr", "o.depth.png", "o.normal.png")):
    for name in names:
        (folder / name).write_bytes(b"old " + name.encode())
    return {name: (folder / name).read_bytes() for name in names}


def assert_unchanged(folder, old):
    assert {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file() and p.name in old} == old
    assert no_temporaries(folder)


def small_frame():
    return pyclray.render(pyclray.load_scene(REPO / "scenes/tp02.toml").with_size(24, 20))


def test_write_together_replaces_every_file(tmp_path):
    old_files(tmp_path, ("a", "b"))
    written = write_together([(tmp_path / "a", lambda tmp: Path(tmp).write_bytes(b"new a")),
                              (tmp_path / "b", lambda tmp: Path(tmp).write_bytes(b"new b"))])
    assert written == [tmp_path / "a", tmp_path / "b"]
    assert (tmp_path / "a").read_bytes() == b"new a" and (tmp_path / "b").read_bytes() == b"new b"
    assert no_temporaries(tmp_path)
    mode = (tmp_path / "a").stat().st_mode & 0o777
    umask = os.umask(0)
    os.umask(umask)
    assert mode == 0o666 & ~umask  # an ordinary new file, not mkstemp's 0600


def test_a_target_that_is_a_folder_replaces_nothing(tmp_path):
    """Defect 1: OUT.depth.png is a folder: OUT.exr and OUT.normal.png stay old, no traceback."""
    old = old_files(tmp_path, ("o.exr", "o.normal.png"))
    (tmp_path / "o.depth.png").mkdir()
    with pytest.raises(OutputError, match=r"o\.depth\.png: it is a folder; nothing was replaced"):
        write_images(tmp_path / "o.exr", frame_bands(small_frame()), width=24, height=20,
                     aovs=("depth", "normal", "id"), previews=True)
    assert_unchanged(tmp_path, old)


def test_a_full_disk_replaces_nothing(tmp_path, monkeypatch):
    """Defect 2: ENOSPC while the second file is written (a patched writer): one OutputError,
    the old files intact, no temporary left."""
    old = old_files(tmp_path)
    real_write = png.PngWriter.write

    def full(self, rgb):
        real_write(self, rgb)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(png.PngWriter, "write", full)
    with pytest.raises(OutputError, match="cannot write .*: no space left on device; nothing was replaced"):
        write_images(tmp_path / "o.exr", frame_bands(small_frame()), width=24, height=20,
                     aovs=("depth", "normal", "id"), previews=True)
    assert_unchanged(tmp_path, old)


def test_a_read_only_folder_is_one_clear_error(tmp_path, monkeypatch):
    """Defect 2: a folder we may not write in. As root permissions do not stop us, so there the
    refusal is injected where the system would raise it (creating the temporary)."""
    old = old_files(tmp_path, ("o.exr",))
    if os.geteuid() == 0:
        def refuse(*args, **kwargs):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(tmp_path / ".o.exr.x.tmp"))

        monkeypatch.setattr(files.tempfile, "mkstemp", refuse)
    else:
        tmp_path.chmod(0o555)
    try:
        with pytest.raises(OutputError, match=r"cannot write .*o\.exr: permission denied; nothing was replaced"):
            write_exr(tmp_path / "o.exr", small_frame())
    finally:
        tmp_path.chmod(0o755)
    assert_unchanged(tmp_path, old)


def test_an_interruption_between_writes_replaces_nothing(tmp_path, monkeypatch):
    """Ctrl-C after the EXR and the normal preview are written, before the depth preview is."""
    old = old_files(tmp_path)

    def interrupt(self):
        raise KeyboardInterrupt

    monkeypatch.setattr(png.PngWriter, "close", interrupt)
    with pytest.raises(KeyboardInterrupt):
        write_images(tmp_path / "o.exr", frame_bands(small_frame()), width=24, height=20,
                     aovs=("depth", "normal", "id"), previews=True)
    assert_unchanged(tmp_path, old)


@pytest.mark.parametrize("failure", [OSError(errno.EIO, "Input/output error"), KeyboardInterrupt()])
def test_a_failed_rename_puts_the_renamed_files_back(tmp_path, monkeypatch, failure):
    """The second of three renames fails: the first target gets its old file back."""
    old = old_files(tmp_path, ("a", "b", "c"))
    real_replace = os.replace
    calls = []

    def flaky(source, target):
        calls.append(target)
        if len(calls) == 2:
            raise failure
        real_replace(source, target)

    monkeypatch.setattr(files.os, "replace", flaky)
    with pytest.raises(type(failure) if isinstance(failure, KeyboardInterrupt) else OutputError):
        with replace_together([tmp_path / n for n in ("a", "b", "c")]) as temporaries:
            for tmp in temporaries:
                Path(tmp).write_bytes(b"new")
    assert_unchanged(tmp_path, old)


def test_a_missing_folder_or_a_repeated_target(tmp_path):
    with pytest.raises(OutputError, match="does not exist"):
        write_together([(tmp_path / "no" / "x", lambda tmp: None)])
    with pytest.raises(OutputError, match="twice"):
        write_together([(tmp_path / "x", lambda tmp: None), (tmp_path / "." / "x", lambda tmp: None)])
    assert list(tmp_path.iterdir()) == []
