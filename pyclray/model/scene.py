"""The scene: a camera, an image size, shapes, lights, shading and an optional animation (frozen,
validated), and the checks a render makes of it."""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace
from functools import cached_property
from numbers import Real

import numpy as np

from .animation import Animation, _find_places, scene_at, tracks_in
from .frames import CheckedShapes, FrameShapes, FrameWork
from .camera import MAX_PLANE_REACH, MAX_PRINCIPAL_POINT, MIN_PIXEL_TAN, Camera, Image
from .cameras import CAMERAS, CameraModel
from .errors import PyclrayWarning, RequestError, SceneError
from .lidar import Lidar
from .lights import Shading, check_lights
from .shapes import REGISTRY
from .shapes.base import Shape, check_label

# The kernels square lengths in the camera's frame (|centre - eye|^2, r^2, b^2) and add a few such
# squares: every length must stay below the square root of the precision's largest float, with a
# factor 4 of room for those sums. fp32: 4.6e18 scene units, fp64: 3.4e153.
MAX_LENGTH = {precision: math.sqrt(float(np.finfo(real).max)) / 4 for precision, real in (("fp32", np.float32), ("fp64", np.float64))}


@dataclass(frozen=True)
class Scene:
    camera: Camera
    image: Image = field(default_factory=Image)
    shapes: tuple[Shape, ...] = ()
    source: str | None = None  # the file it was read from, for messages
    lights: tuple = ()  # PointLight, DirectionalLight (pyclray.model.lights); none: the headlight
    shading: Shading = field(default_factory=Shading)
    animation: Animation | None = None  # keyframes (pyclray/model/animation.py); None: a static scene
    lidars: tuple = ()  # pyclray.Lidar sensors (pyclray/model/lidar/), each named ("lidar<index>" by default)
    # the [[shapes]] table of each shape in the file (for messages) where a table made several shapes
    # (a mesh file's objects, split = true); None: shape k is table k
    tables: tuple[int, ...] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "lights", check_lights(self.lights, self.source))
        if not isinstance(self.shading, Shading):
            raise SceneError(f"expected a pyclray.Shading, got {type(self.shading).__name__}", table="[shading]", file=self.source)
        # the shapes, each looked at once: a CheckedShapes (this scene's camera replaced, an animation's
        # frame made from a checked tuple by dataclasses.replace of a few shapes, which checks them) or
        # an animation's FrameShapes needs no look
        if not isinstance(self.shapes, (CheckedShapes, FrameShapes)):
            shapes = tuple(self.shapes)
            for index, shape in enumerate(shapes):
                if not isinstance(shape, Shape):
                    raise SceneError(
                        f"expected a shape ({', '.join(REGISTRY)}), got {type(shape).__name__}",
                        table=f"[[shapes]] #{index}",
                        file=self.source,
                    )
                if shape.label is not None:  # (a scene file's labels are checked as they are read)
                    try:
                        check_label(shape.label)
                    except SceneError as error:
                        raise error.within(file=self.source, table=f"[[shapes]] #{index} ({shape.type})") from None
            object.__setattr__(self, "shapes", CheckedShapes(shapes))
        if not isinstance(self.camera, CameraModel):
            models = ", ".join(f"pyclray.{cls.__name__}" for cls in CAMERAS.values())  # pyclray.Camera first
            raise SceneError(f"expected a {models}, got {type(self.camera).__name__}", table="[camera]",
                             file=self.source)
        # K is in pixels of this scene's image (a camera from intrinsics, a fisheye)
        if getattr(self.camera, "K", None) is not None and self.camera.size is None:
            object.__setattr__(self, "camera", replace(self.camera, size=(self.image.width, self.image.height)))
        if isinstance(self.camera, Camera):  # the pinhole's image plane (the lens models' rays are their tables)
            check_image_plane(self.camera, self.image, self.source)
        object.__setattr__(self, "lidars", check_lidars(self.lidars, self.source))
        if self.animation is not None:
            self.animation.bind(self)  # known targets and keys, and every frame's scene valid

    # What an animated scene keeps for its frames (found once, dropped with the scene; not pickled)
    @cached_property
    def animation_places(self) -> dict:
        """Target name -> where things of that name sit (pyclray.model.animation)."""
        return _find_places(self)

    @cached_property
    def frame_work(self) -> FrameWork:
        """The frames' working copies of the animated collections (pyclray.model.frames.FrameWork)."""
        return FrameWork()

    @cached_property
    def still_shapes(self) -> tuple[tuple[int, ...], CheckedShapes]:
        """(the indices of the shapes its animation moves, the other shapes as one kept tuple): a
        sweeping scan prepares the still shapes once (engine/queries/scan.py)."""
        moving = tuple(sorted({index for index, _ in tracks_in(self, "shapes")}))
        skip = set(moving)
        return moving, CheckedShapes(shape for index, shape in enumerate(self.shapes) if index not in skip)

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k not in ("animation_places", "frame_work", "still_shapes")}

    def at(self, t: float) -> "Scene":
        """The static scene at time t (seconds, >= 0) of its animation; the scene itself if it has
        none. Frame k is at k / fps; past the last key (and the duration) every track holds its
        last value. A negative or non-finite t is a RequestError."""
        return scene_at(self, checked_time(t))

    def with_size(self, width: int, height: int) -> "Scene":
        """The scene at another image size. A camera from intrinsics keeps its K and size, so its K
        scales with the image (Camera.intrinsics): the same view at another resolution."""
        return replace(self, image=Image(width, height))

    def extent(self) -> float:
        """A length that bounds the scene as seen from the eye (at least 1): the distance to the
        target and the farthest reach of any shape (Mitsuba's clip range and plane stand-in)."""
        eye = np.array(self.camera.eye)
        target = getattr(self.camera, "target", None)
        size = max(1.0, float(np.linalg.norm(np.subtract(target, eye)))) if target is not None else 1.0
        for shape in self.shapes:
            size = max(size, shape.extent_from(eye))
        return size

    def table_of(self, index: int) -> int:
        """The [[shapes]] table of the file that shape `index` comes from (itself but after a table
        that made several shapes)."""
        if self.tables is not None and len(self.tables) == len(self.shapes):
            return self.tables[index]
        return index

    def shape_types(self) -> tuple[str, ...]:
        """The shape types present, in the registry's order."""
        present = {shape.type for shape in self.shapes}
        return tuple(t for t in REGISTRY if t in present)


def check_lidars(lidars, source=None) -> tuple:
    """The scene's sensors as a tuple of Lidars, each named (an unnamed one "lidar<index>"), the
    names unique; a SceneError naming the sensor otherwise."""
    if isinstance(lidars, Lidar):
        lidars = (lidars,)
    if isinstance(lidars, (str, bytes, dict)) or not hasattr(lidars, "__iter__"):
        raise SceneError(f"expected a tuple of pyclray.Lidar, got {type(lidars).__name__}", table="[[lidars]]", file=source)
    named, seen = [], {}
    for index, lidar in enumerate(lidars):
        if not isinstance(lidar, Lidar):
            raise SceneError(f"expected a pyclray.Lidar, got {type(lidar).__name__}", table=f"[[lidars]] #{index}",
                             file=source)
        if lidar.name is None:
            lidar = replace(lidar, name=f"lidar{index}")
        if lidar.name in seen:
            raise SceneError(f"the name {lidar.name!r} is already used by [[lidars]] #{seen[lidar.name]}",
                             table=f"[[lidars]] #{index}", key="name", file=source)
        seen[lidar.name] = index
        named.append(lidar)
    return tuple(named)


def checked_time(t) -> float:
    """t if it is a time in seconds >= 0 (Scene.at, render_animation's frames), else a RequestError."""
    if isinstance(t, bool) or not isinstance(t, Real) or not 0 <= t < math.inf:
        raise RequestError(f"t: expected a time in seconds >= 0 (frame k of an animation is at k / fps; "
                           f"past the last key every track holds its last value), got {t!r}")
    return t


def check_image_plane(camera: Camera, image: Image, source=None) -> None:
    """Refuse a camera whose pixel-centre rays at this image size are not distinct in float32 (a
    too small fov, too long focal lengths) or reach too near 90 degrees off the optical axis (too
    short focal lengths for where the principal point sits): a SceneError naming the key."""
    width, height = image.width, image.height
    plane = camera.image_plane(width, height)
    key = "fov" if camera.K is None else "intrinsics"
    if min(plane.tan_x / width, plane.tan_y / height) < MIN_PIXEL_TAN:
        what = f"fov {camera.fov!r} is too small" if camera.K is None else "the focal lengths are too long"
        raise SceneError(f"{what}: neighbouring pixels' rays are not distinct in float32",
                         table="[camera]", key=key, file=source)
    if camera.K is not None:
        if max(abs(plane.cx), abs(plane.cy)) > MAX_PRINCIPAL_POINT:
            raise SceneError(f"the principal point ({plane.cx:g}, {plane.cy:g}) lies more than {MAX_PRINCIPAL_POINT:.0f} "
                             f"pixels from the {width}x{height} image", table="[camera]", key=key, file=source)
        reach_x = plane.tan_x * max(abs(2 * plane.cx - 1), abs(2 * plane.cx - 2 * width + 1)) / width
        reach_y = plane.tan_y * max(abs(2 * plane.cy - 1), abs(2 * plane.cy - 2 * height + 1)) / height
        if not max(reach_x, reach_y) <= MAX_PLANE_REACH:
            raise SceneError(f"the focal lengths are too short: the {width}x{height} image reaches to within "
                             f"{1 / max(reach_x, reach_y):.2g} radians of 90 degrees off the optical axis",
                             table="[camera]", key=key, file=source)


# The kernels keep a shape as 8 x its index in its type's array + its type (the BVH's refs, the
# winner key of a packet's lanes) in a 32-bit int.
MAX_SHAPES = (2**31 - 1) // 16


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
                file=scene.source, table=f"[[shapes]] #{scene.table_of(index)} ({shape.type})", key=key,
            )
