"""Search for rays a mesh instance lets through (issue 42, item 2: "an instance is as exact as a copy").

The issue's scene: CGAL's bunny, elephant, armadillo and fandisk (bunny00.off, elephant.off,
armadillo.off, fandisk.off of Debian's libcgal-demo data), each scaled to a size and stood on a
ground plane, and a second bunny placed (Mesh.placed: a mesh instance, its triangles tested in
object space) from the first's loaded mesh at 0.7 scale; 640x480 views, K = 525 at (320, 240),
OpenCV poses on a circle about 4.5 away. Each view is rendered twice in fp32: as the issue's scene
(the bunnies instances of one loaded mesh) and with each bunny a plain copy (Mesh(V', F), V' its
placement applied in float64: the same triangles in world space). Every pixel where the two differ
in id, primitive or depth beyond the error model's tolerance is traced by the float64 oracle, and
a pixel where the instance misses the surface the oracle hits (or meets a farther one) while the
oracle's ray passes farther than the render's position error from every contour edge of the mesh
(an edge of a front- and a back-facing triangle, or a boundary: where a ray may legitimately go
either way) is a leak. Interior edges (both triangles facing the ray) give no excuse: a watertight
test meets one of their triangles.

    # get the meshes: cd /tmp && apt-get download libcgal-demo && dpkg-deb -x libcgal-demo*.deb cgal
    #   && tar -xzf cgal/usr/share/doc/libcgal-dev/data.tar.gz -C cgal   (data/meshes/*.off)
    python bench/instance_leaks.py --meshes /tmp/cgal/data/meshes --views 24
    PYTHONPATH=../old-checkout python bench/instance_leaks.py ...   # another checkout's kernels

It prints, per build (fp32 at the default lane width and with PYCLRAY_LANES=1), the views, pixels,
differing pixels and leaks, each leak with its view, pixel, depths, triangles and the margin (the
ray's distance from the nearest contour edge over the render's position error)."""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

import numpy as np

import pyclray
from pyclray.reference import error_model, oracle

K640 = [[525.0, 0.0, 320.0], [0.0, 525.0, 240.0], [0.0, 0.0, 1.0]]


def opencv_camera(eye, target, K, size):
    """A pinhole at ``eye`` looking at ``target`` (y down in the image: OpenCV's pose)."""
    forward = np.subtract(target, eye, dtype=np.float64)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, -1.0, 0.0])
    right /= np.linalg.norm(right)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, np.cross(forward, right), forward, eye
    return pyclray.Camera.from_intrinsics(K, pose), pyclray.Image(*size)


def stood(mesh, size, x, z, **keys):
    """mesh placed (Mesh.placed: its arrays shared) at size ``size``, standing on y = 0 at (x, z)."""
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    s = size / float((hi - lo).max())
    return mesh.placed(scale=s, translate=(x - s * (lo[0] + hi[0]) / 2, -s * lo[1], z - s * (lo[2] + hi[2]) / 2), **keys)


def copy_of(mesh):
    """The same triangles as a plain mesh: the placement applied in float64 (a copy, not an instance)."""
    return pyclray.Mesh(np.array(mesh.world_vertices()), np.array(mesh.faces), name=mesh.name)


def issue_shapes(folder, second_scale=0.7, second_at=(1.3, -0.9), angle=0.0):
    """The ground, a bunny (1.0 tall-ish), the second bunny at second_scale its scale (both placed
    from one loaded mesh: instances), an elephant, an armadillo and the fandisk."""
    folder = Path(folder)
    bunny = pyclray.Mesh.load(folder / "bunny00.off")
    first = stood(bunny, 1.0, 0.0, 0.0, name="bunny")
    s = second_scale * first.scale
    lo, hi = bunny.vertices.min(axis=0), bunny.vertices.max(axis=0)
    second = bunny.placed(scale=s, axis=(0.0, 1.0, 0.0), angle=angle,
                          translate=(second_at[0] - s * (lo[0] + hi[0]) / 2, -s * lo[1], second_at[1] - s * (lo[2] + hi[2]) / 2),
                          name="bunny 0.7")
    return [pyclray.Plane(normal=(0.0, 1.0, 0.0), offset=0.0, name="ground"), first, second,
            stood(pyclray.Mesh.load(folder / "elephant.off"), 1.1, -1.5, 0.4, name="elephant"),
            stood(pyclray.Mesh.load(folder / "armadillo.off"), 1.2, 0.3, 1.5, name="armadillo"),
            stood(pyclray.Mesh.load(folder / "fandisk.off"), 0.8, 1.6, 0.9, name="fandisk")]


def circle_views(count, radius=4.5, centre=(0.2, 0.4, 0.2), size=(640, 480), phase=0.0, heights=(1.0, 1.6, 2.3)):
    """count OpenCV pinholes on a circle ``radius`` from ``centre`` (K: 525 at 640x480, scaled)."""
    scale = size[0] / 640
    K = [[525.0 * scale, 0.0, 320.0 * scale], [0.0, 525.0 * scale, 240.0 * scale], [0.0, 0.0, 1.0]]
    for k in range(count):
        a = 2 * math.pi * k / count + phase
        eye = (centre[0] + radius * math.sin(a), heights[k % len(heights)], centre[2] + radius * math.cos(a))
        yield opencv_camera(eye, centre, K, size)


def contour_margin(mesh, origin, direction, depth, reach):
    """The distance of the ray from the nearest contour edge of ``mesh`` near its hit point at
    ``depth`` (an edge of one triangle facing the ray and one facing away, or of one triangle),
    over ``reach`` (the render's sideways position error there); and the nearest such edge."""
    world = mesh.world_vertices()
    faces = np.asarray(mesh.faces)
    point = origin + depth * direction
    near = np.nonzero(np.linalg.norm(world[faces].mean(axis=1) - point, axis=1) < 0.05)[0]
    normals = mesh.face_normals()
    facing = np.sign(normals[near] @ direction)
    edges: dict = {}
    for f, s in zip(near, facing):
        a, b, c = faces[f]
        for e in ((a, b), (b, c), (c, a)):
            edges.setdefault(tuple(sorted((int(e[0]), int(e[1])))), []).append(s)
    best, which = np.inf, None
    for (a, b), signs in edges.items():
        if len(signs) == 2 and signs[0] == signs[1]:
            continue  # interior: both triangles face the same way along the ray
        p, q = world[a], world[b]
        # the distance between the ray's line and the segment pq
        u = q - p
        w0 = p - origin
        dd, uu, du = direction @ direction, u @ u, direction @ u
        denominator = dd * uu - du * du
        s = np.clip((dd * (u @ -w0) + du * (direction @ w0)) / denominator if denominator > 0 else 0.0, 0.0, 1.0)
        x = p + s * u
        rel = x - origin
        gap = np.linalg.norm(rel - (rel @ direction) / dd * direction)
        if gap < best:
            best, which = gap, (a, b)
    return best / reach, which


def issue_contour_eyes(mesh, faces=(40932, 25323), t=2.69438, cosines=(0.02, 0.001), v=2.3e-4):
    """The eyes of the issue's pixel, reconstructed: rays at distance t from a point of triangle
    faces[0] at barycentric v from its edge shared with faces[1], with |cos| cosines[0] to the first
    triangle (facing it) and cosines[1] to the second (facing it, or away: an interior edge or a
    contour), looking down (the eye above the point). Yields (label, eye, point, edge)."""
    world, F, normals = mesh.world_vertices(), np.asarray(mesh.faces), mesh.face_normals()
    n1, n2 = normals[faces[0]], normals[faces[1]]
    shared = [int(x) for x in F[faces[0]] if x in F[faces[1]]]
    third = [int(x) for x in F[faces[0]] if x not in shared][0]
    a, b, c = world[shared[0]], world[shared[1]], world[third]
    along = (b - a) / np.linalg.norm(b - a)
    gram = np.array([[n1 @ n1, n1 @ n2], [n1 @ n2, n2 @ n2]])
    for label, second in (("interior", -cosines[1]), ("contour", cosines[1])):
        x, y = np.linalg.solve(gram, [-cosines[0], second])
        across = x * n1 + y * n2
        for sign in (1.0, -1.0):
            d = across + sign * math.sqrt(1.0 - across @ across) * along
            point = (1 - 0.5 - v) * a + 0.5 * b + v * c
            eye = point - t * d
            if eye[1] > point[1]:
                yield label, eye, point, (a, b)


def contour_sweep(folder, columns=96, rows=4, spacing=0.4, second_scale=0.7, second_at=(1.3, -0.9), angle=0.0):
    """Rays ``spacing`` float32 eps apart (angle) across the issue's edge (triangles 40932 and
    25323 of the 0.7 bunny) from the reconstructed eyes: per eye, how many rays the instance, the
    copy and the oracle send to the triangles' pair, and the farthest a ray that went the other
    way than the oracle's lies from the edge line, in eps t (float32's unit roundoff times the
    distance): the width of the strip rounding decides."""
    shapes = issue_shapes(folder, second_scale, second_at, angle)
    copies = [copy_of(s) if isinstance(s, pyclray.Mesh) and s.name.startswith("bunny") else s for s in shapes]
    instance = shapes[2]
    eps = 2.0**-24
    out = []
    for label, eye, point, (a, b) in issue_contour_eyes(instance):
        f = 1.0 / (spacing * eps)
        # the camera's x axis across the edge: roll it so that the edge runs along the image's y
        forward = (point - eye) / np.linalg.norm(point - eye)
        edge = (b - a) / np.linalg.norm(b - a)
        down = edge - (edge @ forward) * forward
        down /= np.linalg.norm(down)
        pose = np.eye(4)
        pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = np.cross(down, forward), down, forward, eye
        K = [[f, 0.0, columns / 2], [0.0, f, rows / 2], [0.0, 0.0, 1.0]]
        camera, image = pyclray.Camera.from_intrinsics(K, pose), pyclray.Image(columns, rows)
        O, D = camera.rays(columns, rows)
        O, D = O.reshape(-1, 3), D.reshape(-1, 3)
        D = D / np.linalg.norm(D, axis=1, keepdims=True)
        scene = pyclray.Scene(camera, image, shapes)
        truth = oracle.trace(scene, O, D, aovs=("depth", "normal", "id"))
        cos = oracle.incidence_cosine(scene, D, truth["id"], truth["normal"])
        tolerance, _ = error_model.pyclray_tolerances(scene, truth, cos, O, "fp32", camera.eye, D, flat=False)
        cross = np.cross(D, edge)
        gap = np.einsum("ij,ij->i", a - O, cross) / np.linalg.norm(cross, axis=1) / (eps * truth["depth"])
        row = {"eye": label, "t": float(np.median(truth["depth"])), "oracle_on_pair": 0}
        faces = np.asarray(instance.faces)
        pair = {40932, 25323}
        oracle_face = np.array([instance.oracle_hits(O[k:k + 1], D[k:k + 1])[1][0] if truth["id"][k] == 2 else -1
                                for k in range(len(D))])
        row["oracle_on_pair"] = int(np.isin(oracle_face, list(pair)).sum())
        for name, scene in (("instance", pyclray.Scene(camera, image, shapes)), ("copy", pyclray.Scene(camera, image, copies))):
            got = pyclray.render(scene, aovs=("depth", "id", "primitive"), precision="fp32")
            ids, prim, depth = got["id"].reshape(-1), got["primitive"].reshape(-1), got["depth"].reshape(-1)
            on = (ids == 2) & np.isin(prim, list(pair))
            other = on != np.isin(oracle_face, list(pair))
            # a ray that met another surface than the oracle's (farther by more than a few ulps, or
            # another shape): how far the oracle's ray passes from the nearest contour edge, in eps t
            with np.errstate(invalid="ignore"):
                wrong = (ids != truth["id"]) | (np.abs(depth - truth["depth"]) > tolerance)
            margins = [contour_margin(instance, O[k], D[k], truth["depth"][k], eps * truth["depth"][k])[0]
                       for k in np.nonzero(wrong & (truth["id"] == 2))[0]]
            row[name] = {"on_pair": int(on.sum()), "other_way": int(other.sum()),
                         "farthest_other_way_eps_t": float(np.abs(gap[other]).max()) if other.any() else 0.0,
                         "wrong_surface": int(wrong.sum()),
                         "wrong_surface_contour_gap_eps_t_max": float(max(margins)) if margins else 0.0}
        out.append(row)
        print(json.dumps(row), flush=True)
    return out


def flat_images(scene):
    """depth, id and primitive of an fp32 render of ``scene``, one value a pixel."""
    aovs = ("depth", "id", "primitive")
    frame = pyclray.render(scene, aovs=aovs, precision="fp32")
    return {k: np.asarray(frame[k]).reshape(-1) for k in aovs}


def search(folder, views, builds, size, phase, second_scale, second_at, angle, verbose, threshold=1.0,
           radius=4.5, heights=(1.0, 1.6, 2.3)):
    """Renders of the issue's scene and of its copy over ``views`` eyes on the circle per lane width
    of ``builds`` (None: the device's); (the wrong pixels with margin over ``threshold``, the counts)."""
    shapes = issue_shapes(folder, second_scale, second_at, angle)
    copies = [copy_of(s) if isinstance(s, pyclray.Mesh) and s.name.startswith("bunny") else s for s in shapes]
    found, totals = [], {}
    for lanes in builds:
        if lanes is None:
            os.environ.pop("PYCLRAY_LANES", None)
        else:
            os.environ["PYCLRAY_LANES"] = str(lanes)
        counts = totals.setdefault(str(lanes), {"views": 0, "pixels": 0, "instance px": 0, "differ": 0,
                                                "leaks": 0, "copy leaks": 0})
        views_on_circle = circle_views(views, radius=radius, size=size, phase=phase, heights=heights)
        for v, (camera, image) in enumerate(views_on_circle):
            scene = pyclray.Scene(camera, image, shapes)
            plain = pyclray.Scene(camera, image, copies)
            mine, copy = flat_images(scene), flat_images(plain)
            counts["views"] += 1
            counts["pixels"] += mine["id"].size
            counts["instance px"] += int(np.isin(mine["id"], (1, 2)).sum())
            with np.errstate(invalid="ignore"):
                apart = np.abs(mine["depth"].astype(np.float64) - copy["depth"])
                differ = (mine["id"] != copy["id"]) | (mine["primitive"] != copy["primitive"]) | \
                         (apart > 1e-5 * np.fmin(mine["depth"], copy["depth"]))
            differ &= np.isin(mine["id"], (1, 2)) | np.isin(copy["id"], (1, 2))
            counts["differ"] += int(differ.sum())
            if not differ.any():
                continue
            origins, directions = camera.rays(image.width, image.height)
            O, D = origins.reshape(-1, 3)[differ], directions.reshape(-1, 3)[differ]
            D = D / np.linalg.norm(D, axis=1, keepdims=True)
            truth = oracle.trace(scene, O, D, aovs=("depth", "normal", "id"))
            cos = oracle.incidence_cosine(scene, D, truth["id"], truth["normal"])
            tolerance, _ = error_model.pyclray_tolerances(scene, truth, cos, O, "fp32", camera.eye, D, flat=False)
            pixels = np.nonzero(differ)[0]
            for j, pixel in enumerate(pixels):
                tid = truth["id"][j]
                if tid not in (1, 2):
                    continue
                mesh = shapes[tid]
                face = int(mesh.oracle_hits(O[j:j + 1], D[j:j + 1])[1][0])
                reach = tolerance[j] * cos[j]  # the sideways position error (scene units)
                margin, edge = contour_margin(mesh, O[j], D[j], truth["depth"][j], reach)
                for name, got in (("instance", mine), ("copy", copy)):
                    far = got["id"][pixel] != tid or got["depth"][pixel] > truth["depth"][j] + tolerance[j]
                    if far and margin > threshold:
                        row = {"build": str(lanes), "view": v, "who": name,
                               "pixel": [int(pixel % image.width), int(pixel // image.width)],
                               "oracle": [float(truth["depth"][j]), int(tid), face],
                               "got": [float(got["depth"][pixel]), int(got["id"][pixel]), int(got["primitive"][pixel])],
                               "cos": float(cos[j]), "margin": float(margin),
                               "margin_eps_t": float(margin * reach / (2.0**-24 * truth["depth"][j])),
                               "edge": edge, "tolerance": float(tolerance[j])}
                        found.append(row)
                        counts["leaks" if name == "instance" else "copy leaks"] += int(margin > 1.0)
                        if verbose:
                            print(json.dumps(row), flush=True)
        print(f"lanes {lanes}: {counts}", flush=True)
    return found, totals


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--meshes", required=True,
                        help="the folder of CGAL's bunny00.off, elephant.off, armadillo.off, fandisk.off")
    parser.add_argument("--views", type=int, default=24)
    parser.add_argument("--size", type=int, nargs=2, default=(640, 480))
    parser.add_argument("--phase", type=float, default=0.0, help="the circle's first angle (radians)")
    parser.add_argument("--second-scale", type=float, default=0.7)
    parser.add_argument("--second-at", type=float, nargs=2, default=(1.3, -0.9))
    parser.add_argument("--angle", type=float, default=0.0, help="the second bunny's turn about y (degrees)")
    parser.add_argument("--radius", type=float, default=4.5, help="the circle's radius")
    parser.add_argument("--heights", type=float, nargs="+", default=(1.0, 1.6, 2.3), help="the eyes' heights, in turn")
    parser.add_argument("--lanes", default="default,1", help="lane widths: default (the device's) and/or numbers")
    parser.add_argument("--json", help="write the leaks found here")
    parser.add_argument("--show", type=float, default=1.0,
                        help="print the wrong pixels whose margin is over this (1: the leaks only, 0: all)")
    parser.add_argument("--contour", action="store_true", help="sweep rays across the issue's edge instead")
    args = parser.parse_args(argv)
    if args.contour:
        print(f"pyclray from {Path(pyclray.__file__).parent}", flush=True)
        contour_sweep(args.meshes, second_scale=args.second_scale, second_at=tuple(args.second_at), angle=args.angle)
        return 0
    builds = [None if x == "default" else int(x) for x in args.lanes.split(",")]
    print(f"pyclray from {Path(pyclray.__file__).parent}", flush=True)
    found, totals = search(args.meshes, args.views, builds, tuple(args.size), args.phase, args.second_scale,
                           tuple(args.second_at), args.angle, True, args.show,
                           args.radius, tuple(args.heights))
    if args.json:
        Path(args.json).write_text(json.dumps({"args": vars(args), "totals": totals, "leaks": found}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
