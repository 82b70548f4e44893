"""The plane's own cases (the properties every shape has are in tests/test_shapes.py): parallel
rays and rays from the plane miss it, and its Mitsuba stand-in disk lies within the far clip."""
import numpy as np

import pyclray
from pyclray.reference import mitsuba
from pyclray.model.shapes import Plane



def scene_of(*shapes):
    return pyclray.Scene(pyclray.Camera((0, 0, 0), (0, 0, -1)), pyclray.Image(1, 1), shapes)


def test_parallel_rays_and_rays_from_the_plane_miss():
    plane = Plane((0, 1, 0), 0.0)
    frame = pyclray.cast(scene_of(plane), [[0, 1, 0], [0, 0, 0], [0, 0, 0], [0, -1, 0]],
                         [[1, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 0]])
    assert np.isinf(frame["depth"][:3]).all() and (frame["id"][:3] == -1).all()
    assert frame["depth"][3] == 1.0 and np.array_equal(frame["normal"][3], [0, 1, 0])  # from below


def test_the_stand_in_disk_lies_within_the_far_clip(scenes_dir):
    """far_clip is beyond the farthest point of the disk standing in for each plane."""
    for path in sorted(scenes_dir.glob("*.toml")):
        scene = pyclray.load_scene(path)
        _, far = mitsuba.clip_range(scene)
        eye = np.array(scene.camera.eye)
        for shape in scene.shapes:
            if isinstance(shape, Plane):
                centre, _, radius = shape.mitsuba_disk(scene)
                assert far > np.hypot(radius, np.linalg.norm(eye - centre)) * 1.01
