"""Packets: the kernels cast LANES rays per work-item in vector lanes (kernels/lanes.h), at the
device's width (8 float or 4 double lanes on PoCL's CPU device, 1 on GPUs) or $PYCLRAY_LANES.

A lane's arithmetic is the same at every width: contraction into FMAs is off and every operation is
IEEE (the same dot, cross and square roots), so the images are compared bit for bit across widths;
the float64 oracle judges the scalar and the vector width alike. Windows of an image are the same
pixels as the whole image's, bit for bit, wherever they start (packets start at multiples of LANES in
the image, so a window may cut a packet at both ends)."""
from __future__ import annotations

import numpy as np
import pytest

import pyclray
from pyclray.engine.opencl import device
from pyclray.engine.launch import programs
from pyclray.model.aovs import RENDER_AOVS
from test_render import assert_matches_oracle, small
from test_speedups import random_scene, same

ALL = ("depth", "normal", "id")


def widths(precision: str) -> list[int]:
    """Every lane width up to the widest this machine's PoCL builds (256-bit vectors), and 1."""
    most = programs.MAX_LANE_BITS // (32 if precision == "fp32" else 64)
    return [w for w in programs.LANE_WIDTHS if w <= most]


def need(precision):
    if precision == "fp64" and not device.has_fp64(device.context_for(None).device):
        pytest.skip("device lacks cl_khr_fp64")


def at_width(monkeypatch, lanes: int, fn):
    with monkeypatch.context() as patch:
        patch.setenv("PYCLRAY_LANES", str(lanes))
        return fn()


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("seed", range(4))
def test_every_lane_width_gives_the_same_bits(monkeypatch, seed, precision):
    """Renders (every AOV set, an odd size: 61 x 47 is no multiple of a packet) and casts (a count
    that is no multiple of a packet) are bit-identical at widths 1, 2, 4 and 8."""
    need(precision)
    scene = random_scene(seed)
    rng = np.random.default_rng(seed)
    origins, directions = rng.normal(0, 3, (333, 3)), rng.normal(0, 1, (333, 3))

    def run():
        out = [pyclray.render(scene, aovs, precision) for aovs in (ALL, ("depth",), ("normal",), ("id",))]
        return out + [pyclray.cast(scene, origins, directions, precision=precision)]

    runs = {w: at_width(monkeypatch, w, run) for w in widths(precision)}
    scalar = runs.pop(1)
    for lanes, frames in runs.items():
        for a, b in zip(scalar, frames):
            same(a, b)


@pytest.mark.parametrize("lanes", [1, 8])
@pytest.mark.parametrize("name", ["tp02", "room", "far"])
def test_scalar_and_vector_widths_match_the_oracle(monkeypatch, scenes_dir, name, lanes):
    """The error model's fp32 bounds (tests/test_render.py) hold at one ray per work-item and at 8."""
    scene = small(pyclray.load_scene(scenes_dir / f"{name}.toml"), 67)
    at_width(monkeypatch, lanes, lambda: assert_matches_oracle(scene))


@pytest.mark.parametrize("aovs", [ALL, RENDER_AOVS], ids=["depth,normal,id", "every image"])
@pytest.mark.parametrize("lanes", [1, 4, 8])
def test_windows_are_the_same_pixels_as_the_whole_image(monkeypatch, lanes, aovs):
    """Packets of 4x2 (8 lanes) and 2x2 (4 lanes) pixels: a window starting on an odd row or column
    cuts packets on every side, and each image's writer keeps to the window's pixels."""
    scene = random_scene(5, size=(83, 37))
    whole = at_width(monkeypatch, lanes, lambda: pyclray.render(scene, aovs))
    windows = [(0, 0, 83, 37), (0, 0, 1, 1), (82, 36, 1, 1), (3, 5, 17, 9), (8, 0, 8, 37), (13, 2, 70, 35), (0, 20, 83, 17),
               (1, 1, 81, 35), (5, 7, 2, 1)]
    for col0, row0, cols, rows in windows:
        part = at_width(monkeypatch, lanes, lambda: pyclray.render(scene, aovs, window=(col0, row0, cols, rows)))
        cut = {k: np.ascontiguousarray(v[row0 : row0 + rows, col0 : col0 + cols]) for k, v in whole.items()}
        same(part, cut)


@pytest.mark.parametrize("window", [(0, 0, 0, 1), (-1, 0, 4, 4), (80, 0, 4, 4), (0, 0, 83, 38), "a", (1, 2, 3)])
def test_a_window_outside_the_image_is_a_clear_error(window):
    scene = random_scene(5, size=(83, 37))
    with pytest.raises(pyclray.PyclrayError, match="window: expected"):
        pyclray.render(scene, window=window)


def test_the_lane_width_follows_the_device_and_the_environment(monkeypatch):
    ctx = device.context_for(None)
    monkeypatch.delenv("PYCLRAY_LANES", raising=False)
    for precision, bits in (("fp32", 32), ("fp64", 64)):
        lanes = programs.lanes_for(ctx.device, precision)
        assert lanes in programs.LANE_WIDTHS and lanes * bits <= programs.MAX_LANE_BITS
    if device.is_pocl_cpu(ctx.device) and ctx.device.preferred_vector_width_float >= 8:  # AVX or wider
        assert programs.lanes_for(ctx.device, "fp32") == 8 and programs.lanes_for(ctx.device, "fp64") == 4
    # a CPU device that vectorizes across work-items itself reports a preferred width of 1 (Intel's
    # CPU runtime): explicit packets of the widest lanes there; a GPU's 1 stays one ray a work-item
    import pyopencl as cl
    from types import SimpleNamespace

    for kind, fp32, fp64 in ((cl.device_type.CPU, 8, 4), (cl.device_type.GPU, 1, 1)):
        reports_1 = SimpleNamespace(type=kind, preferred_vector_width_float=1, preferred_vector_width_double=1)
        assert (programs.lanes_for(reports_1, "fp32"), programs.lanes_for(reports_1, "fp64")) == (fp32, fp64)
    monkeypatch.setenv("PYCLRAY_LANES", "2")
    assert programs.lanes_for(ctx.device, "fp32") == 2
    monkeypatch.setenv("PYCLRAY_LANES", "3")
    with pytest.raises(pyclray.DeviceError, match=r"PYCLRAY_LANES: expected one of 1, 2, 4, 8 \(vectors of at most "
                       r"256 bits; fp64 at most 4\), got '3'"):
        programs.lanes_for(ctx.device, "fp32")
    # 512-bit lanes: PoCL 3.0's code generator aborts the process on them (device.py), so none is
    # built: fp32's 16 is refused, and fp64 takes 4 for 8 (one setting for both precisions: an fp32
    # handle's occupancy runs fp64 kernels too)
    for precision in ("fp32", "fp64"):
        monkeypatch.setenv("PYCLRAY_LANES", "16")
        with pytest.raises(pyclray.DeviceError, match="PYCLRAY_LANES: expected one of 1, 2, 4, 8 "):
            programs.lanes_for(ctx.device, precision)
    monkeypatch.setenv("PYCLRAY_LANES", "8")
    assert (programs.lanes_for(ctx.device, "fp32"), programs.lanes_for(ctx.device, "fp64")) == (8, 4)


@pytest.mark.parametrize("precision", ["fp32", "fp64"])
@pytest.mark.parametrize("offset", [0.0, 1e5])
def test_the_wide_trees_packet_test_drops_no_hit(precision, offset):
    """Render's packets traverse the wide BVH with a loose test of a node's 8 children against all
    lanes at once (interval arithmetic, kernels/bvh.h: wide_packet_entries) and a lane-by-lane test
    of each child popped: every hit is still found. Through the BVH the images are those of the tile
    lists (each tile's shapes tested one after the other, no tree), bit for bit, from cameras looking
    along each axis (packets with lanes of both signs on an axis, or flat along it: the interval test
    leaves such an axis out) and obliquely, near the origin and 1e5 away."""
    need(precision)
    rng = np.random.default_rng(7)
    shift = offset * np.array([1.0, -0.5, 0.75])
    centres = rng.uniform(-6, 6, (3000, 3)) + shift
    radii = rng.uniform(0.02, 0.4, 3000)
    shapes = (pyclray.Plane((0.0, 1.0, 0.0), -float(shift[1]) + 7.0), pyclray.Spheres(centres, radii))
    target = tuple(shift)
    cameras = [pyclray.Camera(tuple(shift + [0.0, 0.0, 20.0]), target, fov=60.0),
               pyclray.Camera(tuple(shift + [0.0, 20.0, 0.0]), target, up=(0.0, 0.0, -1.0), fov=60.0),
               pyclray.Camera(tuple(shift + [-20.0, 0.0, 0.0]), target, fov=60.0),
               pyclray.Camera(tuple(shift + [13.0, 7.0, -11.0]), target, fov=40.0)]
    for camera in cameras:
        # 62 columns: a packet (4 wide) straddles the centre, its lanes of both signs along the
        # camera's x; 47 rows: the centre row's lanes run flat along its y (and so along world axes)
        scene = pyclray.Scene(camera, pyclray.Image(62, 47), shapes)
        through_tree = pyclray.render(scene, ALL, precision, acceleration="bvh")
        assert (through_tree["id"] >= 1).sum() > 500  # the spheres fill much of the image
        same(through_tree, pyclray.render(scene, ALL, precision, acceleration="tiles"))
