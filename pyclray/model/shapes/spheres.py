"""A batch of spheres: one shape (one id, one material) of N spheres held as numpy arrays, never a
Python object per sphere. Each sphere is one entry of the packed arrays, tested by the sphere's own
kernel code; the ``primitive`` image says which sphere of the batch a pixel sees."""
from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SceneError, _shown
from .base import Shape
from .sphere import Sphere
from .reference import exact_at_most, plain_closest, rational


def _array(key: str, value, shape_tail: tuple, what: str) -> np.ndarray:
    """value as a read-only float64 array of shape (N, *shape_tail), every element finite."""
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise SceneError(f"expected {what}, got {_shown(value)}", key=key) from None
    if array.size == 0 and shape_tail:
        raise SceneError("expected at least one sphere, got an empty array", key=key)
    if array.ndim != 1 + len(shape_tail) or array.shape[1:] != shape_tail:
        raise SceneError(f"expected {what}, got an array of shape {array.shape}", key=key)
    bad = ~np.isfinite(array).reshape(len(array), -1).all(axis=1)
    if bad.any():
        index = int(np.argmax(bad))
        raise SceneError(f"expected finite numbers, got {array[index].tolist()!r} at index {index}", key=key)
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class Spheres(Shape):
    """N spheres as one shape: centers (N, 3) and radii (N,) (or one radius for all), any array-like
    of numbers. Compared by identity (a batch is one object however many spheres it holds)."""

    centers: np.ndarray
    radii: np.ndarray
    name: str = "spheres"

    type = "spheres"
    c_type = "Sphere"
    solid = True
    keys = ("file", "centers", "radii", "radius")
    struct = Sphere.struct
    world = Sphere.world
    kernel_files = ("sphere.cl", "spheres.cl")
    inside_test = True  # its inside: <type>_inside (the closest-point query)
    tested_from_world = True  # rebased on the eye where tested: no per-view copy (Shape.tested_from_world)
    reads_files = True

    def object_poses(self) -> np.ndarray:
        """Each sphere's own space: its centre at 0, the world's axes."""
        frames = np.broadcast_to(np.eye(4), (len(self.centers), 4, 4)).copy()
        frames[:, :3, 3] = self.centers
        return frames

    def object_pose(self) -> np.ndarray | None:
        return None  # one space per sphere: object_poses

    def __post_init__(self):
        centers = _array("centers", self.centers, (3,), "an array of shape (N, 3) of sphere centres")
        if not len(centers):
            raise SceneError("expected at least one sphere, got an empty array", key="centers")
        radii = self.radii
        if np.ndim(radii) == 0:
            try:
                radii = np.full(len(centers), float(radii))
            except (TypeError, ValueError):
                raise SceneError(f"expected a number, got {_shown(radii)}", key="radii") from None
        radii = _array("radii", radii, (), f"an array of shape ({len(centers)},) of radii, one per centre")
        if len(radii) != len(centers):
            raise SceneError(f"expected {len(centers)} radii, one per centre, got {len(radii)}", key="radii")
        bad = ~(radii > 0)
        if bad.any():
            index = int(np.argmax(bad))
            raise SceneError(f"expected radii > 0, got {float(radii[index])!r} at index {index}", key="radii")
        object.__setattr__(self, "centers", centers)
        object.__setattr__(self, "radii", radii)

    def __repr__(self) -> str:
        return f"Spheres({len(self.centers)} spheres, name={self.name!r})"

    @classmethod
    def _from_table(cls, table, name, folder=None):
        inline = [k for k in ("centers", "radii", "radius") if k in table]
        if "file" in table:
            if inline:
                raise SceneError(f"expected 'file' or inline arrays, not both (got 'file' and '{inline[0]}')", key="file")
            centers, radii = cls._read(table["file"], folder)
            return cls(centers, radii, name)
        if "centers" not in table:
            raise SceneError("expected 'file' (an .npz of centers and radii) or 'centers'", key="centers")
        if ("radii" in table) == ("radius" in table):
            raise SceneError("expected exactly one of 'radii' (one per centre) or 'radius' (for all), got "
                             + ("both" if "radii" in table else "neither"), key="radii")
        if "radius" in table and (isinstance(table["radius"], bool) or not isinstance(table["radius"], (int, float))):
            raise SceneError(f"expected a number, got {_shown(table['radius'])}", key="radius")
        return cls(table["centers"], table["radii"] if "radii" in table else table["radius"], name)

    @staticmethod
    def _read(path, folder):
        if not isinstance(path, str):
            raise SceneError(f"expected the path of an .npz file, got {_shown(path)}", key="file")
        full = Path(folder or ".") / path
        try:
            with np.load(full, allow_pickle=False) as data:
                missing = [k for k in ("centers", "radii") if k not in data.files]
                if missing:
                    raise SceneError(f"{path}: expected arrays 'centers' and 'radii', it has none named '{missing[0]}' "
                                     f"(it has {', '.join(data.files) or 'no arrays'})", key="file")
                return data["centers"], data["radii"]
        except SceneError:
            raise
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:  # a truncated or foreign file too
            reason = error.strerror if isinstance(error, OSError) and error.strerror else str(error)
            raise SceneError(f"cannot read {path}: {reason.lower()}", key="file") from None

    def primitive_count(self) -> int:
        return len(self.centers)

    def describe(self) -> str:
        return f"spheres '{self.name}' ({len(self.centers)} spheres)"

    def lengths(self, eye) -> dict[str, float]:
        with np.errstate(over="ignore", invalid="ignore"):
            return {"centers": float(np.linalg.norm(self.centers - np.asarray(eye), axis=1).max()),
                    "radii": float(self.radii.max())}

    # -- device: as many spheres ------------------------------------------------------------------
    @classmethod
    def _pack_world(cls, out, batches):
        out["center"][:, :3] = np.concatenate([b.centers for b in batches])
        out["center"][:, 3] = np.concatenate([b.radii for b in batches])

    _rebase = Sphere._rebase
    bounds_of = Sphere.bounds_of
    spheres_of = Sphere.spheres_of

    # -- the float64 oracle: the nearest of the batch's spheres ----------------------------------------
    def _each(self):
        return (Sphere(tuple(c), float(r)) for c, r in zip(self.centers.tolist(), self.radii.tolist()))

    def oracle_distance(self, origins, directions):
        best = np.full(np.shape(directions)[:-1], np.inf)
        for sphere in self._each():
            best = np.minimum(best, sphere.oracle_distance(origins, directions))
        return best

    def oracle_primitives(self, origins, directions):
        return self.oracle_hits(origins, directions)[1]

    def oracle_crossings(self, origins, directions):
        """Each sphere's crossings (Sphere.oracle_crossings), with its index in the batch."""
        ts, primitives = [], []
        for index, sphere in enumerate(self._each()):
            t, _ = sphere.oracle_crossings(origins, directions)
            ts.append(t)
            primitives.append(np.full(t.shape, index, np.int64))
        return np.concatenate(ts, axis=1), np.concatenate(primitives, axis=1)

    def hit_normals(self, points, primitives):
        """The outward normal of each point's own sphere of the batch (its primitive)."""
        n = np.asarray(points, np.float64) - self.centers[primitives]
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def oracle_hits(self, origins, directions):
        """(distance, primitive index) of the nearest sphere of the batch per ray (inf, -1 on a miss)."""
        best = np.full(np.shape(directions)[:-1], np.inf)
        which = np.full(best.shape, -1)
        for index, sphere in enumerate(self._each()):
            t = sphere.oracle_distance(origins, directions)
            nearer = t < best
            best, which = np.where(nearer, t, best), np.where(nearer, index, which)
        return best, which

    def _nearest_surface(self, points):
        points = np.asarray(points, np.float64)
        gaps = np.abs(np.linalg.norm(points[..., None, :] - self.centers, axis=-1) - self.radii)
        return gaps.argmin(axis=-1), gaps.min(axis=-1)

    def oracle_normal(self, points):
        index, _ = self._nearest_surface(points)
        n = np.asarray(points, np.float64) - self.centers[index]
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def surface_distance(self, points):
        return self._nearest_surface(points)[1]


    def oracle_closest(self, points):
        points = np.asarray(points, np.float64)
        F = points[:, None, :] - self.centers
        length = np.linalg.norm(F, axis=-1)
        gap = np.abs(length - self.radii)
        index = gap.argmin(axis=-1)  # the lowest primitive on an exact tie
        rows = np.arange(len(points))
        f, l = F[rows, index], length[rows, index]
        n = np.where(l[:, None] > 0, f / np.where(l > 0, l, 1.0)[:, None], [0.0, 0.0, 1.0])
        position = self.centers[index] + self.radii[index][:, None] * n
        return position, n, index.astype(np.int64), np.zeros((len(points), 2)), gap[rows, index]

    def oracle_inside(self, points, sign="parity"):
        """In any of its spheres (each |p - C|^2 <= r^2, exactly)."""
        from .sphere import Sphere

        points = np.asarray(points, np.float64)
        out = np.zeros(len(points), bool)
        for center, radius in zip(self.centers, self.radii):
            out |= Sphere(center=tuple(center), radius=float(radius)).oracle_inside(points)
        return out

    @classmethod
    def random(cls, rng, shift=0.0):
        """A few spheres that do not overlap (on distinct cells of a grid of side 2, each within its
        cell), so that the generic tests' points inside a solid are inside one sphere."""
        count = int(rng.integers(2, 6))
        cells = rng.choice(27, size=count, replace=False)
        grid = np.stack([cells // 9, (cells // 3) % 3, cells % 3], axis=1) * 2.0 - 2.0
        radii = 10 ** rng.uniform(-1.3, -0.1, count)
        return cls(grid + rng.uniform(-0.2, 0.2, (count, 3)) + shift, radii)

    # -- the error model: as its farthest sphere (a bound for any of them) -------------------------
    def anchor(self, point):
        return self.centers[np.linalg.norm(self.centers - np.asarray(point), axis=1).argmax()]

    def curvature_radius(self) -> float:
        return float(self.radii.min())

    def extent_from(self, point) -> float:
        return float((np.linalg.norm(self.centers - np.asarray(point, np.float64), axis=1) + self.radii).max())

    # -- Mitsuba 3 -----------------------------------------------------------------------------
    def mitsuba_shapes(self, scene):
        return [{"type": "sphere", "center": list(c), "radius": r} for c, r in zip(self.centers.tolist(), self.radii.tolist())]
