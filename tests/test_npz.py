"""The .npz output (issue 27, item 10): every AOV as a numpy array under its name, in its own type
(fp64 stays float64), with the camera's K and pose; streamed band by band into a file numpy.load
reads; replaced together with the previews or not at all; read_npz's errors one line."""
import errno
import os
import zipfile

import numpy as np
import pytest

import pyclray
from pyclray.io import npz, png
from pyclray.io.bands import frame_bands, write_images
from pyclray.model.errors import OutputError

from conftest import SCENES
from test_output import no_temporaries, random_frame, read_png

TP02 = SCENES / "tp02.toml"
EVERY = ("depth", "normal", "id", "zdepth", "position", "shaded", "label")


@pytest.mark.parametrize("height,width,rows", [(1, 1, 1), (17, 33, 5), (70, 40, 16), (30, 20, 1000)])
def test_streamed_npz_holds_the_arrays_as_numpy_savez_would(tmp_path, height, width, rows):
    frame = random_frame(height, width, seed=width, real=np.float64)
    extra = {"K": np.eye(3), "pose": np.arange(16.0).reshape(4, 4)}
    path = tmp_path / "x.npz"
    assert write_images(path, frame_bands(frame, rows), width=width, height=height, aovs=tuple(frame),
                        camera=(extra["K"], extra["pose"])) == [path]
    with np.load(path, allow_pickle=False) as archive:
        assert archive.files == [*frame, "K", "pose"]
        for name, array in {**frame, **extra}.items():
            assert archive[name].dtype == array.dtype and archive[name].shape == array.shape, name
            assert np.array_equal(archive[name].view(np.uint8), array.view(np.uint8)), name  # bit for bit, NaN too
    assert zipfile.ZipFile(path).infolist()[0].compress_type == zipfile.ZIP_DEFLATED  # as numpy.savez_compressed
    assert no_temporaries(tmp_path) and sorted(p.name for p in tmp_path.iterdir()) == ["x.npz"]


def test_write_npz_and_read_npz_with_the_frames_camera(tmp_path):
    scene = pyclray.load_scene(TP02).with_size(48, 32)
    frame = pyclray.render(scene, aovs=EVERY, precision="fp64")
    pyclray.write_npz(tmp_path / "f.npz", frame)  # a render's Frame: its camera as K and pose
    back = pyclray.read_npz(tmp_path / "f.npz")
    assert list(back) == [*frame, "K", "pose"]
    for name in frame:
        assert back[name].dtype == frame[name].dtype and np.array_equal(back[name], frame[name]), name
    assert back["depth"].dtype == np.float64  # unlike an EXR, the .npz keeps fp64
    assert np.array_equal(back["K"], scene.camera.intrinsics(48, 32)) and np.array_equal(back["pose"], scene.camera.pose())
    window = pyclray.render(scene, aovs=("depth",), window=(8, 4, 16, 12))  # a window's K: its own pixels
    pyclray.write_npz(tmp_path / "w.npz", window)
    assert np.array_equal(pyclray.read_npz(tmp_path / "w.npz")["K"], window.intrinsics)
    pyclray.write_npz(tmp_path / "g.npz", dict(frame))  # a plain dict of images: the images only
    assert list(pyclray.read_npz(tmp_path / "g.npz")) == list(frame)


def test_k_and_pose_back_project_the_depth_onto_the_positions(tmp_path):
    """What K and pose are for: pose @ [depth * normalize(K^-1 [i, j, 1]), 1] is the world hit
    point (the position image), for every pixel that hits (K in OpenCV's pixel convention, centres
    at integers, since the sensors issue: it was [i + 0.5, j + 0.5, 1])."""
    from pyclray.apps import cli

    out = tmp_path / "v.npz"
    assert cli.main(["render", str(SCENES / "shapes.toml"), "-o", str(out), "--aov", "depth,position", "--size", "64x48"]) == 0
    data = pyclray.read_npz(out)
    j, i = np.mgrid[0:48, 0:64]
    pixels = np.stack([i, j, np.ones_like(i, float)], axis=-1)
    rays = pixels @ np.linalg.inv(data["K"]).T
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    hit = np.isfinite(data["depth"])
    camera_points = rays[hit] * data["depth"][hit, None].astype(np.float64)
    world = camera_points @ data["pose"][:3, :3].T + data["pose"][:3, 3]
    assert hit.sum() > 1000
    assert np.allclose(world, data["position"][hit], rtol=0, atol=1e-4 * (1 + np.abs(world).max()))


def test_the_command_writes_npz_and_previews_in_bands(tmp_path, monkeypatch, capsys):
    """-o OUT.npz --png: OUT.npz (the arrays of the whole image, streamed in bands of 16 rows here)
    and OUT.<aov>.png beside it; the last line names the arrays."""
    from pyclray.apps import cli
    from pyclray.io import bands

    monkeypatch.setattr(bands, "band_rows", lambda width: 16)
    out = tmp_path / "b.npz"
    assert cli.main(["render", str(TP02), "-o", str(out), "--png", "--size", "40x70", "--aov", "depth,id,label"]) == 0
    assert "[depth, id, label, K, pose]" in capsys.readouterr().out
    scene = pyclray.load_scene(TP02).with_size(40, 70)
    whole = pyclray.render(scene, aovs=("depth", "id", "label"))
    data = pyclray.read_npz(out)
    for name in whole:
        assert np.array_equal(data[name], whole[name]), name
    assert np.array_equal(read_png(tmp_path / "b.depth.png"), png.preview("depth", whole["depth"]))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.depth.png", "b.id.png", "b.label.png", "b.npz"]


def test_a_full_disk_while_writing_the_npz_replaces_nothing(tmp_path, monkeypatch):
    for name in ("o.npz", "o.depth.png"):
        (tmp_path / name).write_bytes(b"old")

    def full(self):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(npz.NpzWriter, "close", full)
    frame = random_frame(20, 24)
    with pytest.raises(OutputError, match="no space left on device; nothing was replaced"):
        write_images(tmp_path / "o.npz", frame_bands(frame, 8), width=24, height=20, aovs=tuple(frame), previews=True)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == {"o.npz": b"old", "o.depth.png": b"old"}


def test_read_npz_of_a_bad_file_is_one_output_error(tmp_path):
    np.savez(tmp_path / "good.npz", depth=np.zeros((2, 2), np.float32))
    (tmp_path / "text.npz").write_text("not an archive\n")
    (tmp_path / "cut.npz").write_bytes((tmp_path / "good.npz").read_bytes()[:100])
    np.save(tmp_path / "plain.npy", np.zeros(3))
    cases = {"missing.npz": "no such file or directory", ".": "is a directory", "text.npz": "not an .npz file",
             "plain.npy": "not an .npz file", "cut.npz": "a damaged .npz file"}
    for name, reason in cases.items():
        with pytest.raises(OutputError) as caught:
            pyclray.read_npz(tmp_path / name)
        assert str(caught.value).startswith(f"cannot read {tmp_path / name}: {reason}") and "\n" not in str(caught.value)
    assert list(pyclray.read_npz(tmp_path / "good.npz")) == ["depth"]


def test_npz_is_compressed_as_numpy_savez_compressed(tmp_path):
    """Issue 42 item 11: every member deflated (what numpy.savez_compressed writes): a 640x480
    depth, normal and id of tp02 takes far less than its 640*480*20 bytes of arrays, and reads back
    bit for bit."""
    scene = pyclray.load_scene(TP02).with_size(640, 480)
    frame = pyclray.render(scene, aovs=("depth", "normal", "id"))
    path = tmp_path / "view.npz"
    pyclray.write_npz(path, frame)
    assert all(info.compress_type == zipfile.ZIP_DEFLATED for info in zipfile.ZipFile(path).infolist())
    assert path.stat().st_size < 0.4 * 640 * 480 * 20, path.stat().st_size
    back = pyclray.read_npz(path)
    for name in ("depth", "normal", "id"):
        assert np.array_equal(back[name], frame[name]), name
