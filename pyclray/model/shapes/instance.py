"""Mesh instances: meshes that share their arrays (the same file in a scene file, the same loaded
Mesh placed many times in Python) packed as one copy of the triangles in the mesh's own (object)
space and, per mesh placed, an instance: its transform and a top-level box (two levels: DESIGN.md
item 12, Embree's instances, Mitsuba's shapegroup/instance).

Not a scene type of its own: the scene holds Mesh shapes (the oracle, the checks and Mitsuba see
each as the mesh it is), and only the prepared scene packs the meshes that share their arrays as
instances (``Mesh.packed_as``). An instance's entry holds object_from_world (float64), its normal
matrix and its object box; engine/scene/instances.py builds the one BVH per shared mesh (in object space)
over the shared triangles, and kernels/instance.cl enters it through the inverse transform.

Per view (``_rebase``, kernels/instance.cl's instance_rebase: the same float64 operations), each
instance gets the eye in object space, e = object_from_world (eye - translate) in float64: the
object-space triangles are rebased on it (their float64 difference rounded once, at each visit), as
a mesh's world triangles are rebased on the eye, so a far instance keeps float32's relative precision;
and object_from_space / k rounded to the kernel's precision (the ray's direction in object space,
its one extra rounding: a relative error of about 3 eps of the direction, which the error model's
K eps (t + L) bounds many times over), k a power of two with |object_from_space / k| <= 1, so that
the box tests' cone (kernels/bvh.h) is as wide in the object's units as in the world's.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..layout import Struct
from .base import Shape
from .capabilities import SharedArrays, SmoothShading
from .device import padded_bounds
from .mesh import Mesh
from .mesh_sharing import shared_key

# the shared arrays the kernel takes after the instances' array: (name, OpenCL C element type)
# (each distinct mesh once: its object-space vertices (float64, w 0), its faces in its tree's leaf order
# (three vertex indices into the vertices and its index in its mesh, ~index where it has zero area), the
# tree's binary nodes (where a program traverses pair nodes, one ray per work-item, the trees' pair nodes
# instead: engine/scene/prepared.py, shared_of), and the vertices' unit object-space normals where an
# instance is smooth: engine/scene/instances.py)
SHARED = (("vertices", "double4"), ("faces", "int4"), ("nodes", "BvhNode"), ("normals", "double4"))


@dataclass(frozen=True, eq=False)
class Instances(SharedArrays, SmoothShading, Shape):
    """The packing of meshes as instances (never in a scene: see the module's docstring): its device
    part only; what the oracle and the checks ask of a shape is the Mesh's (each instance is the mesh
    it places)."""

    type = "instance"
    c_type = "Instance"
    keys = ()
    kernel_files = ("mesh.cl", "mesh_blocks.cl", "mesh_closest.cl", "instance.cl")
    shared = SHARED
    kernel_structs = (Mesh.struct, Mesh.world, Mesh.smooth_struct)
    # smooth shading: per instance whether it is smooth (its mesh's vertex normals are shared: SHARED)
    smooth_struct = Struct("InstanceNormals", (("smooth", "int"),), "Whether an instance shades with its mesh's vertex normals.")
    barycentric = True
    world = Struct(
        "InstanceWorld",
        (
            ("inverse0", "double4"),  # rows of object_from_world's 3x3 part
            ("inverse1", "double4"),
            ("inverse2", "double4"),
            ("translate", "double4"),  # world_from_object's translation
            ("normal0", "double4"),  # rows of sign(det A) A^-T: a world normal's direction from an object one
            ("normal1", "double4"),
            ("normal2", "double4"),
            ("anchor", "double4"),  # the object-space point its BVH's boxes are around; w: k (a power of two)
            ("lo", "double4"),  # the mesh's object-space box
            ("hi", "double4"),
            ("root", "int"),  # its BVH's first node and first triangle in the shared arrays (engine/scene/instances.py)
            ("first", "int"),
        ),
        "A mesh instance: object_from_world, its normal matrix, its object box and its BVH in the shared arrays.",
    )
    struct = Struct(
        "Instance",
        (
            ("eye", "double4"),  # the space's origin in object space (float64)
            ("normal0", "double4"),  # rows of the normal matrix (as in the world entry)
            ("normal1", "double4"),
            ("normal2", "double4"),
            ("box", "float4"),  # the eye from the BVH's anchor, rounded; w: a margin over that rounding
            ("m0", "real4"),  # rows of object_from_space / k, rounded once; m0.w: k
            ("m1", "real4"),
            ("m2", "real4"),
            # what rounding m0, m1, m2 left out, rounded (row + row_low: the fp32 camera rays' object
            # directions in float64 from the exact pixel point, kernels/instance.cl's instance_pixel_row)
            ("m_low0", "real4"),
            ("m_low1", "real4"),
            ("m_low2", "real4"),
            ("root", "int"),
            ("first", "int"),
            ("id", "int"),
            ("primitive", "int"),
        ),
        "A mesh instance in a space: the eye in object space and the space's directions there.",
    )

    @classmethod
    def entries_of(cls, shapes, ids):
        """One entry per instance (its triangles are shared, not entries)."""
        return np.asarray(ids, np.int32).reshape(-1), np.zeros(len(shapes), np.int32)

    @classmethod
    def pack_world(cls, shapes) -> np.ndarray:
        from ..layout import layout

        out = np.zeros(len(shapes), dtype=layout(cls.world, "fp64").dtype)
        boxes: dict = {}  # each shared mesh's object box once
        for k, mesh in enumerate(shapes):
            m = mesh.transform()
            a = m[:3, :3]
            inverse = np.linalg.inv(a)
            normal = np.sign(np.linalg.det(a)) * inverse.T
            for r in range(3):
                out[f"inverse{r}"][k, :3] = inverse[r]
                out[f"normal{r}"][k, :3] = normal[r]
            out["translate"][k, :3] = m[:3, 3]
            key = shared_key(mesh)
            if key not in boxes:
                boxes[key] = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
            lo, hi = boxes[key]
            out["lo"][k, :3], out["hi"][k, :3] = lo, hi
            out["anchor"][k, :3] = 0.5 * (lo + hi)
            # k: a power of two at least the largest |object_from_world d| of a unit d (the Frobenius
            # norm bounds it), so that the object rays' directions (divided by it, exactly) are at most unit
            out["anchor"][k, 3] = 2.0 ** np.ceil(np.log2(np.linalg.norm(inverse)))
        return out

    @classmethod
    def pack_smooth(cls, shapes, precision: str):
        """1 for each smooth instance, 0 for a flat one; None where none is smooth."""
        if not any(mesh.smooth for mesh in shapes):
            return None
        from ..layout import layout

        out = np.zeros(len(shapes), dtype=layout(cls.smooth_struct, precision).dtype)
        out["smooth"] = [1 if mesh.smooth else 0 for mesh in shapes]
        return out

    @classmethod
    def bounds_of(cls, world):
        """The world box of each instance: its object box's corners placed (float64), padded."""
        inverse = np.stack([world[f"inverse{r}"][:, :3] for r in range(3)], axis=1)
        forward = np.linalg.inv(inverse)
        lo, hi = world["lo"][:, :3], world["hi"][:, :3]
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        middle = np.einsum("nij,nj->ni", forward, centre) + world["translate"][:, :3]
        reach = np.einsum("nij,nj->ni", np.abs(forward), half)
        pad = 1e-9 * (np.abs(middle) + reach)  # the rounding of this placement, and of the inverse's inverse
        return padded_bounds(middle - reach - pad, middle + reach + pad)

    @classmethod
    def _rebase(cls, out, world, origin, rotation_rows):
        # the eye in object space: object_from_world (origin - translate), summed as instance_rebase does
        F = origin - world["translate"][:, :3]
        eye = np.stack([_dot3(world[f"inverse{r}"][:, :3], F) for r in range(3)], axis=1)
        out["eye"][:, :3] = eye
        for r in range(3):
            out[f"normal{r}"][:, :3] = world[f"normal{r}"][:, :3]
        scale = world["anchor"][:, 3]
        for r in range(3):  # object_from_space = object_from_world world_from_space, over k (exact)
            row = world[f"inverse{r}"][:, :3]
            exact = np.stack([_dot3(row, np.broadcast_to(axis, row.shape)) for axis in rotation_rows], axis=1) / scale[:, None]
            out[f"m{r}"][:, :3] = exact
            out[f"m_low{r}"][:, :3] = exact - out[f"m{r}"][:, :3].astype(np.float64)
        out["m0"][:, 3] = scale
        box = (eye - world["anchor"][:, :3]).astype(np.float32)
        out["box"][:, :3] = box
        out["box"][:, 3] = 2.0**-20 * np.abs(box.astype(np.float64)).sum(axis=1)
        out["root"], out["first"] = world["root"], world["first"]


def _dot3(x, y):
    """Row-wise (x0 y0 + x1 y1) + x2 y2 in float64, the order kernels/instance.cl sums in."""
    return (x[:, 0] * y[:, 0] + x[:, 1] * y[:, 1]) + x[:, 2] * y[:, 2]
