"""The same scene in Mitsuba 3, as the reference for checks and benchmarks.

Imported lazily, never on the render path (`import mitsuba` takes about a second). Conventions
that differ between pyclray and Mitsuba, and how they are mapped here:

- depth: Mitsuba measures from the near-clip plane; distance from the eye =
  depth + near_clip / cos(angle to the optical axis). A miss is 0 in every AOV; here +inf.
- ids: Mitsuba's ``shape_index`` is 1 + the position in ``scene.shapes()`` in the scalar variants
  and the shape's registry id in the JIT (llvm, cuda) ones; both are mapped back to pyclray ids.
- planes: Mitsuba has no infinite plane. A disk of radius ``PLANE_DISK_SCALE`` times the scene's
  extent, centred at the eye's foot on the plane, stands in for it (a disk's error does not depend
  on its size; a rectangle's, two float32 triangles, does). Beyond the disk's edge, near the
  horizon, Mitsuba sees nothing where pyclray sees the plane: ``plane_beyond_disk`` marks those
  pixels so that comparisons can leave them out.
- normals: ``geo_normal`` is the geometric normal, outward and not flipped, as pyclray's.
"""
from __future__ import annotations

import numpy as np

from .scene import Scene

DEFAULT_VARIANT = "scalar_rgb"
PLANE_DISK_SCALE = 1e4
AOV_SPEC = "dd:depth,gn:geo_normal,sn:sh_normal,si:shape_index"


def import_mitsuba(variant: str = DEFAULT_VARIANT):
    """``mitsuba`` with the variant set (an ImportError says how to install it)."""
    try:
        import mitsuba as mi
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError("the Mitsuba cross-check needs `pip install mitsuba` (or pyclray[mitsuba])") from error
    if variant not in mi.variants():
        raise ValueError(f"Mitsuba variant {variant!r} is not available; available: {', '.join(mi.variants())}")
    mi.set_variant(variant)
    return mi


def extent(scene: Scene) -> float:
    """A length that bounds the scene as seen from the eye (at least 1)."""
    eye = np.array(scene.camera.eye)
    size = max(1.0, float(np.linalg.norm(np.subtract(scene.camera.target, eye))))
    for shape in scene.shapes:
        if shape.type == "sphere":
            size = max(size, float(np.linalg.norm(np.subtract(shape.center, eye))) + shape.radius)
        elif shape.type == "plane":
            n, h = shape.unit()
            size = max(size, abs(float(n @ eye + h)))
    return size


def clip_range(scene: Scene) -> tuple[float, float]:
    """(near_clip, far_clip): near small against every distance, far beyond every disk's edge."""
    size = extent(scene)
    near = 1e-6 * size
    for shape in scene.shapes:  # stay nearer than the nearest surface
        if shape.type == "sphere":
            gap = abs(float(np.linalg.norm(np.subtract(shape.center, scene.camera.eye))) - shape.radius)
        else:
            n, h = shape.unit()
            gap = abs(float(n @ np.array(scene.camera.eye) + h))
        if gap > 0:
            near = min(near, 1e-3 * gap)
    return near, 4 * PLANE_DISK_SCALE * size


def plane_disk(plane, scene: Scene):
    """(centre, frame columns, radius) of the disk standing in for a plane."""
    n, h = plane.unit()
    eye = np.array(scene.camera.eye)
    centre = eye - (n @ eye + h) * n  # the eye's foot on the plane
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(helper, n)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    return centre, (t1, t2, n), PLANE_DISK_SCALE * extent(scene)


def shape_key(index: int) -> str:
    return f"shape_{index:06d}"


def scene_dict(scene: Scene, variant: str = DEFAULT_VARIANT, aovs: str = AOV_SPEC) -> dict:
    """The Mitsuba scene description: pixel-centre perspective sensor, aov integrator, shapes."""
    mi = import_mitsuba(variant)
    camera, image = scene.camera, scene.image
    near, far = clip_range(scene)
    out = {
        "type": "scene",
        "integrator": {"type": "aov", "aovs": aovs},
        "sensor": {
            "type": "perspective",
            "fov": camera.fov,
            "fov_axis": camera.fov_axis,
            "near_clip": near,
            "far_clip": far,
            "to_world": mi.ScalarTransform4f().look_at(origin=list(camera.eye), target=list(camera.target), up=list(camera.up)),
            # one ray through each pixel centre
            "sampler": {"type": "stratified", "sample_count": 1, "jitter": False},
            "film": {
                "type": "hdrfilm",
                "width": image.width,
                "height": image.height,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
        },
    }
    for index, shape in enumerate(scene.shapes):
        if shape.type == "sphere":
            out[shape_key(index)] = {"type": "sphere", "center": list(shape.center), "radius": shape.radius}
        elif shape.type == "plane":
            centre, (t1, t2, n), radius = plane_disk(shape, scene)
            matrix = np.eye(4)
            matrix[:3, 0], matrix[:3, 1], matrix[:3, 2] = t1 * radius, t2 * radius, n * radius
            matrix[:3, 3] = centre
            out[shape_key(index)] = {"type": "disk", "to_world": mi.ScalarTransform4f(matrix.tolist())}
        else:  # pragma: no cover - every registered shape is handled above
            raise NotImplementedError(f"no Mitsuba counterpart for shape type {shape.type!r}")
    return out


def load(scene: Scene, variant: str = DEFAULT_VARIANT, aovs: str = AOV_SPEC):
    """(Mitsuba scene, {Mitsuba shape_index value: pyclray id})."""
    mi = import_mitsuba(variant)
    mi_scene = mi.load_dict(scene_dict(scene, variant, aovs), optimize=False)  # keeps shapes and order
    ids = {}
    for position, shape in enumerate(mi_scene.shapes()):
        pyclray_id = int(shape.id().removeprefix("shape_"))
        ids[shape_index_value(mi, shape, position)] = pyclray_id
    return mi_scene, ids


def shape_index_value(mi, shape, position: int) -> int:
    """What the aov integrator's shape_index holds for this shape."""
    if mi.variant().startswith("scalar"):
        return position + 1
    import drjit as dr

    pointer = mi.ShapePtr(shape)
    return int(dr.reinterpret_array(mi.UInt32, pointer)[0])


def axis_cosines(scene: Scene) -> np.ndarray:
    """cos of each pixel-centre ray's angle to the optical axis, (height, width) float64."""
    from .oracle import image_plane

    sx, sy = image_plane(scene)
    return 1.0 / np.sqrt(1.0 + sx[None, :] ** 2 + sy[:, None] ** 2)


def render(scene: Scene, variant: str = DEFAULT_VARIANT) -> dict:
    """Mitsuba's images in pyclray's conventions: depth (distance from the eye, inf on a miss),
    normal (geo_normal), sh_normal, id (-1 on a miss), all (height, width[, 3])."""
    import_mitsuba(variant)
    mi_scene, ids = load(scene, variant)
    image = np.array(mi_scene.integrator().render(mi_scene, mi_scene.sensors()[0]), dtype=np.float64)
    near, _ = clip_range(scene)
    index = np.rint(image[..., 7]).astype(np.int64)
    hit = index > 0
    lookup = np.vectorize(lambda k: ids.get(int(k), -1), otypes=[np.int32])
    out = {
        "depth": np.where(hit, image[..., 0] + near / axis_cosines(scene), np.inf),
        "normal": np.where(hit[..., None], image[..., 1:4], 0.0),
        "sh_normal": np.where(hit[..., None], image[..., 4:7], 0.0),
        "id": np.where(hit, lookup(np.where(hit, index, 0)) if hit.any() else -1, -1).astype(np.int32),
    }
    return out


def plane_beyond_disk(scene: Scene, origins, directions) -> np.ndarray:
    """True for rays that would meet a plane farther from its disk's centre than the disk reaches:
    there Mitsuba's stand-in disk ends and it sees nothing (or what lies behind)."""
    mask = np.zeros(directions.shape[:-1], bool)
    for shape in scene.shapes:
        if shape.type != "plane":
            continue
        centre, _, radius = plane_disk(shape, scene)
        t = shape.oracle_distance(origins.reshape(-1, 3), directions.reshape(-1, 3)).reshape(mask.shape)
        with np.errstate(invalid="ignore"):
            points = origins + np.where(np.isfinite(t), t, 0)[..., None] * directions
        far = np.isfinite(t) & (np.linalg.norm(points - centre, axis=-1) > radius * (1 - 1e-6))
        mask |= far
    return mask


# -- ray level: Mitsuba's own primary rays, and its intersection of arbitrary rays --------------
def pixel_positions(scene: Scene, rows, columns) -> tuple[np.ndarray, np.ndarray]:
    """The film positions in [0, 1]^2 of pixel centres, as the sensor's ``position_sample``:
    ((column + 0.5) / width, (row + 0.5) / height); row 0 is the top, as in pyclray's images
    (checked against the rendered image: these rays give the image's depth to a few ulps)."""
    width, height = scene.image.width, scene.image.height
    return (np.asarray(columns) + 0.5) / width, (np.asarray(rows) + 0.5) / height


def _as_rows(mi, value, count: int) -> np.ndarray:
    """A Mitsuba 3-vector (scalar) or vectorised 3-vector (JIT, component-major) as (count, 3) float64."""
    array = np.array(value, dtype=np.float64)
    if mi.variant().startswith("scalar"):
        return array.reshape(count, 3)
    return array.reshape(3, count).T


def primary_rays(mi_scene, scene: Scene, rows, columns) -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba's own float32 primary rays through these pixel centres: (origins, directions),
    each (n, 3) float64 holding the float32 values exactly. The origin sits on the near-clip
    plane (eye + near / cos * direction, rounded to float32); directions are unit in float32."""
    import mitsuba as mi

    sensor = mi_scene.sensors()[0]
    x, y = pixel_positions(scene, rows, columns)
    count = len(x)
    if mi.variant().startswith("scalar"):
        origins, directions = np.empty((count, 3)), np.empty((count, 3))
        for k in range(count):
            ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(float(x[k]), float(y[k])), mi.Point2f(0.5, 0.5))
            origins[k], directions[k] = np.array(ray.o, np.float64), np.array(ray.d, np.float64)
        return origins, directions
    position = mi.Point2f(mi.Float(x.astype(np.float32)), mi.Float(y.astype(np.float32)))
    ray, _ = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), position, mi.Point2f(0.5, 0.5))
    return _as_rows(mi, ray.o, count), _as_rows(mi, ray.d, count)


def intersect(mi_scene, ids: dict, origins, directions) -> dict:
    """Mitsuba's ``ray_intersect`` of these rays (float64 (n, 3) arrays, rounded to float32):
    depth (t along the ray, inf on a miss), normal (geo_normal, 0 on a miss), id (pyclray's, -1)."""
    import drjit as dr
    import mitsuba as mi

    origins = np.asarray(origins, np.float64).reshape(-1, 3)
    directions = np.asarray(directions, np.float64).reshape(-1, 3)
    count = len(origins)
    depth, normal, found = np.full(count, np.inf), np.zeros((count, 3)), np.full(count, -1, np.int32)
    if mi.variant().startswith("scalar"):
        for k in range(count):
            si = mi_scene.ray_intersect(mi.Ray3f(mi.Point3f(*origins[k]), mi.Vector3f(*directions[k])))
            if si.is_valid():
                depth[k] = si.t
                normal[k] = np.array(si.n, np.float64)
                found[k] = int(si.shape.id().removeprefix("shape_"))
        return {"depth": depth, "normal": normal, "id": found}
    if count == 0:
        return {"depth": depth, "normal": normal, "id": found}
    o, d = origins.T.astype(np.float32), directions.T.astype(np.float32)
    ray = mi.Ray3f(mi.Point3f(*(mi.Float(row) for row in o)), mi.Vector3f(*(mi.Float(row) for row in d)))
    si = mi_scene.ray_intersect(ray)
    valid = np.array(si.is_valid(), bool).reshape(count)
    index = np.array(dr.reinterpret_array(mi.UInt32, si.shape), np.int64).reshape(count)
    depth = np.where(valid, np.array(si.t, np.float64).reshape(count), np.inf)
    normal = np.where(valid[:, None], _as_rows(mi, si.n, count), 0.0)
    found = np.array([ids.get(int(k), -1) if v else -1 for k, v in zip(index, valid)], np.int32)
    return {"depth": depth, "normal": normal, "id": found}
