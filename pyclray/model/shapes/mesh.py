"""The triangle mesh: one shape (one id, one material) of many triangles held as numpy arrays.

Each triangle is one entry of the packed arrays (as a batch's spheres are), with its three world
vertices in float64 and its world normal; the per-view pass subtracts the eye from each vertex in
float64 and rounds once, so that a vertex shared by two triangles has the same bits in both and the
watertight test of kernels/mesh.cl (Woop, Benthin and Wald 2013) sees one edge, whatever the
distance to the world's origin. A world point is translate + R(axis, angle) (scale * p), or matrix
applied to p (scene-format.md, "Triangle meshes").
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from functools import partial

import numpy as np

from ..errors import SceneError, _shown, number, vector3
from ..layout import Struct, layout
from . import mesh_pack
from .mesh_keys import faces_of, matrix_of, vertices_of
from .base import Shape, flag
from .capabilities import CastBlocks, IndexedTriangles, Instancing, SmoothShading
from .device import in_space, padded_bounds
from .rotations import axis_angle, rotation
# mesh_io (file readers) and mesh_oracle (the float64 reference) are imported where used: a scene
# without a mesh file, and every render, needs neither (docs/benchmarks.md, "Why the engine does what it
# does")

FIXED = {"animatable": False}
PLACEMENT = ("scale", "axis", "angle", "translate")


@dataclass(frozen=True, eq=False)
class Mesh(IndexedTriangles, CastBlocks, Instancing, SmoothShading, Shape):
    """A triangle mesh: vertices (V, 3) and faces (F, 3) (0-based vertex indices), placed by scale,
    axis and angle, translate, or a 4x4 matrix; smooth: the shaded image interpolates vertex normals
    (normals (V, 3), else area-weighted). Compared by identity, like a batch of spheres.

    ``Mesh.load(path)`` reads a file once; ``mesh.placed(translate=...)`` places the same arrays
    again (the vertices and faces are shared, not copied)."""

    vertices: np.ndarray = field(metadata=FIXED)
    faces: np.ndarray = field(metadata=FIXED)
    scale: float | tuple = 1.0
    axis: tuple | None = None
    angle: float = 0.0
    translate: tuple = (0.0, 0.0, 0.0)
    matrix: tuple | None = field(default=None, metadata=FIXED)
    smooth: bool = field(default=False, metadata=FIXED)
    normals: np.ndarray | None = field(default=None, metadata=FIXED)
    name: str = "mesh"
    # The arrays whose checks this mesh passed (vertices, faces, normals), which dataclasses.replace
    # carries to its copies: a mesh placed again (Mesh.placed, 10,000 instances, an animation's
    # frame) is not checked again (docs/benchmarks.md, "Why the engine does what it does"); compared
    # by identity, so a copy given other arrays checks those.
    _checked: tuple | None = field(default=None, repr=False, compare=False, metadata=FIXED)

    type = "mesh"
    c_type = "Triangle"
    keys = ("file", "split", "vertices", "faces", "scale", "axis", "angle", "translate", "matrix", "smooth")
    reads_files = True
    struct = Struct(
        "Triangle",
        (
            ("a", "real4"),  # vertex a in the space (from float64, rounded once); w: the world normal's x
            ("b", "real4"),  # vertex b; w: the world normal's y
            ("c", "real4"),  # vertex c; w: the world normal's z (a zero normal: a zero-area triangle)
            ("id", "int"),
            ("primitive", "int"),  # the triangle's index in its mesh
        ),
        "Triangle: its vertices in the space and (in w) its unit world normal from float64.",
    )
    world = Struct(
        "TriangleWorld",
        (
            ("a", "double4"),  # world vertices; w: the unit world normal normalize(cross(b - a, c - a))
            ("b", "double4"),
            ("c", "double4"),
        ),
        "A triangle in world coordinates: vertices a, b, c and (in w) its unit normal.",
    )
    kernel_files = ("mesh.cl", "mesh_blocks.cl", "mesh_closest.cl")  # the ray tests, cast's blocks, the closest point
    # Triangles per BVH leaf at most: 7, the most the wide BVH's leaf code holds (engine/bvh/wide.py:
    # count < 8), about a packet's 8 lanes: a triangle test is cheap next to a node's box test and the
    # stack (docs/benchmarks.md, "Why the engine does what it does": Mesh.leaf_size)
    leaf_size = 7
    smooth_struct = Struct(
        "TriangleNormals",
        (
            ("a", "real4"),  # the unit world vertex normals at a, b, c (smooth shading); all 0: flat
            ("b", "real4"),
            ("c", "real4"),
        ),
        "A triangle's unit world vertex normals for smooth shading (zero for a flat mesh's triangles).",
    )
    barycentric = True
    winding_number = True  # inside: its triangles' parity or winding number (the closest-point query)
    mitsuba_primitives = True

    def __post_init__(self):
        arrays = (self.vertices, self.faces, self.normals)
        known = self._checked is not None and all(a is b for a, b in zip(self._checked, arrays))
        vertices = self.vertices if known else vertices_of(self.vertices)
        object.__setattr__(self, "vertices", vertices)
        if not known:
            object.__setattr__(self, "faces", faces_of(self.faces, len(vertices)))
        scale = self.scale
        if np.ndim(scale) == 0:
            scale = number("scale", scale)
            bad = scale == 0
        else:
            scale = vector3("scale", scale)
            bad = any(s == 0 for s in scale)
        if bad:
            raise SceneError(f"expected non-zero scale factors, got {_shown(self.scale)}", key="scale")
        object.__setattr__(self, "scale", scale)
        axis, angle = axis_angle(self.axis, self.angle)
        object.__setattr__(self, "axis", axis)
        object.__setattr__(self, "angle", angle)
        object.__setattr__(self, "translate", vector3("translate", self.translate))
        if self.matrix is not None:
            placed = [k for k in PLACEMENT if getattr(self, k) != getattr(Mesh, k, None)
                      and not (k == "translate" and self.translate == (0.0, 0.0, 0.0))]
            if placed:
                raise SceneError(f"expected 'matrix' or scale/axis/angle/translate, not both (got '{placed[0]}' too)",
                                 key="matrix")
            object.__setattr__(self, "matrix", matrix_of(self.matrix))
        object.__setattr__(self, "smooth", flag("smooth", self.smooth))
        if self.normals is not None and not known:
            object.__setattr__(self, "normals", vertices_of(self.normals, "normals"))
            if len(self.normals) != len(vertices):
                raise SceneError(f"expected {len(vertices)} normals, one per vertex, got {len(self.normals)}", key="normals")
        object.__setattr__(self, "_checked", (self.vertices, self.faces, self.normals))
        object.__setattr__(self, "_cache", {})

    def __eq__(self, other) -> bool:
        """The same arrays (by identity: a mesh is one object however many triangles it holds) and
        equal other fields (an animation frame that keys a placement to its own value is equal)."""
        if type(other) is not Mesh:
            return NotImplemented
        same = all(getattr(self, k) is getattr(other, k) for k in ("vertices", "faces", "normals"))
        return same and all(getattr(self, f.name) == getattr(other, f.name) for f in fields(self)
                            if f.compare and f.name not in ("vertices", "faces", "normals"))

    def __hash__(self) -> int:
        return hash((id(self.vertices), id(self.faces), self.scale, self.axis, self.angle, self.translate, self.name))

    def __repr__(self) -> str:
        return f"Mesh({len(self.faces)} triangles, {len(self.vertices)} vertices, name={self.name!r})"

    @property
    def closed(self) -> bool:
        """Whether the mesh is closed: every edge is shared by exactly two faces, which run along it
        in opposite directions (consistently oriented, no border, no edge of three faces). A closed
        mesh has an inside (signed_distance and occupancy with sign="parity"). From its faces alone,
        found once (its faces are fixed) and kept."""
        closed = self._cache.get("closed")
        if closed is None:
            closed = self._cache["closed"] = edges_closed(self.faces, len(self.vertices))
        return closed

    def describe(self) -> str:
        return f"mesh '{self.name}' ({len(self.faces)} triangles)"

    # -- files and placement -------------------------------------------------------------------
    @classmethod
    def load(cls, path, split: bool = False, **keys) -> "Mesh | tuple[Mesh, ...]":
        """The mesh of a file (OBJ, PLY, STL, OFF, glTF/GLB; read once per unchanged file), with
        these keys (scale, axis, angle, translate, matrix, smooth, name, material, label).

        split=True: a tuple of one mesh per object of the file, in its order (OBJ's `o` and `g`
        groups, glTF's nodes with their transforms applied; another file is one object), each with
        the keys given and named as its object (made unique), after ``name.`` where a name is given."""
        if split is not True:
            if split is not False:
                raise SceneError(f"expected True or False, got {_shown(split)}", key="split")
            vertices, faces, normals = _read_mesh(path)
            return cls(vertices, faces, normals=normals, **keys)
        return cls._split(_read_mesh_objects(path), keys.pop("name", None), keys)

    @classmethod
    def _split(cls, objects, name, keys) -> tuple:
        """One mesh per (object name, vertices, faces, normals), named name.object (object alone
        without a name), the other keys alike."""
        return tuple(cls(vertices, faces, normals=normals, name=own if name is None else f"{name}.{own}", **keys)
                     for own, vertices, faces, normals in objects)

    def placed(self, **keys) -> "Mesh":
        """The same triangles (shared arrays) placed anew: scale, axis, angle, translate or matrix
        (the placement keys not given are reset), and any other key to change (name, smooth ...)."""
        reset = {k: getattr(Mesh, k, None) for k in PLACEMENT + ("matrix",)}
        reset["translate"] = (0.0, 0.0, 0.0)
        return replace(self, **{**reset, **keys})

    @classmethod
    def _from_table(cls, table, name, folder=None):
        keys = {k: table[k] for k in ("scale", "axis", "angle", "translate", "matrix", "smooth") if k in table}
        split = flag("split", table.get("split", False))
        if split and "file" not in table:
            raise SceneError("expected 'file' with split = true (a file's objects as shapes of their own)", key="split")
        if split:  # one shape per object of the file: named after the table's name where it has one
            inline = [k for k in ("vertices", "faces") if k in table]
            if inline:
                raise SceneError(f"expected 'file' or inline 'vertices' and 'faces', not both (got 'file' and "
                                 f"'{inline[0]}')", key="file")
            return cls._split(_read_mesh_objects(table["file"], folder), table.get("name"), keys)
        if "file" in table:
            inline = [k for k in ("vertices", "faces") if k in table]
            if inline:
                raise SceneError(f"expected 'file' or inline 'vertices' and 'faces', not both (got 'file' and "
                                 f"'{inline[0]}')", key="file")
            vertices, faces, normals = _read_mesh(table["file"], folder)
            return cls(vertices, faces, normals=normals, name=name, **keys)
        for key in ("vertices", "faces"):
            if key not in table:
                raise SceneError("expected 'file' (a mesh file) or inline 'vertices' and 'faces'", key=key)
        return cls(table["vertices"], table["faces"], name=name, **keys)

    # -- world geometry ------------------------------------------------------------------------
    def transform(self) -> np.ndarray:
        """The 4x4 float64 matrix world_from_object."""
        if self.matrix is not None:
            return np.array(self.matrix, np.float64)
        out = np.eye(4)
        out[:3, :3] = rotation(self.axis, self.angle) * np.asarray(self.scale, np.float64)
        out[:3, 3] = self.translate
        return out

    def object_pose(self) -> np.ndarray:
        """world_from_object: the placement (transform) of the file's coordinates."""
        return self.transform()

    def object_model(self) -> tuple[np.ndarray, np.ndarray]:
        """The file's vertices and the faces (the mesh in its own space)."""
        return self.vertices, self.faces

    def world_vertices(self) -> np.ndarray:
        """(V, 3) float64: translate + R (scale p) (or the matrix's), per vertex (computed once)."""
        if "vertices" not in self._cache:
            m = self.transform()
            rotated = self.vertices @ m[:3, :3].T
            world = rotated + m[:3, 3]
            world.setflags(write=False)
            self._cache["vertices"] = world
        return self._cache["vertices"]

    def corners(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w = self.world_vertices()
        return w[self.faces[:, 0]], w[self.faces[:, 1]], w[self.faces[:, 2]]

    def face_normals(self) -> np.ndarray:
        """(F, 3) unit world normals normalize(cross(b - a, c - a)) in float64, (0, 0, 0) for a
        triangle of zero area (within the float64 rounding of the cross product: such a triangle is
        never hit)."""
        if "normals" not in self._cache:
            a, b, c = self.corners()
            e1, e2 = b - a, c - a
            n = np.cross(e1, e2)
            length = np.linalg.norm(n, axis=1)
            size = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
            flat = ~(length > 8 * 2.0**-53 * size)
            with np.errstate(invalid="ignore", divide="ignore"):
                n = np.where(flat[:, None], 0.0, n / np.where(flat, 1.0, length)[:, None])
            self._cache["normals"] = n
        return self._cache["normals"]

    def vertex_normals(self) -> np.ndarray:
        """(V, 3) unit world vertex normals for smooth shading: the file's (or the given ones),
        turned by the inverse transpose of the placement, else the area-weighted sum of the faces'."""
        if "vertex_normals" not in self._cache:
            if self.normals is not None:
                n = self.normals @ np.linalg.inv(self.transform()[:3, :3])
            else:
                a, b, c = self.corners()
                weighted = np.cross(b - a, c - a)  # twice the area times the unit normal
                n = np.zeros_like(self.world_vertices())
                for k in range(3):
                    np.add.at(n, self.faces[:, k], weighted)
            length = np.linalg.norm(n, axis=1, keepdims=True)
            self._cache["vertex_normals"] = np.where(length > 0, n / np.where(length > 0, length, 1.0), 0.0)
        return self._cache["vertex_normals"]

    def primitive_count(self) -> int:
        return len(self.faces)

    def lengths(self, eye) -> dict[str, float]:
        with np.errstate(over="ignore", invalid="ignore"):
            return {"vertices": float(np.linalg.norm(self.world_vertices() - np.asarray(eye), axis=1).max())}

    # -- device ----------------------------------------------------------------------------------
    @classmethod
    def packed_as(cls, shapes, ids) -> dict:
        """Meshes that share their arrays with another are packed as instances (model/shapes/instance.py)."""
        from .mesh_sharing import split_meshes

        return split_meshes(shapes, ids)

    @classmethod
    def _pack_world(cls, out, meshes):
        start = 0
        for mesh in meshes:
            a, b, c = mesh.corners()
            rows = slice(start, start + len(a))
            for name, v in (("a", a), ("b", b), ("c", c)):
                out[name][rows, :3] = v
            normal = mesh.face_normals()
            out["a"][rows, 3], out["b"][rows, 3], out["c"][rows, 3] = normal[:, 0], normal[:, 1], normal[:, 2]
            start += len(a)

    @classmethod
    def pack_indexed(cls, meshes):
        return mesh_pack.indexed(meshes)

    @classmethod
    def pack_indexed_smooth(cls, meshes, precision: str):
        return mesh_pack.indexed_smooth(meshes, precision)

    @classmethod
    def pack_smooth(cls, meshes, precision: str):
        """Per triangle its vertex normals (vertex_normals: unit, world) where its mesh is smooth,
        zeros where it is not (the kernel then lights with the geometric normal); None without a
        smooth mesh. In world coordinates: the kernel turns the interpolated normal into the view's."""
        if not any(mesh.smooth for mesh in meshes):
            return None
        out = np.zeros(sum(len(m.faces) for m in meshes), dtype=layout(cls.smooth_struct, precision).dtype)
        start = 0
        for mesh in meshes:
            rows = slice(start, start + len(mesh.faces))
            if mesh.smooth:
                normals = mesh.vertex_normals()
                for k, name in enumerate("abc"):
                    out[name][rows, :3] = normals[mesh.faces[:, k]]
            start += len(mesh.faces)
        return out

    @classmethod
    def _rebase(cls, out, world, origin, rotation_rows):
        # each vertex minus the space's origin in float64, along the space's axes, rounded once: a
        # vertex shared by two triangles gets the same bits in both (the watertight test needs it)
        for name in ("a", "b", "c"):
            out[name][:, :3] = in_space(world[name][:, :3] - origin, rotation_rows)
            out[name][:, 3] = world[name][:, 3]

    @classmethod
    def pack_cast_blocks(cls, vertices, corners, ids, entries, starts):
        return mesh_pack.cast_blocks(vertices, corners, ids, entries, starts)

    @classmethod
    def bounds_of(cls, world):
        a, b, c = (world[k][:, :3] for k in ("a", "b", "c"))
        return padded_bounds(np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c))

    @classmethod
    def cast_anchors(cls, world, ids) -> np.ndarray:
        """(N, 4) per entry: cast's anchor (xyz) and bounding radius (w) of its whole mesh (the box
        of the entries of its id), so that a cast ray meets every triangle of a mesh from one
        rounded origin and the shared vertices keep their bits (watertight, as for camera rays)."""
        bounds = cls.bounds_of(world)
        unique, group = np.unique(ids, return_inverse=True)
        lo = np.full((len(unique), 3), np.inf)
        hi = np.full((len(unique), 3), -np.inf)
        np.minimum.at(lo, group, bounds[:, 0])
        np.maximum.at(hi, group, bounds[:, 1])
        out = np.empty((len(ids), 4))
        out[:, :3] = (0.5 * (lo + hi))[group]
        # the radius with the margin of the BVH's boxes (2^-12 of their size: engine/bvh/tree.py's WIDEN)
        out[:, 3] = (0.5 * np.linalg.norm(hi - lo, axis=1) * (1 + 2.0**-12))[group]
        return out

    # -- the float64 oracle ----------------------------------------------------------------------
    def _hierarchy(self):
        if "hierarchy" not in self._cache:
            a, b, c = self.corners()
            from .mesh_oracle import Hierarchy

            self._cache["hierarchy"] = Hierarchy(a, b, c, self.face_normals().any(axis=1))
        return self._cache["hierarchy"]

    def oracle_hits(self, origins, directions):
        """(t, triangle index, (u, v)) of each ray's nearest hit (inf, -1, (0, 0) on a miss)."""
        origins = np.broadcast_to(np.asarray(origins, np.float64), np.shape(directions)).reshape(-1, 3)
        directions = np.asarray(directions, np.float64).reshape(-1, 3)
        return self._hierarchy().intersect(origins, directions)

    def oracle_primitives(self, origins, directions):
        return self.oracle_hits(origins, directions)[1]

    def oracle_crossings(self, origins, directions):
        """Every triangle each ray crosses, by kernels/mesh.cl's test and tie rule in exact
        arithmetic (mesh_oracle.crossings): each crossing of the surface once."""
        from .mesh_oracle import crossings

        O = np.broadcast_to(np.asarray(origins, np.float64), np.shape(directions)).reshape(-1, 3)
        D = np.asarray(directions, np.float64).reshape(-1, 3)
        a, b, c = self.corners()
        valid = np.any(self.face_normals() != 0, axis=1)
        found = [crossings(a, b, c, valid, o, d) for o, d in zip(O, D)]
        width = max([len(t) for t, _ in found] + [1])
        t = np.full((len(D), width), np.inf)
        primitives = np.full((len(D), width), -1, np.int64)
        for row, (ts, which) in enumerate(found):
            t[row, : len(ts)] = ts
            primitives[row, : len(ts)] = which
        return t, primitives

    def hit_normals(self, points, primitives):
        """Each hit triangle's unit normal (face_normals: the bits cast's normal has)."""
        return self.face_normals()[primitives]

    def hit_barycentrics(self, points, primitives):
        """(u, v) of each point on its triangle (mesh_oracle.barycentrics, float64)."""
        from .mesh_oracle import barycentrics

        a, b, c = (x[primitives] for x in self.corners())
        return np.stack(barycentrics(np.asarray(points, np.float64), a, b, c), axis=-1)

    def oracle_distance(self, origins, directions):
        shape = np.shape(directions)[:-1]
        return self.oracle_hits(origins, directions)[0].reshape(shape)

    def oracle_normal(self, points):
        points = np.asarray(points, np.float64)
        _, which, _ = self._hierarchy().nearest(points.reshape(-1, 3))
        return self.face_normals()[which].reshape(points.shape)

    def surface_distance(self, points):
        points = np.asarray(points, np.float64)
        return self._hierarchy().nearest(points.reshape(-1, 3))[0].reshape(points.shape[:-1])

    def oracle_closest(self, points):
        """The nearest triangle (the lowest index on an exact tie) and its point nearest each point."""
        from .mesh_oracle import closest_on_triangles

        points = np.asarray(points, np.float64).reshape(-1, 3)
        distance, which, _ = self._hierarchy().nearest(points)
        a, b, c = self.corners()
        position, uv = closest_on_triangles(points, a[which], b[which], c[which])
        return position, self.face_normals()[which], which, uv, distance

    def oracle_winding(self, points) -> np.ndarray:
        """The generalized winding number of its triangles at each point (float64, all triangles summed)."""
        from .mesh_oracle import winding_numbers

        return winding_numbers(np.asarray(points, np.float64).reshape(-1, 3), *self.corners())

    def oracle_inside(self, points, sign: str = "parity"):
        """sign "winding": its winding number >= 1/2; "parity": a closed mesh's winding number odd
        (the parity of any ray's crossings; an integer up to rounding away from its surface), an
        open mesh never."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        if sign == "parity" and not self.closed:
            return np.zeros(len(points), bool)
        w = self.oracle_winding(points)
        return w >= 0.5 if sign == "winding" else (np.rint(w).astype(np.int64) % 2 == 1)

    def oracle_shading_normal(self, points, normals):
        """Smooth: the vertex normals interpolated at the barycentrics of each point's nearest
        triangle (float64), normalized; the geometric normal where the mesh is flat or the
        interpolation is zero (as kernels/mesh.cl's mesh_shading_normal)."""
        if not self.smooth:
            return normals
        points = np.asarray(points, np.float64).reshape(-1, 3)
        _, which, _ = self._hierarchy().nearest(points)
        from .mesh_oracle import barycentrics

        u, v = barycentrics(points, *(x[which] for x in self.corners()))
        vertex = self.vertex_normals()[self.faces[which]]  # (N, 3 corners, 3)
        n = (1 - u - v)[:, None] * vertex[:, 0] + u[:, None] * vertex[:, 1] + v[:, None] * vertex[:, 2]
        length = np.linalg.norm(n, axis=1, keepdims=True)
        good = np.isfinite(length) & (length > 0)
        return np.where(good, n / np.where(good, length, 1.0), np.asarray(normals).reshape(-1, 3)).reshape(np.shape(normals))

    def shading_normals(self, primitives, barycentrics, normals):
        """Smooth: the vertex normals of each hit's triangle (``primitives``) interpolated at its
        (u, v) (``barycentrics``), normalized; the geometric normal where the mesh is flat or the
        interpolation is zero (as kernels/mesh.cl's mesh_shading_normal)."""
        normals = np.asarray(normals, np.float64)
        if not self.smooth:
            return normals
        vertex = self.vertex_normals()[self.faces[np.asarray(primitives)]]  # (N, 3 corners, 3)
        u, v = (np.asarray(barycentrics, np.float64)[:, k] for k in (0, 1))
        n = (1 - u - v)[:, None] * vertex[:, 0] + u[:, None] * vertex[:, 1] + v[:, None] * vertex[:, 2]
        length = np.linalg.norm(n, axis=1, keepdims=True)
        good = np.isfinite(length) & (length > 0)
        return np.where(good, n / np.where(good, length, 1.0), normals)

    def edge_distance(self, points):
        """Distance to the nearest edge of the nearest triangle: at every edge (shared or not) a ray
        within rounding may meet either triangle (another normal, another primitive)."""
        points = np.asarray(points, np.float64)
        return self._hierarchy().nearest(points.reshape(-1, 3))[2].reshape(points.shape[:-1])

    @classmethod
    def random(cls, rng, shift=0.0):
        """A closed, perturbed, randomly placed icosphere-like mesh (a UV sphere of 6 x 8 cells
        with random radii per vertex) of about unit size near ``shift``."""
        from .mesh_shapes import perturbed_sphere

        vertices, faces = perturbed_sphere(6, 8, 1.0, 0.2, rng)
        axis = tuple(rng.normal(size=3))
        return cls(vertices, faces, scale=float(10 ** rng.uniform(-0.6, 0.1)), axis=axis,
                   angle=float(rng.uniform(0, 360)), translate=tuple(rng.uniform(-3, 3, 3) + shift))

    # -- the error model: as its farthest vertex (a bound for any of its triangles) ---------------
    def anchor(self, point):
        w = self.world_vertices()
        return w[np.linalg.norm(w - np.asarray(point, np.float64), axis=1).argmax()]

    def extent_from(self, point) -> float:
        return float(np.linalg.norm(self.world_vertices() - np.asarray(point, np.float64), axis=1).max())

    def curvature_radius(self) -> float:
        """The smallest altitude of its (non-degenerate) triangles: a vertex moved by e (Mitsuba's
        float32 positions) turns a triangle's normal by up to about e / altitude, as a position error
        turns a curved surface's normal by e / radius."""
        if "altitude" not in self._cache:
            a, b, c = self.corners()
            twice_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
            longest = np.maximum.reduce([np.linalg.norm(x - y, axis=1) for x, y in ((a, b), (b, c), (c, a))])
            valid = self.face_normals().any(axis=1)
            self._cache["altitude"] = float((twice_area[valid] / longest[valid]).min()) if valid.any() else np.inf
        # smooth: a hit moved by e along a triangle moves its barycentrics by e / altitude and the
        # interpolated normal by up to |n_b - n_a| e / altitude <= 2 e / altitude
        return self._cache["altitude"] / (2 if self.smooth else 1)

    def silhouette_radius(self) -> float:
        """inf: each triangle is flat, so a grazing hit inside it is the plane's |cos| rule only; a
        mesh's silhouettes lie on its edges, where edge_distance (the edge rule) sets them apart.
        The smallest altitude (curvature_radius) here made every pixel of a mesh 1e6 away a
        silhouette (cos^2 < 2 e / r with r ~ 0.01), leaving nothing to judge."""
        return np.inf

    # -- Mitsuba 3 -------------------------------------------------------------------------------
    mitsuba_plugins = ("obj", "ply")
    mitsuba_in_groups = True

    @classmethod
    def from_mitsuba(cls, props, folder):
        """Mitsuba's obj and ply: the triangle mesh of the file (relative to folder), placed by
        to_world. Its geometric normals are the faces' in both; face_normals (whether Mitsuba shades
        with them rather than the file's vertex normals) changes no geometry, and the mesh read is
        not smooth (shaded with the faces' normals)."""
        filename = props.take("filename", "string", required=True)
        to_world = props.to_world()
        props.ignore.update(("face_normals", "flip_tex_coords", "maintain_order"))  # shading, textures, merging
        matrix = None if np.array_equal(to_world.matrix, np.eye(4)) else tuple(map(tuple, to_world.matrix.tolist()))
        return partial(cls.load, folder / filename, matrix=matrix)

    def mitsuba_shapes(self, scene):
        """Mitsuba's mesh from the same arrays: world vertices (float64 here, float32 there) and faces
        (the bridge builds an mi.Mesh of a dict of type 'mesh')."""
        out = {"type": "mesh", "vertex_positions": self.world_vertices(), "faces": self.faces}
        if self.smooth:  # Mitsuba interpolates them at the hit's barycentrics too (its sh_frame)
            out["vertex_normals"] = self.vertex_normals()
        return [out]


def _read_mesh(*args):
    from . import mesh_io

    return mesh_io.read_mesh(*args)


def edges_closed(faces: np.ndarray, vertex_count: int) -> bool:
    """Whether each directed edge (a, b) of the faces occurs once and its reverse (b, a) once: every
    edge shared by exactly two faces with opposite orientations."""
    if not len(faces):
        return False
    faces = np.asarray(faces, np.int64)
    start = faces.reshape(-1)
    end = faces[:, [1, 2, 0]].reshape(-1)
    keys = np.sort(start * vertex_count + end)
    if (keys[1:] == keys[:-1]).any():  # a directed edge of two faces: three or more faces, or flipped ones
        return False
    reverse = end * vertex_count + start
    found = np.searchsorted(keys, reverse)
    return bool((keys[np.minimum(found, len(keys) - 1)] == reverse).all())


def _read_mesh_objects(*args):
    from . import mesh_io

    return mesh_io.read_mesh_objects(*args)
