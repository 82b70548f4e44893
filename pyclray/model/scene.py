"""The scene model (frozen, validated dataclasses) and the TOML loader."""
from __future__ import annotations

import math
import os
import tomllib
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .animation import Animation, scene_at
from .errors import PyclrayWarning, RequestError, SceneError, integer, no_unknown_keys, norm3, number, typed_table, vector3
from .lighting import Shading, check_lights, lights_from_list
from .shapes import REGISTRY
from .shapes.base import Shape

# Below this sine of the angle between up and the view direction the image's roll is decided by
# rounding noise: a degenerate camera, reported as an error rather than rendered.
MIN_UP_SINE = 1e-6
# The smallest half-width of a pixel on the image plane (tan(fov/2) / size): below it the rays of
# neighbouring pixels are no longer distinct in float32, so such a fov is an error.
MIN_PIXEL_TAN = 1e-30
MAX_IMAGE_SIDE = 1 << 16
# The kernels square lengths in the camera's frame (|centre - eye|^2, r^2, b^2) and add a few such
# squares: every length must stay below the square root of the precision's largest float, with a
# factor 4 of room for those sums. fp32: 4.6e18 scene units, fp64: 3.4e153.
MAX_LENGTH = {precision: math.sqrt(float(np.finfo(real).max)) / 4 for precision, real in (("fp32", np.float32), ("fp64", np.float64))}


@dataclass(frozen=True)
class Camera:
    """A perspective camera looking from ``eye`` at ``target``; ``fov`` in degrees along ``fov_axis``."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov: float = 45.0
    fov_axis: str = "x"

    def __post_init__(self):
        object.__setattr__(self, "eye", vector3("eye", self.eye))
        object.__setattr__(self, "target", vector3("target", self.target))
        object.__setattr__(self, "up", vector3("up", self.up))
        fov = number("fov", self.fov)
        if not 0 < fov < 180:
            raise SceneError(f"expected 0 < fov < 180 (degrees), got {fov!r}", key="fov")
        object.__setattr__(self, "fov", fov)
        if self.fov_axis not in ("x", "y"):
            raise SceneError(f'expected "x" or "y", got {self.fov_axis!r}', key="fov_axis")
        self.basis()  # a degenerate basis is an error now, not a NaN image later

    def basis(self) -> np.ndarray:
        """Rows u (left), v (up), w (forward): the world_from_camera columns, in float64."""
        with np.errstate(over="ignore"):
            forward = np.subtract(self.target, self.eye)
        length = norm3(forward)
        if not math.isfinite(length):
            raise SceneError("expected target - eye within the range of float64, got an overflow", key="target")
        if length == 0:
            raise SceneError("expected target != eye (the view direction is undefined)", key="target")
        w = forward / length
        up_length = norm3(self.up)
        if up_length == 0:
            raise SceneError("expected a non-zero up vector, got [0, 0, 0]", key="up")
        left = np.cross(np.array(self.up) / up_length, w)
        sine = norm3(left)
        if sine < MIN_UP_SINE:
            raise SceneError(
                f"expected up not parallel to the view direction (target - eye); the sine of "
                f"their angle is {sine:.3g}, below {MIN_UP_SINE:g}",
                key="up",
            )
        u = left / sine
        v = np.cross(w, u)
        return np.stack([u, v, w])

    def tangents(self, width: int, height: int) -> tuple[float, float]:
        """tan of the half opening angles along x and y (square pixels)."""
        t = math.tan(math.radians(self.fov) / 2)
        if self.fov_axis == "x":
            return t, t * height / width
        return t * width / height, t


@dataclass(frozen=True)
class Image:
    width: int = 512
    height: int = 512

    def __post_init__(self):
        integer("width", self.width, minimum=1, maximum=MAX_IMAGE_SIDE)
        integer("height", self.height, minimum=1, maximum=MAX_IMAGE_SIDE)


@dataclass(frozen=True)
class Scene:
    camera: Camera
    image: Image = field(default_factory=Image)
    shapes: tuple[Shape, ...] = ()
    source: str | None = None  # the file it was read from, for messages
    lights: tuple = ()  # PointLight, DirectionalLight (pyclray.lighting); none: the headlight
    shading: Shading = field(default_factory=Shading)
    animation: Animation | None = None  # keyframes (pyclray/animation.py); None: a static scene

    def __post_init__(self):
        object.__setattr__(self, "shapes", tuple(self.shapes))
        object.__setattr__(self, "lights", check_lights(self.lights, self.source))
        if not isinstance(self.shading, Shading):
            raise SceneError(f"expected a pyclray.Shading, got {type(self.shading).__name__}", table="[shading]", file=self.source)
        for index, shape in enumerate(self.shapes):
            if not isinstance(shape, Shape):
                raise SceneError(
                    f"expected a shape ({', '.join(REGISTRY)}), got {type(shape).__name__}",
                    table=f"[[shapes]] #{index}",
                    file=self.source,
                )
        tan_x, tan_y = self.camera.tangents(self.image.width, self.image.height)
        if min(tan_x / self.image.width, tan_y / self.image.height) < MIN_PIXEL_TAN:
            raise SceneError(
                f"fov {self.camera.fov!r} is too small: neighbouring pixels' rays are not distinct "
                "in float32",
                table="[camera]",
                key="fov",
                file=self.source,
            )
        if self.animation is not None:
            self.animation.bind(self)  # known targets and keys, and every frame's scene valid

    def at(self, t: float) -> "Scene":
        """The static scene at time t (seconds) of its animation; the scene itself if it has none."""
        return scene_at(self, t)

    def with_size(self, width: int, height: int) -> "Scene":
        return replace(self, image=Image(width, height))

    def shape_types(self) -> tuple[str, ...]:
        """The shape types present, in the registry's order."""
        present = {shape.type for shape in self.shapes}
        return tuple(t for t in REGISTRY if t in present)


# The kernels keep a shape as 8 x its index in its type's array + its type (the BVH's refs, the
# winner key of a packet's lanes) in a 32-bit int.
MAX_SHAPES = (2**31 - 1) // 8


def check_shape_count(scene: Scene) -> None:
    """Refuse more shapes than the kernels can index (a SceneError)."""
    if len(scene.shapes) > MAX_SHAPES:
        where = f"{scene.source}: [[shapes]]" if scene.source else "shapes"
        raise SceneError(f"{where}: {len(scene.shapes)} shapes; pyclray renders at most {MAX_SHAPES} "
                         "(the kernels index a shape by 8 x its position + its type in 32 bits)")


def check_renderable(scene: Scene, precision: str) -> None:
    """Refuse geometry beyond the precision's range (a SceneError naming the shape and the key, and
    whether fp64 would do) rather than render it as silent misses; warn about a scene with no
    shapes (every pixel a miss)."""
    if not scene.shapes:
        where = f"{scene.source}: no [[shapes]]" if scene.source else "the scene has no shapes"
        warnings.warn(f"{where}: every pixel is a miss", PyclrayWarning, stacklevel=3)
    check_shape_count(scene)
    limit = MAX_LENGTH[precision]
    for index, shape in enumerate(scene.shapes):
        for key, length in shape.lengths(scene.camera.eye).items():
            if length <= limit:
                continue
            if length <= MAX_LENGTH["fp64"]:
                remedy = "precision fp64 is needed (--precision fp64)"
            else:
                remedy = "beyond fp64 too: move it nearer the camera"
            raise SceneError(
                f"{length:.3g} from the eye in the camera's frame, beyond what {precision} can render "
                f"(at most {limit:.2g}: the kernel squares lengths); {remedy}",
                file=scene.source, table=f"[[shapes]] #{index} ({shape.type})", key=key,
            )


def as_scene(value) -> Scene:
    """A Scene, or the path of a scene file (loaded); anything else is a RequestError."""
    if isinstance(value, Scene):
        return value
    if isinstance(value, (str, os.PathLike)):
        return load_scene(value)
    raise RequestError(f"scene: expected a pyclray.Scene or the path of a scene file, got {type(value).__name__}")


def _table(data: dict, key: str, *, required: bool) -> dict:
    if key not in data:
        if required:
            raise SceneError(f"missing required table [{key}]")
        return {}
    if not isinstance(data[key], dict):
        raise SceneError(f"expected a table [{key}], got {type(data[key]).__name__}", key=key)
    return data[key]


def scene_from_dict(data: dict, source: str | None = None) -> Scene:
    """A Scene from the parsed contents of a scene file (see scene-format.md)."""
    if not isinstance(data, dict):
        raise SceneError(f"expected a table of [camera], [image] and [[shapes]], got {type(data).__name__}", file=source)
    try:
        no_unknown_keys(data, ("camera", "image", "shapes", "lights", "shading", "animation"), required=())
    except SceneError as error:
        raise error.within(file=source, table="(top level)") from None
    try:
        table = _table(data, "camera", required=True)
        no_unknown_keys(table, ("eye", "target", "up", "fov", "fov_axis"), required=("eye", "target", "fov"))
        camera = Camera(**table)
    except SceneError as error:
        raise error.within(file=source, table="[camera]") from None
    try:
        table = _table(data, "image", required=False)
        no_unknown_keys(table, ("width", "height"))
        image = Image(**table)
    except SceneError as error:
        raise error.within(file=source, table="[image]") from None

    entries = data.get("shapes", [])
    if not isinstance(entries, list):
        raise SceneError("expected an array of tables [[shapes]]", key="shapes", file=source)
    shapes = []
    for index, entry in enumerate(entries):
        where = f"[[shapes]] #{index}"
        try:
            kind = typed_table(entry, REGISTRY, "shape")
            where = f"[[shapes]] #{index} ({kind})"
            shapes.append(REGISTRY[kind].from_table(entry, index))
        except SceneError as error:
            raise error.within(file=source, table=where) from None
    lights = lights_from_list(data.get("lights", []), source)
    try:
        shading = Shading.from_table(_table(data, "shading", required=False))
    except SceneError as error:
        raise error.within(file=source, table="[shading]") from None
    try:
        animation = Animation.from_table(data["animation"]) if "animation" in data else None
    except SceneError as error:
        raise error.within(file=source, table="[animation]") from None
    return Scene(camera, image, tuple(shapes), source, lights, shading, animation=animation)


def load_scene(path) -> Scene:
    """Read and validate a scene file; raises SceneError naming the file, table and key."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as error:
        raise SceneError(f"cannot read the scene file: {(error.strerror or str(error)).lower()}", file=path) from None
    try:
        # a UTF-8 byte order mark (as some editors write) is not part of the text
        data = tomllib.loads(raw.removeprefix(b"\xef\xbb\xbf").decode("utf-8"))
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"not valid TOML: {error}", file=path) from None
    except UnicodeDecodeError as error:
        raise SceneError(f"not valid UTF-8 text: {error}", file=path) from None
    except RecursionError:
        raise SceneError("not a scene: arrays or tables nested too deeply", file=path) from None
    return scene_from_dict(data, source=str(path))
