"""Issue 42 item 7: every error is one line, with plain numbers: a 3x4 pose given for a 4x4 one is
not printed as numpy's multi-line repr, a skewed K says 1.0 (not np.float64(1.0)), and a full disk
under `pyclray animate -o fr/` names fr/, not the hidden temporary the frames were written to."""
import errno
import os

import numpy as np
import pytest

import pyclray
from pyclray.apps.cli import main

K = np.array([[525.0, 0.0, 320.0], [0.0, 525.0, 240.0], [0.0, 0.0, 1.0]])


def test_a_3x4_pose_is_one_line_with_its_shape():
    pose = np.hstack([np.eye(3), [[0.0], [0.0], [5.0]]])
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.Camera.from_intrinsics(K, pose)
    text = str(error.value)
    assert "\n" not in text and "key 'pose'" in text and "4x4" in text and "(3, 4)" in text, text


@pytest.mark.parametrize("skew", [np.float64(1.0), np.float32(1.0), 1.0])
def test_the_skew_error_prints_a_plain_number(skew):
    bad = K.astype(object)
    bad[0, 1] = skew
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.Camera.from_intrinsics(bad.tolist() if not isinstance(skew, np.generic) else bad, np.eye(4))
    text = str(error.value)
    assert text.endswith("got 1.0") and "np." not in text, text


def test_numpy_values_are_shown_plainly_everywhere():
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.Sphere((0, 0, 0), np.float64(-1.0))
    assert "np." not in str(error.value), str(error.value)
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.Mesh(np.zeros((3, 2)), [[0, 1, 2]])
    assert "\n" not in str(error.value)


def test_animate_on_a_full_disk_names_the_output_folder(tmp_path, scenes_dir, monkeypatch, capsys):
    """The frames' writes fail with ENOSPC (a monkeypatched write: no tmpfs to fill here): one line
    naming fr/, exit status 2, no fr/ and no temporary left."""
    import pyclray.io.files as files

    real_replace = os.replace

    def full(source, target, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(target))

    monkeypatch.setattr(files.os, "replace", full)
    monkeypatch.chdir(tmp_path)
    status = main(["animate", str(scenes_dir / "tp02_orbit.toml"), "-o", "fr/", "--size", "8x8", "--aov", "depth",
                   "--frames", "0:3"])
    err = capsys.readouterr().err
    assert status == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "fr/" in lines[0] and "no space left on device" in lines[0].lower(), err
    assert ".tmp" not in lines[0] and not lines[0].count("/.")
    monkeypatch.setattr(files.os, "replace", real_replace)
    assert sorted(p.name for p in tmp_path.iterdir()) == [], list(tmp_path.iterdir())
