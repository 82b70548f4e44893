"""Stiff and extreme cases, and the stability report (`pyclray stability`).

Each case is a scene that stresses one part of the numerics: far and huge spheres, a scene far
from the origin, grazing and parallel rays, a camera on or below a plane or inside a sphere,
tangent rays, coincident and nested shapes, extreme fields of view; tall thin cylinders, a disk of
radius 1e6 as the ground, cylinders, disks, rectangles and boxes 1e5 and 1e6 away, and cameras
inside a box and a capped cylinder. The report sets pyclray fp32
and fp64 beside Mitsuba 3 (scalar_rgb and llvm_ad_rgb) against the float64 oracle.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .error_model import FP32_DEPTH_ULPS, FP32_NORMAL, FP64_DEPTH_RELATIVE, compare, meets_targets, reference
from ..model.camera import Camera, Image
from ..model.scene import Scene
from ..model.shapes import Box, Cylinder, Disk, Plane, Rectangle, Sphere

# The targets (pyclray.reference.error_model): on pixels that are neither silhouettes nor near-ties nor at edges,
# fp32 depth within 8 float32 ulps of t / |cos|, normals within 2e-5 / |cos|, ids right; fp64 depth
# within 1e-12 relative / |cos|, normals within 1e-12 / |cos| times the normal's conditioning.
__all__ = ["CASES", "FP32_DEPTH_ULPS", "FP32_NORMAL", "FP64_DEPTH_RELATIVE", "evaluate", "meets_targets", "run", "table"]


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def far_sphere(distance: float, size: int = 96) -> Scene:
    """A unit sphere `distance` away in an oblique direction, filling most of a tiny fov."""
    direction = _unit([0.48, 0.36, -0.8])
    eye = np.array([0.3, 1.7, -2.1])
    center = eye + distance * direction
    fov = 2 * math.degrees(math.atan(1.25 / distance))
    return Scene(Camera(tuple(eye), tuple(center), (0.0, 1.0, 0.0), fov), Image(size, size),
                 (Sphere(tuple(center), 1.0, "far"),))


def huge_ground(size: int = 96) -> Scene:
    """A sphere of radius 1e6 as the ground, the camera 3 units above it, two balls on it."""
    R = 1e6
    return Scene(
        Camera((0.0, 3.0, 6.0), (0.0, 0.5, -4.0), (0.0, 1.0, 0.0), 60.0),
        Image(size, size),
        (
            Sphere((0.0, -R, 0.0), R, "ground"),
            Sphere((-1.0, 1.0, -3.0), 1.0, "ball"),
            Sphere((2.0, 0.5, -6.0), 0.5, "small"),
        ),
    )


def tp02_like(offset=(0.0, 0.0, 0.0), size: int = 96) -> Scene:
    o = np.asarray(offset, np.float64)

    def at(p):
        return tuple(float(v) for v in np.asarray(p) + o)

    ground = Plane.through(at((0.0, 0.0, 0.0)), (0.0, 1.0, 0.0), "ground")
    return Scene(
        Camera(at((0.0, 2.0, 6.0)), at((0.0, 0.5, 0.0)), (0.0, 1.0, 0.0), 45.0),
        Image(size, size),
        (
            ground,
            Sphere(at((-1.6, 0.7, -0.5)), 0.7, "red"),
            Sphere(at((0.0, 1.0, 0.0)), 1.0, "green"),
            Sphere(at((1.5, 0.5, 1.0)), 0.5, "blue"),
        ),
    )


def translated(size: int = 96) -> Scene:
    """tp02 moved by 1e5 along an oblique direction."""
    return tp02_like(1e5 * _unit([1.0, 0.6, -0.8]), size)


def grazing_plane(size: int = 97) -> Scene:
    """The camera 1e-3 above a plane looking level: rays graze it, and the middle row (odd
    height: sy = 0 exactly) runs parallel to it."""
    return Scene(
        Camera((0.0, 1e-3, 0.0), (0.0, 1e-3, -1.0), (0.0, 1.0, 0.0), 60.0),
        Image(size, size),
        (Plane((0.0, 1.0, 0.0), 0.0, "ground"), Sphere((0.0, 0.5, -8.0), 0.5, "ball")),
    )


def camera_on_plane(size: int = 96) -> Scene:
    """The eye exactly on a plane (it sees none of it: only t > 0 counts), and below another."""
    return Scene(
        Camera((0.0, 0.0, 4.0), (0.0, 1.0, -4.0), (0.0, 1.0, 0.0), 70.0),
        Image(size, size),
        (
            Plane((0.0, 1.0, 0.0), 0.0, "under-the-eye"),
            Plane((0.0, 1.0, 0.0), -3.0, "ceiling"),  # y = 3, seen from below, normal +y
            Sphere((0.0, 1.0, -3.0), 1.0, "ball"),
        ),
    )


def inside_sphere(size: int = 96) -> Scene:
    """The camera inside a sphere sees its far side (outward normals), and a ball inside it."""
    return Scene(
        Camera((0.2, 0.1, 0.3), (0.0, 0.0, -5.0), (0.0, 1.0, 0.0), 90.0),
        Image(size, size),
        (Sphere((0.0, 0.0, 0.0), 10.0, "room"), Sphere((1.0, -0.5, -4.0), 1.0, "ball")),
    )


def tangent_and_cut(size: int = 96) -> Scene:
    """Spheres grazed by rays (their silhouettes) and cut by the image border."""
    return Scene(
        Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 40.0),
        Image(size, size),
        (
            Sphere((-1.6, 0.0, 0.0), 0.9, "cut-left"),
            Sphere((0.0, 1.8, -1.0), 1.0, "cut-top"),
            Sphere((0.4, -0.3, 0.0), 0.6, "middle"),
        ),
    )


def coincident(size: int = 96) -> Scene:
    """Identical spheres and planes (the lowest id must win), and nested concentric spheres."""
    return Scene(
        Camera((0.0, 2.0, 6.0), (0.0, 0.5, 0.0), (0.0, 1.0, 0.0), 50.0),
        Image(size, size),
        (
            Sphere((-1.0, 1.0, 0.0), 1.0, "a"),
            Sphere((-1.0, 1.0, 0.0), 1.0, "a-again"),
            Plane((0.0, 2.0, 0.0), 0.0, "floor"),
            Plane((0.0, 1.0, 0.0), 0.0, "floor-again"),
            Sphere((1.5, 1.0, 0.0), 0.5, "inner"),
            Sphere((1.5, 1.0, 0.0), 0.9, "outer"),
        ),
    )


def narrow_fov(size: int = 64) -> Scene:
    """fov of 1e-4 degrees on a unit sphere 1e5 away (nearly orthographic)."""
    scene = far_sphere(1e5, size)
    return Scene(Camera(scene.camera.eye, scene.camera.target, (0.0, 1.0, 0.0), 1e-3), scene.image, scene.shapes)


def wide_fov(size: int = 96) -> Scene:
    """fov of 179.9 degrees: rays run out to nearly 90 degrees off the axis."""
    return Scene(
        Camera((0.0, 1.0, 0.0), (0.0, 1.0, -1.0), (0.0, 1.0, 0.0), 179.9),
        Image(size, size),
        (Plane((0.0, 1.0, 0.0), 0.0, "ground"), Sphere((0.0, 1.0, -3.0), 1.0, "ball"), Sphere((3.0, 1.0, 0.0), 1.0, "side")),
    )


def up_nearly_parallel(size: int = 96) -> Scene:
    """up 1e-4 rad from the view direction: still a well-defined (if steep) roll."""
    w = _unit([0.0, -1.0, -1.0])
    up = _unit(w + 1e-4 * np.array([0.0, 1.0, -1.0]))
    return Scene(Camera((0.0, 4.0, 4.0), (0.0, 0.0, 0.0), tuple(up), 50.0), Image(size, size),
                 (Plane((0.0, 1.0, 0.0), 0.0, "ground"), Sphere((0.0, 1.0, 0.0), 1.0, "ball")))


# -- the cylinder, the disk, the rectangle and the box -------------------------------------------
def tall_thin_cylinder(size: int = 96) -> Scene:
    """A cylinder of height 100 and radius 0.5 seen from 20 away, looking up along it: its side
    runs from grazing to head-on and its top cap is a thin ellipse 100 units up."""
    return Scene(
        Camera((0.0, 1.0, 20.0), (0.0, 30.0, 0.0), (0.0, 1.0, 0.0), 90.0),
        Image(size, size),
        (Cylinder((0.0, 0.0, 0.0), (0.0, 100.0, 0.0), 0.5, name="pole"),
         Cylinder((3.0, 0.0, -2.0), (2.0, 100.0, -1.0), 0.5, name="leaning")),
    )


def huge_disk_ground(size: int = 96) -> Scene:
    """A disk of radius 1e6 as the ground, the eye 3 above it, a box, a cylinder and a panel on it."""
    return Scene(
        Camera((0.3, 3.0, 6.0), (0.0, 0.5, -4.0), (0.0, 1.0, 0.0), 60.0),
        Image(size, size),
        (
            Disk((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 1e6, "ground"),
            Box((-1.5, 0.6, -3.0), (1.2, 1.2, 1.2), (0.0, 1.0, 0.0), 20.0, "crate"),
            Cylinder((1.5, 0.0, -5.0), (1.5, 1.5, -5.0), 0.6, name="drum"),
            Rectangle((0.0, 1.0, -8.0), (2.0, 0.0, 0.0), (0.0, 1.0, 0.0), "panel"),
        ),
    )


def far_shapes(distance: float, size: int = 96) -> Scene:
    """A cylinder, a disk, a rectangle and a box `distance` away in an oblique direction, through a
    fov that frames them (a few units wide)."""
    direction = _unit([0.48, 0.36, -0.8])
    eye = np.array([0.3, 1.7, -2.1])
    c = eye + distance * direction

    def at(p):
        return tuple(float(v) for v in c + np.asarray(p, np.float64))

    fov = 2 * math.degrees(math.atan(2.6 / distance))
    return Scene(
        Camera(tuple(eye), tuple(c), (0.0, 1.0, 0.0), fov),
        Image(size, size),
        (
            Cylinder(at((-1.2, -1.2, 0.0)), at((-1.0, 0.4, 0.3)), 0.6, name="cylinder"),
            Disk(at((1.1, 1.0, 0.0)), (0.2, 0.3, 1.0), 0.9, "disk"),
            Rectangle(at((-1.0, 1.2, -0.5)), (0.9, 0.2, 0.0), (-0.1, 0.45, 0.3), "panel"),
            Box(at((1.0, -0.9, 0.2)), (1.2, 1.0, 0.8), (1.0, 2.0, 0.5), 40.0, "box"),
        ),
    )


def inside_box(size: int = 96) -> Scene:
    """The eye inside a rotated box (a room): its far walls with outward normals, and a ball and a
    capped cylinder inside it."""
    return Scene(
        Camera((0.4, 0.2, 0.3), (-1.0, -0.5, -4.0), (0.0, 1.0, 0.0), 100.0),
        Image(size, size),
        (
            Box((0.0, 0.0, 0.0), (8.0, 3.0, 10.0), (0.2, 1.0, 0.1), 25.0, "room"),
            Sphere((1.0, -0.5, -3.0), 0.8, "ball"),
            Cylinder((-2.0, -1.5, -2.5), (-2.0, 0.5, -2.5), 0.5, name="column"),
        ),
    )


def inside_cylinder(size: int = 96) -> Scene:
    """The eye inside a capped cylinder (a silo), looking along its axis at the far cap and its
    side, with a box inside."""
    return Scene(
        Camera((0.5, 0.3, 0.2), (0.0, 0.0, -10.0), (0.0, 1.0, 0.0), 100.0),
        Image(size, size),
        (
            Cylinder((0.0, 0.0, 8.0), (0.0, 0.0, -12.0), 3.0, name="silo"),
            Box((1.0, -1.0, -5.0), (1.0, 1.0, 1.0), None, 0.0, "crate"),
        ),
    )


@dataclass(frozen=True)
class Case:
    name: str
    make: Callable[[], Scene]
    note: str


CASES = (
    Case("far-sphere-1e5", lambda: far_sphere(1e5), "unit sphere 1e5 away, oblique, tiny fov"),
    Case("far-sphere-1e7", lambda: far_sphere(1e7), "unit sphere 1e7 away, oblique, tiny fov"),
    Case("huge-ground", huge_ground, "radius 1e6 sphere as the ground, eye 3 above"),
    Case("translated-1e5", translated, "tp02 moved 1e5 along an oblique axis"),
    Case("grazing-plane", grazing_plane, "eye 1e-3 above a plane, level: grazing and parallel rays"),
    Case("camera-on-plane", camera_on_plane, "eye on one plane, below another"),
    Case("inside-sphere", inside_sphere, "eye inside a sphere"),
    Case("tangent-and-cut", tangent_and_cut, "silhouettes and spheres cut by the border"),
    Case("coincident", coincident, "identical and nested shapes: lowest id wins"),
    Case("narrow-fov", narrow_fov, "fov 1e-3 degrees"),
    Case("wide-fov", wide_fov, "fov 179.9 degrees"),
    Case("up-nearly-parallel", up_nearly_parallel, "up 1e-4 rad from the view direction"),
    Case("tall-thin-cylinder", tall_thin_cylinder, "cylinders of height 100, radius 0.5"),
    Case("huge-disk-ground", huge_disk_ground, "disk of radius 1e6 as the ground, eye 3 above"),
    Case("far-shapes-1e5", lambda: far_shapes(1e5), "cylinder, disk, rectangle, box 1e5 away, tiny fov"),
    Case("far-shapes-1e6", lambda: far_shapes(1e6), "cylinder, disk, rectangle, box 1e6 away, tiny fov"),
    Case("inside-box", inside_box, "eye inside a rotated box"),
    Case("inside-cylinder", inside_cylinder, "eye inside a capped cylinder"),
)


def evaluate(scene: Scene, engines=("fp32", "fp64"), ref=None) -> dict:
    """engine -> compare() result; engines: "fp32", "fp64", "scalar_rgb", "llvm_ad_rgb"."""
    from ..engine.api import render

    ref = ref if ref is not None else reference(scene)
    out = {}
    for engine in engines:
        if engine in ("fp32", "fp64"):
            images = render(scene, precision=engine)
            out[engine] = compare(images, ref, engine=engine)
        else:
            from . import mitsuba

            images = mitsuba.render(scene, engine)
            beyond = mitsuba.beyond_counterparts(scene, ref["origins"], ref["directions"])
            # judged on pyclray fp32's pixels, so that the engines are compared on the same pixels
            # (by its own, looser tolerance Mitsuba at 1e7 would have no pixel left to judge)
            out[engine] = compare(images, ref, exclude=beyond, engine="fp32")
    return out


def table(results: dict) -> str:
    """A Markdown table: one row per case and engine."""
    lines = [
        "| case | engine | depth max (ulps x cos) | depth p99 | depth max rel. | normal max (x cos) | id mismatches | judged px | silhouette / near-tie / edge px |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for case, engines in results.items():
        for engine, r in engines.items():
            if "error" in r:
                lines.append(f"| {case} | {engine} | {r['error']} | | | | | | |")
                continue
            lines.append(
                f"| {case} | {engine} | {r['depth_ulps_max']:.3g} | {r['depth_ulps_p99']:.3g} | {r['depth_rel_max']:.2e} | "
                f"{r['normal_cos_max']:.2e} | {r['id_mismatch'] + r['miss_mismatch']} | {r['pixels']} | {r['silhouette']} / {r['near_tie']} / {r['edge']} |"
            )
    return "\n".join(lines)


def run(case_names=None, engines=("fp32", "fp64", "scalar_rgb", "llvm_ad_rgb")) -> dict:
    results = {}
    for case in CASES:
        if case_names and case.name not in case_names:
            continue
        scene = case.make()
        ref = reference(scene)
        results[case.name] = {}
        for engine in engines:
            try:
                results[case.name].update(evaluate(scene, (engine,), ref))
            except Exception as error:  # a reference engine may refuse a case; say so in the table
                results[case.name][engine] = {"error": f"{type(error).__name__}: {error}"[:80]}
    return results
