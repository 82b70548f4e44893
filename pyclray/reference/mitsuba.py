"""The same scene in Mitsuba 3, as the reference for checks and benchmarks.

Imported lazily, never on the render path (`import mitsuba` takes about a second). Conventions
that differ between pyclray and Mitsuba, and how they are mapped here:

- depth: Mitsuba measures from the near-clip plane; distance from the eye =
  depth + near_clip / cos(angle to the optical axis). A miss is 0 in every AOV; here +inf.
- ids: Mitsuba's ``shape_index`` is 1 + the position in ``scene.shapes()`` in the scalar variants
  and the shape's registry id in the JIT (llvm, cuda) ones; both are mapped back to pyclray ids.
- shapes: each shape module builds its counterpart (``Shape.mitsuba_shapes``: one or more Mitsuba
  shapes, all mapped back to its id; a cylinder's caps are two disks beside Mitsuba's open
  cylinder). Mitsuba has no infinite plane: a disk of radius ``PLANE_DISK_SCALE`` times the
  scene's extent, centred at the eye's foot on the plane, stands in for it. Beyond the disk's
  edge, near the horizon, Mitsuba sees nothing where pyclray sees the plane:
  ``beyond_counterparts`` marks those pixels so that comparisons can leave them out.
- normals: ``geo_normal`` is the geometric normal, outward and not flipped, as pyclray's.
- cameras: each camera model declares its Mitsuba sensor as data (``CameraModel.mitsuba_sensor``,
  model/cameras): the perspective camera's is Mitsuba's perspective sensor (a look-at camera's
  ``look_at`` with its fov and fov_axis; a camera from intrinsics with fx = fy: its frame as
  ``to_world`` and its principal point as ``principal_point_offset_x/_y``). A model Mitsuba has no
  sensor for (or a camera of fx != fy) is a SceneError.
"""
from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from ..model.cameras import LookAt
from ..model.errors import SceneError
from ..model.lights import PointLight
from ..model.scene import Scene
from ..model.shapes.plane import DISK_SCALE as PLANE_DISK_SCALE

DEFAULT_VARIANT = "scalar_rgb"
AOV_SPEC = "dd:depth,gn:geo_normal,sn:sh_normal,si:shape_index,pi:prim_index"


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


def clip_range(scene: Scene) -> tuple[float, float]:
    """(near_clip, far_clip): near small against every distance, far beyond every stand-in's edge."""
    size = scene.extent()
    near = 1e-6 * size
    eye = np.array(scene.camera.eye, np.float64)[None]
    for shape in scene.shapes:  # stay nearer than the nearest surface
        gap = float(shape.surface_distance(eye)[0])
        if gap > 0:
            near = min(near, 1e-3 * gap)
    return near, 4 * PLANE_DISK_SCALE * size


def shape_key(index: int, part: int = 0) -> str:
    """The Mitsuba id of part ``part`` of pyclray shape ``index`` (a cylinder's caps are parts)."""
    return f"shape_{index:06d}" if part == 0 else f"shape_{index:06d}_{part}"


def pyclray_id(mitsuba_id: str) -> int:
    """The pyclray id a Mitsuba shape id (shape_key) maps back to."""
    return int(mitsuba_id.removeprefix("shape_").split("_")[0])


def _is_mesh(value) -> bool:
    return isinstance(value, dict) and value.get("type") == "mesh" and isinstance(value.get("vertex_positions"), np.ndarray)


def mitsuba_mesh(mi, value: dict, name: str):
    """An mi.Mesh of a dict of type 'mesh' with numpy arrays vertex_positions (V, 3) and faces (F, 3)
    (Mitsuba's float32 positions; face normals, or vertex_normals (V, 3) where given; its id is name)
    and its 'bsdf', if any, as a dict."""
    positions, faces = value["vertex_positions"], np.asarray(value["faces"])
    props = mi.Properties()
    if "bsdf" in value:
        props["bsdf"] = mi.load_dict(value["bsdf"])
    normals = value.get("vertex_normals")  # a smooth mesh's (V, 3): Mitsuba interpolates them (sh_frame)
    mesh = mi.Mesh(name, len(positions), len(faces), props=props, has_vertex_normals=normals is not None,
                   has_vertex_texcoords=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = np.ascontiguousarray(positions, np.float32).reshape(-1)
    params["faces"] = np.ascontiguousarray(faces, np.uint32).reshape(-1)
    if normals is not None:
        params["vertex_normals"] = np.ascontiguousarray(normals, np.float32).reshape(-1)
    params.update()
    return mesh


def load_dict(mi, description: dict):
    """mi.load_dict of a scene_dict (its shapes kept in order), the meshes made mi.Mesh objects there:
    after the caller has added what it needs to their dicts (a BSDF)."""
    ready = {key: mitsuba_mesh(mi, value, key) if _is_mesh(value) else value for key, value in description.items()}
    return mi.load_dict(ready, optimize=False)


def mitsuba_values(mi, value):
    """A plain scene dict's values for Mitsuba: 4x4 numpy matrices and LookAt become ScalarTransform4f;
    a mesh's dict stays a dict (load_dict makes it an mi.Mesh)."""
    if _is_mesh(value):
        return value
    if isinstance(value, LookAt):
        from ..model.mitsuba_xml.properties import look_at

        value = look_at(*(np.array(v, np.float64) for v in value))
    if isinstance(value, np.ndarray) and value.shape == (4, 4):
        # as Mitsuba's XML parser builds a transform: the matrix and its inverse transpose in float64,
        # each rounded once to float32 (a Transform4f of the matrix alone inverts it in float32)
        return mi.ScalarTransform4f(mi.ScalarMatrix4f(value.tolist()), mi.ScalarMatrix4f(np.linalg.inv(value).T.tolist()))
    if isinstance(value, dict):
        return {k: mitsuba_values(mi, v) for k, v in value.items()}
    return value


@contextmanager
def quiet_interrupts(mi):
    """Mitsuba's render loops answer Ctrl-C by winding down with a WARN line on stderr; pyclray's
    commands end quietly instead (status 130): Mitsuba logs only errors while it renders."""
    previous = mi.log_level()
    mi.set_log_level(mi.LogLevel.Error)
    try:
        yield
    finally:
        mi.set_log_level(previous)


def sensor_of(scene: Scene) -> dict:
    """The sensor plugin of the scene's camera at its image size (its model's mitsuba_sensor) as plain
    values: its type, its properties (a perspective sensor's fov, fov_axis, principal point offsets)
    and to_world (a 4x4 numpy matrix or a LookAt); a SceneError naming the file and the camera's key
    where Mitsuba has no such camera (a perspective camera of fx != fy). Needs no Mitsuba."""
    try:
        sensor = scene.camera.mitsuba_sensor(scene.image.width, scene.image.height)
    except SceneError as error:
        raise error.within(file=scene.source, table="[camera]") from None
    return {"type": sensor.plugin, **sensor.properties,
            "to_world": sensor.to_world if sensor.look_at is None else sensor.look_at}


def mitsuba_dict(scene: Scene, aovs: str = AOV_SPEC, key=shape_key) -> dict:
    """The Mitsuba scene description ``pyclray check`` builds, as plain values (no Mitsuba needed):
    a perspective sensor with one unjittered ray through each pixel centre, the aov integrator
    (``aovs``), and each shape's counterpart (``Shape.mitsuba_shapes``) under the id key(index, part)
    (default shape_000003, shape_000003_1, ...: how the check maps Mitsuba's shapes back to ids).
    A to_world is a 4x4 float64 numpy matrix or a LookAt. ``scene_dict`` gives it to Mitsuba,
    ``pyclray.reference.mitsuba_export`` writes it as XML."""
    image = scene.image
    near, far = clip_range(scene)
    out = {
        "type": "scene",
        "integrator": {"type": "aov", "aovs": aovs},
        "sensor": {
            **sensor_of(scene),
            "near_clip": near,
            "far_clip": far,
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
        for part, counterpart in enumerate(shape.mitsuba_shapes(scene)):
            out[key(index, part)] = counterpart
    return out


def scene_dict(scene: Scene, variant: str = DEFAULT_VARIANT, aovs: str = AOV_SPEC) -> dict:
    """mitsuba_dict with Mitsuba's own values (ScalarTransform4f), ready for mi.load_dict."""
    return mitsuba_values(import_mitsuba(variant), mitsuba_dict(scene, aovs))


def emitter_dict(light) -> dict:
    """A pyclray light as a Mitsuba emitter: point (intensity) or directional (irradiance)."""
    if isinstance(light, PointLight):
        return {"type": "point", "position": list(light.position),
                "intensity": {"type": "rgb", "value": list(light.intensity)}}
    return {"type": "directional", "direction": list(light.direction),
            "irradiance": {"type": "rgb", "value": list(light.irradiance)}}


def load(scene: Scene, variant: str = DEFAULT_VARIANT, aovs: str = AOV_SPEC):
    """(Mitsuba scene, {Mitsuba shape_index value: pyclray id})."""
    mi = import_mitsuba(variant)
    mi_scene = load_dict(mi, scene_dict(scene, variant, aovs))  # keeps shapes and order
    ids = {}
    for position, shape in enumerate(mi_scene.shapes()):
        ids[shape_index_value(mi, shape, position)] = pyclray_id(shape.id())
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
    sx, sy = scene.camera.plane_coordinates(scene.image.width, scene.image.height)
    return 1.0 / np.sqrt(1.0 + sx[None, :] ** 2 + sy[:, None] ** 2)


def render(scene: Scene, variant: str = DEFAULT_VARIANT) -> dict:
    """Mitsuba's images in pyclray's conventions: depth (distance from the eye, inf on a miss),
    normal (geo_normal), sh_normal, id (-1 on a miss), primitive (prim_index, -1 on a miss), all
    (height, width[, 3]).

    The JIT variants render with the aov integrator. The scalar ones cast the same rays one by one (the
    sensor's sample_ray at each pixel centre, then ray_intersect: what the aov integrator does for each
    sample, as the ray-level check measures): Mitsuba 3.9.1's scalar aov integrator takes time in
    proportion to the number of shapes per sample, far more than the same rays cast from here
    (docs/benchmarks.md, "Why the engine does what it does")."""
    mi = import_mitsuba(variant)
    near, _ = clip_range(scene)
    if mi.variant().startswith("scalar"):
        depth, normal, sh_normal, found, primitive = _cast_pixels(mi, scene)
        hit = found >= 0
        return {"depth": np.where(hit, depth + scene.camera.mitsuba_ray_starts(scene.image.width, scene.image.height, near), np.inf), "normal": normal,
                "sh_normal": sh_normal, "id": found, "primitive": primitive}
    mi_scene, ids = load(scene, variant)
    with quiet_interrupts(mi):
        image = np.array(mi_scene.integrator().render(mi_scene, mi_scene.sensors()[0]), dtype=np.float64)
    index = np.rint(image[..., 7]).astype(np.int64)
    hit = index > 0
    lookup = np.vectorize(lambda k: ids.get(int(k), -1), otypes=[np.int32])
    out = {
        "depth": np.where(hit, image[..., 0] + scene.camera.mitsuba_ray_starts(scene.image.width, scene.image.height, near), np.inf),
        "normal": np.where(hit[..., None], image[..., 1:4], 0.0),
        "sh_normal": np.where(hit[..., None], image[..., 4:7], 0.0),
        "id": np.where(hit, lookup(np.where(hit, index, 0)) if hit.any() else -1, -1).astype(np.int32),
        "primitive": np.where(hit, np.rint(image[..., 8]), -1).astype(np.int32),  # prim_index
    }
    return out


def _cast_pixels(mi, scene: Scene):
    """(t from the near-clip plane, geo_normal, sh_normal, pyclray id, prim_index; -1 on a miss) of
    Mitsuba's primary ray of every pixel centre (scalar variants), with a progress bar over the rows."""
    from ..io.progress import progress

    mi_scene = load_dict(mi, scene_dict(scene, mi.variant()))
    shapes = list(mi_scene.shapes())  # kept alive: the lookup is by the Python objects' identity
    lookup = {id(shape): pyclray_id(shape.id()) for shape in shapes}
    sensor = mi_scene.sensors()[0]
    width, height = scene.image.width, scene.image.height
    depth, found, primitive = np.zeros((height, width)), np.full((height, width), -1, np.int32), np.full((height, width), -1, np.int32)
    normal, sh_normal = np.zeros((height, width, 3)), np.zeros((height, width, 3))
    half = mi.Point2f(0.5, 0.5)
    xs, ys = pixel_positions(scene, np.arange(height), np.arange(width))
    xs, ys = xs.tolist(), ys.tolist()
    with progress(height, desc=f"Mitsuba {mi.variant()}", unit="row") as bar:
        for j in range(height):
            y = ys[j]
            for i in range(width):
                ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(xs[i], y), half)
                si = mi_scene.ray_intersect(ray)
                if si.is_valid():
                    depth[j, i], found[j, i], primitive[j, i] = si.t, lookup[id(si.shape)], si.prim_index
                    normal[j, i], sh_normal[j, i] = tuple(si.n), tuple(si.sh_frame.n)
            bar.update(1)
    return depth, normal, sh_normal, found, primitive


def beyond_counterparts(scene: Scene, origins, directions) -> np.ndarray:
    """True for rays that would meet a shape where its Mitsuba counterpart does not reach (the
    plane beyond its stand-in disk's edge): there Mitsuba sees nothing (or what lies behind)."""
    from ..model.shapes.base import Shape

    origins = np.broadcast_to(np.asarray(origins, np.float64), np.shape(directions))
    mask = np.zeros(np.shape(directions)[:-1], bool)
    # only a counterpart that may end before its shape does (mitsuba_covers is its own) is looked at
    for shape in (s for s in scene.shapes if type(s).mitsuba_covers is not Shape.mitsuba_covers):
        t = shape.oracle_distance(origins.reshape(-1, 3), np.reshape(directions, (-1, 3))).reshape(mask.shape)
        hit = np.isfinite(t)
        if hit.any():
            points = origins[hit] + t[hit][:, None] * np.asarray(directions)[hit]
            mask[hit] |= ~shape.mitsuba_covers(scene, points)
    return mask


# -- ray level: Mitsuba's own primary rays, and its intersection of arbitrary rays --------------
def pixel_positions(scene: Scene, rows, columns) -> tuple[np.ndarray, np.ndarray]:
    """The film positions in [0, 1]^2 of pixel centres, as Mitsuba's sampling integrator computes
    the sensor's ``position_sample`` (render_sample: fmadd(pixel + 0.5, 1 / size, 0) in float32,
    1 / size itself a float32): ((column + 0.5) / width, (row + 0.5) / height) rounded as Mitsuba
    rounds them (pixel + 0.5 times the float32 1 / size is exact in float64, then rounded once);
    row 0 is the top, as in pyclray's images."""
    width, height = scene.image.width, scene.image.height
    x = (np.asarray(columns) + 0.5) * np.float64(np.float32(1.0) / np.float32(width))
    y = (np.asarray(rows) + 0.5) * np.float64(np.float32(1.0) / np.float32(height))
    return x.astype(np.float32).astype(np.float64), y.astype(np.float32).astype(np.float64)


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
                found[k] = pyclray_id(si.shape.id())
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
