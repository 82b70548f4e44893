"""Helpers of the per-shape test files: a scene file with one shape table, and rays aimed at both
sides of an edge."""
import numpy as np
import pytest

import pyclray
from pyclray.engine.opencl.device import context_for, has_fp64

CAMERA = '[camera]\neye = [0.0, 2.0, 6.0]\ntarget = [0.0, 0.5, 0.0]\nfov = 45.0\n[image]\nwidth = 8\nheight = 8\n'


def assert_bad_table(tmp_path, table: str, index: int, kind: str, key: str):
    """A scene whose shape #index is ``table`` fails with one line naming the file, the table
    "[[shapes]] #index (kind)" and the key."""
    path = tmp_path / "bad.toml"
    shapes = '[[shapes]]\ntype = "sphere"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\n' * index
    path.write_text(CAMERA + shapes + "[[shapes]]\n" + table)
    with pytest.raises(pyclray.SceneError) as caught:
        pyclray.load_scene(path)
    error = caught.value
    message = str(error)
    assert error.file == str(path) and error.table == f"[[shapes]] #{index} ({kind})" and error.key == key, message
    assert "\n" not in message and f"'{key}'" in message and str(path) in message


def scene_of(*shapes):
    return pyclray.Scene(pyclray.Camera((0, 0, 0), (0, 0, -1)), pyclray.Image(1, 1), shapes)


def precisions():
    return ["fp32"] + (["fp64"] if has_fp64(context_for().device) else [])


def both_sides(scene, origins, points, outward, margin, precision, inside_id, outside_id):
    """Rays from origins to points on an edge moved by -margin (inside) and +margin (outside)
    along ``outward`` (unit, across the edge): the inside rays hit inside_id, the outside ones
    outside_id; and rays at the edge itself give one of the two, never NaN."""
    origins = np.asarray(origins, np.float64)
    for sign, expected in ((-1, inside_id), (1, outside_id)):
        targets = points + sign * margin * outward
        result = pyclray.cast(scene, origins, targets - origins, precision=precision)
        assert np.all(result["id"] == expected), (sign, result["id"])
    result = pyclray.cast(scene, origins, points - origins, precision=precision)
    assert np.all(np.isin(result["id"], [inside_id, outside_id]))
    assert not np.isnan(result["depth"]).any() and not np.isnan(result["normal"]).any()
