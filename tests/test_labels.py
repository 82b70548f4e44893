"""Semantic labels (issue 27, item 11): an optional integer `label` on any shape and a `label` image
beside the instance `id`, derived on the host from the id image: one render gives instance and
class masks."""
import dataclasses
import tomllib

import numpy as np
import pytest

import pyclray
from pyclray.engine.launch import run
from pyclray.io import png
from pyclray.model.loader import scene_from_dict
from pyclray.model.shapes import REGISTRY

from conftest import REPO, SCENES

# the ground unlabelled; the others' classes (two shapes share class 7); every shape type is here
LABELS = {"ball": 7, "log": 2, "tube": 7, "mat": 0, "panel": 5, "crate": 2147483647, "pebbles": 9, "pyramid": 4}


def labelled(size=(96, 72)):
    data = tomllib.loads((SCENES / "shapes.toml").read_text())
    for table in data["shapes"]:
        if table["name"] in LABELS:
            table["label"] = LABELS[table["name"]]
    return scene_from_dict(data, source="labelled.toml").with_size(*size)


def expected_labels(scene, ids):
    table = {k: (-1 if s.label is None else s.label) for k, s in enumerate(scene.shapes)}
    return np.vectorize(lambda i: table.get(int(i), -1), otypes=[np.int32])(ids)


def test_the_scene_file_has_every_shape_type_and_its_labels():
    scene = labelled()
    assert {s.type for s in scene.shapes} == set(REGISTRY)
    assert {s.name: s.label for s in scene.shapes} == {"ground": None, **LABELS}


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("acceleration", ["tiles", "bvh"])
def test_the_label_image_is_the_label_of_the_id_image_everywhere(precision, acceleration):
    scene = labelled()
    frame = pyclray.render(scene, aovs=("depth", "id", "label"), precision=precision, acceleration=acceleration)
    assert list(frame) == ["depth", "id", "label"] and frame["label"].dtype == np.int32
    assert np.array_equal(frame["label"], expected_labels(scene, frame["id"]))
    assert (frame["label"][frame["id"] == -1] == -1).all()  # the sky
    assert (frame["label"][frame["id"] == 0] == -1).all()  # the unlabelled ground
    assert {7, 2, 0, 5, 2147483647, 9} <= set(np.unique(frame["label"]).tolist())  # every class is seen
    # the same pixels as the other images: the render without labels is the same
    plain = pyclray.render(scene, aovs=("depth", "id"), precision=precision, acceleration=acceleration)
    assert np.array_equal(plain["id"], frame["id"]) and np.array_equal(plain["depth"], frame["depth"])


def test_label_alone_is_label_alone_and_the_kernel_never_sees_it(monkeypatch):
    """Asked without id, id is made for it and dropped; the kernel's images are those of an id
    render (the same program)."""
    scene = labelled()
    variants = []
    real = run.kernel_for
    monkeypatch.setattr(run, "kernel_for", lambda ctx, variant: variants.append(variant) or real(ctx, variant))
    frame = pyclray.render(scene, aovs=("label",))
    ids = pyclray.render(scene, aovs=("id",))
    assert list(frame) == ["label"] and np.array_equal(frame["label"], expected_labels(scene, ids["id"]))
    assert variants[0] == variants[1] and variants[0].aovs == ("id",)
    window = pyclray.render(scene, aovs=("label", "normal"), window=(10, 20, 30, 11))
    assert list(window) == ["normal", "label"]
    assert np.array_equal(window["label"], frame["label"][20:31, 10:40])


def test_a_scene_without_labels_has_a_label_image_of_minus_one():
    frame = pyclray.render(pyclray.load_scene(SCENES / "tp02.toml").with_size(16, 16), aovs=("label",))
    assert (frame["label"] == -1).all()


def test_labels_in_python_and_their_checks():
    camera = pyclray.Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0))
    scene = pyclray.Scene(camera, pyclray.Image(8, 8), (pyclray.Sphere((0.0, 0.0, 0.0), 1.0, label=3),))
    assert pyclray.render(scene, aovs=("label",))["label"][4, 4] == 3
    for bad in (-1, 1.0, True, "3", 2**31):
        with pytest.raises(pyclray.SceneError) as caught:
            pyclray.Scene(camera, pyclray.Image(8, 8), (pyclray.Plane((0, 1, 0), 0.0), pyclray.Sphere((0, 0, 0), 1.0, label=bad)))
        assert caught.value.table == "[[shapes]] #1 (sphere)" and caught.value.key == "label"


@pytest.mark.parametrize("value,words", [("-1", ">= 0"), ("1.5", "whole number"), ("true", "whole number"),
                                         ('"cat"', "whole number"), ("2147483648", "<= 2147483647")])
def test_a_bad_label_in_a_scene_file_names_the_file_table_and_key(tmp_path, value, words):
    path = tmp_path / "bad.toml"
    path.write_text((SCENES / "tp02.toml").read_text() + f'\n[[shapes]]\ntype = "disk"\ncenter = [0.0, 0.0, 0.0]\n'
                    f'normal = [0.0, 1.0, 0.0]\nradius = 1.0\nlabel = {value}\n')
    with pytest.raises(pyclray.SceneError) as caught:
        pyclray.load_scene(path)
    error = caught.value
    assert error.file == str(path) and error.table.endswith("(disk)") and error.key == "label" and words in str(error)


def test_a_label_cannot_be_animated():
    scene = labelled()
    keys = pyclray.Animation(4.0, 1.0, ({"target": "ball", "time": 0.0, "label": 3},))
    with pytest.raises(pyclray.SceneError, match="cannot be animated"):
        dataclasses.replace(scene, animation=keys)


def test_the_label_image_in_files(tmp_path):
    """EXR channel `label` (UINT, the int32 pattern as id), read back as int32; its PNG preview gives
    each label a colour (as ids), misses and unlabelled shapes black."""
    import OpenEXR

    from test_output import read_png

    scene_path = tmp_path / "labelled.toml"
    data = tomllib.loads((SCENES / "shapes.toml").read_text())
    for table in data["shapes"]:
        if table["name"] in LABELS:
            table["label"] = LABELS[table["name"]]
    scene_path.write_text(toml_of(data))
    out = tmp_path / "l.exr"
    from pyclray.apps import cli

    assert cli.main(["render", str(scene_path), "-o", str(out), "--aov", "label", "--png", "--size", "64x48"]) == 0
    with OpenEXR.File(str(out), separate_channels=True) as exr:
        assert set(exr.channels()) == {"label"} and exr.channels()["label"].pixels.dtype == np.uint32
    images = pyclray.read_exr(out)
    expected = pyclray.render(pyclray.load_scene(scene_path).with_size(64, 48), aovs=("label",))["label"]
    assert list(images) == ["label"] and images["label"].dtype == np.int32 and np.array_equal(images["label"], expected)
    assert np.array_equal(read_png(tmp_path / "l.label.png"), png.id_preview(expected))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["l.exr", "l.label.png", "labelled.toml"]


def toml_of(data: dict) -> str:
    """A scene dict as TOML (numbers, strings, booleans, lists of numbers; tables and arrays of tables)."""
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v + '"'
        if isinstance(v, list):
            return "[" + ", ".join(value(c) for c in v) + "]"
        return repr(v)

    lines = []
    for name, table in data.items():
        for entry in table if isinstance(table, list) else [table]:
            lines.append(f"[[{name}]]" if isinstance(table, list) else f"[{name}]")
            lines += [f"{k} = {value(v)}" for k, v in entry.items()]
    return "\n".join(lines) + "\n"
