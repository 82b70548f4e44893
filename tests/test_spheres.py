"""Batches of spheres (pyclray.Spheres, TOML type = "spheres"): one shape, one id, numpy arrays and
no Python object per sphere; the primitive image says which sphere of the batch a pixel sees. A
batch is tested by the sphere's own kernel code, so its images are those of the same spheres given
one by one, bit for bit (which tests/test_sphere.py and test_shapes.py hold to the float64 oracle;
the generic suite of test_shapes.py runs batches too)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import pyclray
from pyclray.model.aovs import RENDER_AOVS

REPO = Path(__file__).resolve().parent.parent


def cloud(count=300, seed=0):
    rng = np.random.default_rng(seed)
    centers = np.column_stack([rng.uniform(-3, 3, count), rng.uniform(0.2, 2.0, count), rng.uniform(-3, 3, count)])
    return centers, rng.uniform(0.05, 0.25, count)


def scenes(centers, radii, size=(56, 40)):
    camera, image = pyclray.Camera((0.5, 2.5, 8.0), (0.0, 0.8, 0.0), fov=50.0), pyclray.Image(*size)
    ground = pyclray.Plane((0.0, 1.0, 0.0), 0.0)
    batch = pyclray.Scene(camera, image, (ground, pyclray.Spheres(centers, radii, name="cloud")))
    single = pyclray.Scene(camera, image, (ground,) + tuple(pyclray.Sphere(tuple(c), float(r)) for c, r in zip(centers.tolist(), radii.tolist())))
    return batch, single


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("acceleration", ["tiles", "bvh"])
def test_a_batch_renders_as_its_spheres_one_by_one(precision, acceleration):
    batch, single = scenes(*cloud())
    aovs = tuple(a for a in RENDER_AOVS if a != "shaded") + ("shaded",)
    ours = pyclray.render(batch, aovs=aovs, precision=precision, acceleration=acceleration)
    theirs = pyclray.render(single, aovs=aovs, precision=precision, acceleration=acceleration)
    for name in ("depth", "normal", "zdepth", "position"):
        assert np.array_equal(ours[name], theirs[name]), name
    # one id for the batch, its primitive = the index of the sphere (id - 1 among the singles)
    assert set(np.unique(ours["id"])) <= {-1, 0, 1}
    assert np.array_equal(ours["id"], np.minimum(theirs["id"], 1))
    assert np.array_equal(ours["primitive"], np.where(theirs["id"] >= 1, theirs["id"] - 1, np.where(theirs["id"] == 0, 0, -1)))
    assert np.array_equal(theirs["primitive"], np.where(theirs["id"] >= 0, 0, -1))  # single shapes: 0


def test_cast_through_a_batch_is_cast_through_its_spheres():
    batch, single = scenes(*cloud(seed=3))
    rng = np.random.default_rng(1)
    origins = rng.normal(size=(500, 3)) * 4 + (0, 2, 0)
    directions = rng.normal(size=(500, 3))
    ours, theirs = pyclray.cast(batch, origins, directions), pyclray.cast(single, origins, directions)
    assert np.array_equal(ours["depth"], theirs["depth"]) and np.array_equal(ours["normal"], theirs["normal"])
    assert np.array_equal(ours["id"], np.minimum(theirs["id"], 1))


def test_toml_inline_one_radius_and_npz_files(tmp_path):
    centers, radii = cloud(40, seed=7)
    np.savez(tmp_path / "cloud.npz", centers=centers, radii=radii)
    head = '[camera]\neye = [0.5, 2.5, 8.0]\ntarget = [0.0, 0.8, 0.0]\nfov = 50.0\n[image]\nwidth = 32\nheight = 24\n'
    (tmp_path / "file.toml").write_text(head + '[[shapes]]\ntype = "spheres"\nfile = "cloud.npz"\ncolor = [0.2, 0.4, 0.9]\n')
    inline = "\n".join(["[[shapes]]", 'type = "spheres"', f"centers = {centers.tolist()}", f"radii = {radii.tolist()}"])
    (tmp_path / "inline.toml").write_text(head + inline + "\n")
    from_file = pyclray.load_scene(tmp_path / "file.toml")
    (batch,) = from_file.shapes
    assert isinstance(batch, pyclray.Spheres) and batch.name == "spheres0" and batch.material.color == (0.2, 0.4, 0.9)
    assert np.array_equal(batch.centers, centers) and np.array_equal(batch.radii, radii)
    a, b = pyclray.render(from_file), pyclray.render(pyclray.load_scene(tmp_path / "inline.toml"))
    assert np.array_equal(a["depth"], b["depth"])
    (tmp_path / "one.toml").write_text(head + '[[shapes]]\ntype = "spheres"\ncenters = [[0, 1, 0], [1, 1, 0]]\nradius = 0.5\n')
    assert pyclray.load_scene(tmp_path / "one.toml").shapes[0].radii.tolist() == [0.5, 0.5]


@pytest.mark.parametrize(
    "body,key,message",
    [
        ('centers = [[0, 1, 0], [1, 1]]\nradius = 1.0', "centers", "expected an array of shape (N, 3)"),
        ('centers = [[0, 1, 0], [1, 1, 0]]\nradii = [1.0, -0.5]', "radii", "expected radii > 0, got -0.5 at index 1"),
        ('centers = [[0, 1, 0], [1, 1, 0], [2, 1, 0]]\nradii = [1.0, 0.0, 1.0]', "radii", "at index 1"),
        ('centers = [[0, 1, 0], [1, 1, 0]]\nradii = [1.0]', "radii", "expected 2 radii, one per centre, got 1"),
        ('centers = [[0, 1, 0], [1, 1, 0]]\nradii = [1.0, 1.0]\nradius = 2.0', "radii", "both"),
        ('centers = [[0, 1, 0]]', "radii", "neither"),
        ('centers = []\nradius = 1.0', "centers", "at least one sphere"),
        ('file = "nowhere.npz"', "file", "cannot read nowhere.npz"),
        ('file = "cloud.npz"\nradius = 1.0', "file", "not both"),
        ('file = "other.npz"', "file", "expected arrays 'centers' and 'radii'"),
        ('file = "broken.npz"', "file", "cannot read broken.npz"),  # a truncated archive (BadZipFile)
    ],
)
def test_bad_batches_are_one_scene_error_naming_the_key(tmp_path, body, key, message):
    np.savez(tmp_path / "cloud.npz", centers=np.zeros((2, 3)), radii=np.ones(2))
    np.savez(tmp_path / "other.npz", points=np.zeros((2, 3)))
    (tmp_path / "broken.npz").write_bytes((tmp_path / "cloud.npz").read_bytes()[:100])
    path = tmp_path / "bad.toml"
    path.write_text('[camera]\neye = [0, 2, 8]\ntarget = [0, 0, 0]\nfov = 45.0\n[[shapes]]\ntype = "spheres"\n' + body + "\n")
    with pytest.raises(pyclray.SceneError) as error:
        pyclray.load_scene(path)
    text = str(error.value)
    assert f"key '{key}'" in text and message in text and "[[shapes]] #0 (spheres)" in text, text
    result = subprocess.run([sys.executable, "-m", "pyclray", "render", str(path), "-o", str(tmp_path / "x.exr")],
                            capture_output=True, text=True)
    assert result.returncode == 2 and result.stderr.count("\n") == 1 and message in result.stderr
    assert not (tmp_path / "x.exr").exists()


def test_non_finite_values_name_their_index():
    with pytest.raises(pyclray.SceneError, match=r"key 'centers': expected finite numbers, got \[0.0, nan, 0.0\] at index 2"):
        pyclray.Spheres([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]], 1.0)
    with pytest.raises(pyclray.SceneError, match="key 'radii': expected finite numbers, got inf at index 0"):
        pyclray.Spheres([[0, 0, 0]], [np.inf])


def test_arrays_are_copied_and_read_only():
    centers = np.zeros((3, 3))
    batch = pyclray.Spheres(centers, np.ones(3))
    centers[0, 0] = 5.0  # the caller's array changes: the batch does not
    assert batch.centers[0, 0] == 0.0
    with pytest.raises(ValueError):
        batch.centers[0, 0] = 1.0


def test_a_batch_beyond_the_precision_is_refused_naming_the_key():
    scene = pyclray.Scene(pyclray.Camera((0, 0, 5), (0, 0, 0)), pyclray.Image(8, 8),
                          (pyclray.Spheres([[0, 0, 0], [1e30, 0, 0]], 1.0),))
    with pytest.raises(pyclray.SceneError, match="key 'centers'.*fp64 is needed"):
        pyclray.render(scene)
