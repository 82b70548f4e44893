"""The view's live editing (pyclray/apps/view/watch.py): a save changes the files' signature however
the editor writes (in place, or beside and renamed over), the files a scene names are watched, and
a scene loaded again reuses the prepared scene (no shape changed) or updates it in place (one
changed), with the same images as a fresh render of the file."""
import os

import numpy as np
import pytest

import pyclray
from conftest import REPO
from pyclray.apps.view import watch
from pyclray.model.animation import derivation

TP02 = (REPO / "scenes/tp02.toml").read_text()


def test_in_place_and_renamed_saves_change_the_signature(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text(TP02)
    before = watch.signature([scene])
    os.utime(scene, ns=(1, 1))  # the same size and text, another time
    in_place = watch.signature([scene])
    assert in_place != before
    beside = tmp_path / "scene.toml~"
    beside.write_text(TP02)
    os.utime(beside, ns=(1, 1))  # the same size and mtime as in_place: only the inode tells
    os.replace(beside, scene)
    assert watch.signature([scene]) != in_place
    scene.unlink()
    assert watch.signature([scene]) == (None,)


def test_the_files_a_scene_names_are_watched(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text('[camera]\neye = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 40\n[[shapes]]\ntype = "spheres"\n'
                     'file = "field.npz"\n[[shapes]]\ntype = "spheres"\nfile = "sub/more.npz"\n')
    assert watch.named_files(scene) == (scene, tmp_path / "field.npz", tmp_path / "sub/more.npz")
    scene.write_text("[camera\n")  # not TOML: the scene file alone
    assert watch.named_files(scene) == (scene,)


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(TP02 + '\n[[lights]]\ntype = "point"\nname = "lamp"\nposition = [3.0, 5.0, 4.0]\nintensity = 30.0\n')
    return path


def fresh(path, aov="shaded"):
    return pyclray.render(pyclray.load_scene(path).with_size(64, 48), aovs=(aov,))[aov]


def test_a_reload_keeps_the_prepared_scene_or_updates_the_changed_shapes(scene_file):
    first, _ = watch.load(scene_file, (64, 48))
    pyclray.render(first, aovs=("shaded",))
    scene_file.write_text(scene_file.read_text().replace("intensity = 30.0", "intensity = 50.0"))
    lit, _ = watch.load(scene_file, (64, 48), first)
    assert lit.shapes is first.shapes  # no shape changed: the same tuple, the same prepared scene
    assert np.array_equal(pyclray.render(lit, aovs=("shaded",))["shaded"], fresh(scene_file))
    scene_file.write_text(scene_file.read_text().replace("radius = 0.5", "radius = 0.4"))
    smaller, _ = watch.load(scene_file, (64, 48), lit)
    assert derivation(smaller.shapes) == (first.shapes, (3,))  # the blue ball only
    assert all(a is b for k, (a, b) in enumerate(zip(smaller.shapes, first.shapes)) if k != 3)
    for aov in ("shaded", "depth", "id"):
        assert np.array_equal(pyclray.render(smaller, aovs=(aov,))[aov], fresh(scene_file, aov)), aov
    scene_file.write_text(scene_file.read_text().replace("radius = 1.0", "radius = 0.9"))
    both, _ = watch.load(scene_file, (64, 48), smaller)
    assert derivation(both.shapes) == (first.shapes, (2, 3))
    assert np.array_equal(pyclray.render(both, aovs=("depth",))["depth"], fresh(scene_file, "depth"))
    scene_file.write_text(TP02)  # the radii back (the light gone): the shapes are the first ones again
    back, _ = watch.load(scene_file, (64, 48), both)
    assert np.array_equal(pyclray.render(back, aovs=("depth",))["depth"], fresh(scene_file, "depth"))


def test_the_watcher_outlives_an_error_of_its_own(scene_file, monkeypatch, capsys):
    """A watcher task ended by an exception would leave the page on a scene no save changes any more,
    without a word (issue 42, item 13): an error anywhere in a poll is said, and the next save loads."""
    import asyncio

    from pyclray.apps.view.server import App

    app = App(scene_file, pyclray.load_scene(scene_file), "shaded", (64, 48))
    real, failures = watch.signature, [1]

    def failing_once(paths):
        if failures:
            failures.pop()
            raise RuntimeError("a bug of ours")
        return real(paths)

    monkeypatch.setattr(watch, "signature", failing_once)

    async def scenario():
        task = asyncio.create_task(app.watch())
        await asyncio.sleep(3 * watch.POLL_SECONDS)  # the failing poll has come and gone
        scene_file.write_text(TP02.replace("radius = 0.5", "radius = 0.4"))
        for _ in range(200):
            await asyncio.sleep(watch.POLL_SECONDS)
            if app.scene.shapes[3].radius == 0.4:
                break
        task.cancel()
        app.executor.shutdown()

    asyncio.run(scenario())
    assert not failures and app.scene.shapes[3].radius == 0.4
    assert "pyclray view: warning: reloading failed: RuntimeError: a bug of ours" in capsys.readouterr().err
