"""pyclray sample: SDF and occupancy training data. The file's arrays against the queries and the
float64 oracle, the two kinds of points (uniform in the bounds, jittered about the surfaces), the seed,
bad options (one line, exit status 2, no file written), and the file replaced whole or not at all."""
import numpy as np
import pytest

import pyclray
from pyclray.apps import cli
from pyclray.reference import oracle

from conftest import SCENES

SCENE = SCENES / "mesh.toml"


def run(capsys, *args):
    try:
        status = cli.main(["sample", str(SCENE), *map(str, args)])
    except SystemExit as exit_:  # argparse's own errors (options.Parser: one line, status 2)
        status = exit_.code
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_writes_points_with_their_answers(tmp_path, capsys):
    out = tmp_path / "samples.npz"
    status, text, _ = run(capsys, "-o", out, "--points", 3000, "--near-surface", 0.01, "--seed", 3, "--precision", "fp64")
    assert status == 0 and "3000 points" in text
    data = np.load(out)
    assert set(data.files) == {"points", "sdf", "occupancy", "closest", "normal", "id", "bounds"}
    points = data["points"]
    assert points.shape == (3000, 3) and data["sdf"].dtype == np.float64 and data["occupancy"].dtype == np.uint8
    scene = pyclray.load_scene(SCENE)
    # the answers are the queries' (and so the oracle's: tests/test_closest.py, tests/test_sdf.py)
    assert np.array_equal(data["sdf"], pyclray.signed_distance(scene, points, precision="fp64"))
    assert np.array_equal(data["occupancy"], pyclray.occupancy(scene, points, precision="fp64"))
    nearest = pyclray.closest_points(scene, points, precision="fp64")
    assert np.array_equal(data["closest"], nearest["position"]) and np.array_equal(data["id"], nearest["id"])
    assert np.array_equal(data["normal"], nearest["normal"])
    truth = oracle.signed_distance(scene, points[:300])
    assert np.allclose(data["sdf"][:300], truth, rtol=0, atol=1e-12)
    # the first half uniform in the bounds, the second within a few sigma of the surfaces
    lo, hi = data["bounds"]
    assert (points[:1500] >= lo).all() and (points[:1500] <= hi).all()
    assert np.abs(data["sdf"][1500:]).max() < 0.01 * 6
    assert np.median(np.abs(data["sdf"][:1500])) > 10 * np.median(np.abs(data["sdf"][1500:]))
    # both sides of the surfaces are sampled
    assert 0 < data["occupancy"][1500:].mean() < 1


def test_uniform_only_and_seed(tmp_path, capsys):
    a, b, c = tmp_path / "a.npz", tmp_path / "b.npz", tmp_path / "c.npz"
    assert run(capsys, "-o", a, "--points", 500, "--seed", 1)[0] == 0
    assert run(capsys, "-o", b, "--points", 500, "--seed", 1)[0] == 0
    assert run(capsys, "-o", c, "--points", 500, "--seed", 2, "--sign", "winding")[0] == 0
    first, second, third = np.load(a), np.load(b), np.load(c)
    assert all(np.array_equal(first[k], second[k]) for k in first.files)
    assert not np.array_equal(first["points"], third["points"])
    lo, hi = first["bounds"]
    assert (first["points"] >= lo).all() and (first["points"] <= hi).all()


@pytest.mark.parametrize("args, message", [
    (["--points", "0"], "--points: expected a whole number >= 1, got '0'"),
    (["--points", "10", "--near-surface", "-1"], "--near-surface: expected a distance > 0"),
    (["--points", "10", "--near-surface", "nan"], "--near-surface: expected a distance > 0"),
    (["--points", "10", "--seed", "x"], "--seed: expected a whole number >= 0"),
    (["--points", "10", "--sign", "even"], "--sign: invalid choice"),
    ([], "the following arguments are required: --points"),
])
def test_bad_options(tmp_path, capsys, args, message):
    out = tmp_path / "s.npz"
    status, _, err = run(capsys, "-o", out, *args)
    assert status == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_bad_output_and_scene(tmp_path, capsys):
    status, _, err = run(capsys, "-o", tmp_path / "s.txt", "--points", 5)
    assert status == 2 and "expected OUT.npz" in err and len(err.strip().splitlines()) == 1
    status, _, err = run(capsys, "-o", tmp_path / "missing" / "s.npz", "--points", 5)
    assert status == 2 and len(err.strip().splitlines()) == 1
    planes = tmp_path / "planes.toml"
    planes.write_text('[camera]\neye = [0, 1, 5]\ntarget = [0, 0, 0]\nfov = 40.0\n[[shapes]]\ntype = "plane"\nnormal = [0, 1, 0]\noffset = 0.0\n')
    status = cli.main(["sample", str(planes), "-o", str(tmp_path / "p.npz"), "--points", "5"])
    err = capsys.readouterr().err
    assert status == 2 and "no bounded shape" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "p.npz").exists()


def test_old_file_kept_when_the_run_fails(tmp_path, capsys, monkeypatch):
    out = tmp_path / "s.npz"
    out.write_bytes(b"old")
    from pyclray.engine import tracer

    def broken(self, points, sign="parity"):
        raise pyclray.PyclrayError("broken on purpose")

    monkeypatch.setattr(tracer.Tracer, "signed_distance", broken)
    status, _, err = run(capsys, "-o", out, "--points", 10)
    assert status == 1 and "broken on purpose" in err
    assert out.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["s.npz"]
