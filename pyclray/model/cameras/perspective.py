"""The perspective camera (pyclray.Camera): a pinhole view from an eye toward a target, or from a
pose and pinhole intrinsics; the same rays as Mitsuba 3's perspective sensor."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..errors import SceneError, _shown, integer, no_unknown_keys, norm3, number, text, vector3
from ..layout import Struct, layout
from . import lens
from .base import MAX_IMAGE_SIDE, CameraModel, LookAt, MitsubaSensor

# Below this sine of the angle between up and the view direction the image's roll is decided by
# rounding noise: a degenerate camera, reported as an error rather than rendered.
MIN_UP_SINE = 1e-6
# The smallest half-width of a pixel on the image plane (tan(fov/2) / size): below it the rays of
# neighbouring pixels are no longer distinct in float32, so such a fov is an error.
MIN_PIXEL_TAN = 1e-30
# A pose's rotation R must be orthonormal within this (every entry of R^T R - I), with det R > 0:
# poses written with 7 significant digits pass. Within float64 rounding (RIGID_EXACT) R is used as
# given; otherwise the camera holds its nearest rotation (the polar factor of R), so that its space
# is orthonormal as the kernels assume.
RIGID_TOLERANCE = 1e-6
RIGID_EXACT = 1e-12
# The image plane's reach (the largest |x / z| or |y / z| of a pixel centre's ray), as far as a
# look-at camera's fov < 180 reaches in float64 (tan(90 - 1.4e-14 degrees) = 4e15): beyond it the
# kernels' squares of the ray's coordinates are not safely finite in float32.
MAX_PLANE_REACH = 1e16
# The principal point at most this many pixels from the image's corner (twice it is an int32 in the
# kernel's camera struct, less the pixel's index).
MAX_PRINCIPAL_POINT = 2.0**28

LOOK_AT_KEYS = ("target", "up", "fov", "fov_axis")  # the fields of each kind of camera
INTRINSICS_KEYS = ("K", "rotation", "size", "distortion")
TABLE_LOOK_AT_KEYS = ("eye", "target", "up", "fov", "fov_axis")  # the [camera] table's keys of each kind
TABLE_INTRINSICS_KEYS = ("intrinsics", "pose")
TABLE_INTRINSICS_OPTIONS = ("pixel_origin", "distortion")  # besides intrinsics and pose
# OpenCV's distortion vectors: k1, k2, p1, p2[, k3[, k4, k5, k6]] (its 12- and 14-coefficient thin
# prism and tilted models are not this model's)
DISTORTION_LENGTHS = (4, 5, 8)
PIXEL_ORIGINS = ("center", "corner")
# Mitsuba's pixels are square: a camera from intrinsics maps to its sensor where fx and fy agree
# to this (relative; K scaled to another image size may round them apart)
SQUARE_PIXELS = 1e-9
FILM_DIAGONAL_MM = math.hypot(36.0, 24.0)  # a Mitsuba focal length is for a 35 mm film, along its diagonal

# The camera, as the kernel's camera function reads it (one element).
CAMERA = Struct(
    "Camera",
    (
        ("u", "real4"),  # world_from_camera: columns u (left), v (up), w (forward)
        ("v", "real4"),
        ("w", "real4"),
        # the eye in the render BVH's space (world axes around the scene's anchor), rounded to float,
        # and (w) a margin over that rounding (kernels/bvh_packet.h: box_entries)
        ("box_origin", "float4"),
        # pixel (row j, column i) looks through sx = tan_x (centre_x - 1 - 2 i + centre_x_low) / width,
        # sy = tan_y (centre_y - 1 - 2 j + centre_y_low) / height (ImagePlane):
        ("tan_x", "real"),  # width / (2 fx), height / (2 fy): a centred camera's tan of half its opening angles
        ("tan_y", "real"),
        ("centre_x_low", "real"),  # 2 cx - centre_x, 2 cy - centre_y: the principal point's fractions
        ("centre_y_low", "real"),
        ("width", "int"),
        ("height", "int"),
        ("centre_x", "int"),  # 2 cx and 2 cy rounded to integers: width and height for a centred camera
        ("centre_y", "int"),
        # tan_x / width and tan_y / height each as a high part of 11 significant bits and the rest
        # (x, x's rest, y, y's rest; fp64: (value, 0)): the fp32 kernel's exact sx, sy (kernels/camera.h)
        ("pixel_step", "real4"),
    ),
    "The camera space (world_from_camera columns) and the image plane (its pixel-centre rays).",
)


class ImagePlane(NamedTuple):
    """Where the pixel centres' rays go, on the image plane at distance 1 in the camera's space
    (x left, y up, z forward): pixel (row j, column i) at
    sx = tan_x (2 cx - 2 i - 1) / width, sy = tan_y (2 cy - 2 j - 1) / height.
    tan_x = width / (2 fx) and tan_y = height / (2 fy) (the tangents of a centred camera's half
    opening angles); cx, cy: the principal point in pixels (K's: width / 2, height / 2 when centred)."""

    tan_x: float
    tan_y: float
    cx: float
    cy: float


def _matrix(key: str, value, rows: int, columns: int) -> np.ndarray:
    """A rows x columns matrix of finite numbers (nested sequences or an array), as float64."""
    shape = f"{rows}x{columns}"
    try:
        array = np.array(value, dtype=object)
    except (ValueError, TypeError):  # a ragged nesting
        array = None
    if array is None or array.shape != (rows, columns):
        raise SceneError(f"expected a {shape} matrix ({rows} rows of {columns} numbers), got {_shown(value)}", key=key)
    out = np.empty((rows, columns))
    for index, entry in np.ndenumerate(array):
        if isinstance(entry, (bool, np.bool_)) or not isinstance(entry, (int, float, np.integer, np.floating)):
            raise SceneError(f"expected a {shape} matrix of numbers, got {_shown(entry)} in row {index[0]}", key=key)
        try:
            out[index] = float(entry)
        except OverflowError:  # an integer beyond float64
            out[index] = math.inf
    if not np.all(np.isfinite(out)):
        raise SceneError(f"expected a {shape} matrix of finite numbers, got {_shown(value)}", key=key)
    return out


def _nested(array: np.ndarray) -> tuple:
    return tuple(tuple(float(x) for x in row) for row in array)


def _intrinsics(key: str, value) -> np.ndarray:
    """K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]: fx, fy > 0, no skew, principal point anywhere
    within MAX_PRINCIPAL_POINT."""
    K = _matrix(key, value, 3, 3)
    form = "[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]"
    if K[0, 1] != 0:
        raise SceneError(f"expected no skew (K[0][1] = 0, as OpenCV's and Mitsuba's cameras), got {float(K[0, 1])!r}", key=key)
    if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise SceneError(f"expected a pinhole matrix {form}, got {_shown(_nested(K))}", key=key)
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        raise SceneError(f"expected focal lengths fx = K[0][0] > 0 and fy = K[1][1] > 0 (pixels), got "
                         f"fx = {float(K[0, 0])!r}, fy = {float(K[1, 1])!r}", key=key)
    if max(abs(K[0, 2]), abs(K[1, 2])) > MAX_PRINCIPAL_POINT:
        raise SceneError(f"expected the principal point (cx, cy) within {MAX_PRINCIPAL_POINT:.0f} pixels of the "
                         f"image's corner, got ({float(K[0, 2])!r}, {float(K[1, 2])!r})", key=key)
    return K


def _rotation(key: str, R: np.ndarray) -> np.ndarray:
    """A rotation within RIGID_TOLERANCE (orthonormal, det +1): as given when orthonormal to float64
    rounding, else its nearest rotation (the polar factor U V^T of R = U S V^T)."""
    deviation = float(np.abs(R.T @ R - np.eye(3)).max())
    determinant = float(np.linalg.det(R))
    if not (deviation <= RIGID_TOLERANCE and determinant > 0):
        what = "a reflection (det < 0)" if determinant < 0 and deviation <= RIGID_TOLERANCE else (
            f"R^T R - I up to {deviation:.3g}")
        raise SceneError(f"expected a rigid camera-to-world pose: its rotation orthonormal within "
                         f"{RIGID_TOLERANCE:g} with det +1 (no scale, shear or mirror), got {what}", key=key)
    if deviation <= RIGID_EXACT:
        return R
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def scaled_intrinsics(K, size, width: int, height: int) -> np.ndarray:
    """K (OpenCV's convention) given for an image of ``size`` (or None: any), at width x height: the
    image's edges scale (pixel centres at integers: the edge at -1/2), so fx and cx + 1/2 do."""
    K = np.array(K, dtype=np.float64)
    if size is not None and (width, height) != tuple(size):
        for row, ratio in ((0, width / size[0]), (1, height / size[1])):
            K[row, row] *= ratio
            K[row, 2] = (K[row, 2] + 0.5) * ratio - 0.5
    return K


def packed_camera(rows, plane: ImagePlane, width: int, height: int, precision: str, box_origin=(0.0, 0.0, 0.0)):
    """The kernel's Camera (CAMERA): the space's rows u, v, w, the image plane (an ImagePlane at
    this size) and the eye in the BVH's space (box_origin: the eye minus the scene's anchor,
    float64). Twice the principal point goes as an integer and the rest, so that the kernel's
    numerator 2 cx - 1 - 2 i is exact but for one rounding of the sum (and exactly
    width - 1 - 2 i, as ever, for a centred camera)."""
    camera = np.zeros(1, dtype=layout(CAMERA, precision).dtype)
    for name, row in zip("uvw", rows):
        camera[name][0, :3] = row
    # rounded to float: the box tests are in float; the margin, 2^-20 |o|_1 (as cast's box rays),
    # covers that rounding and the kernel's differences of faces and origin (kernels/bvh.h)
    origin = np.asarray(box_origin, np.float64)
    camera["box_origin"][0, :3] = origin
    camera["box_origin"][0, 3] = 2.0**-20 * float(np.abs(origin).sum())
    camera["tan_x"], camera["tan_y"] = plane.tan_x, plane.tan_y
    camera["width"], camera["height"] = width, height
    real = camera["pixel_step"].dtype.type
    for k, step in enumerate((plane.tan_x / width, plane.tan_y / height)):
        if real is np.float32:  # 11 bits: its product with a pixel's integer numerator is exact in float
            mantissa, exponent = math.frexp(step)
            high = math.ldexp(round(mantissa * 2.0**11), exponent - 11)
        else:
            high = step
        camera["pixel_step"][0, 2 * k: 2 * k + 2] = high, step - high
    for axis, c in (("x", plane.cx), ("y", plane.cy)):
        whole = round(2 * c)
        camera[f"centre_{axis}"] = whole
        camera[f"centre_{axis}_low"] = 2 * c - whole  # exact in float64: |2 c| < 2^30
    return camera


def packed_space(rows, width: int, height: int, precision: str, box_origin=(0.0, 0.0, 0.0)):
    """The kernel's Camera struct of a model whose rays the kernel does not make from an image plane
    (a table's: lenses, panoramas; or cast: orthographic): the camera's space (rows) alone, with a
    unit plane centred on the image."""
    return packed_camera(rows, ImagePlane(1.0, 1.0, width / 2, height / 2), width, height, precision, box_origin)


@dataclass(frozen=True)
class Camera(CameraModel):
    """A perspective camera at ``eye``, given one of two ways (never a mix):

    - looking at ``target``, ``up`` (default +y), ``fov`` in degrees (default 45) along ``fov_axis``
      ("x", the default, or "y"): ``Camera(eye, target, up, fov)``;
    - from pinhole intrinsics and a pose, OpenCV's convention (x right, y down, z forward):
      ``Camera.from_intrinsics(K, pose)``, which holds ``K`` (3x3, pixels), ``rotation`` (the pose's
      3x3 camera-to-world rotation) and ``size`` ((width, height): the image K is in pixels of;
      None: the scene's image, filled in by the Scene).

    ``intrinsics(width, height)`` and ``pose()`` give K and the pose of either kind; ``basis()`` the
    frame the kernels use, ``image_plane(width, height)`` where its pixel-centre rays go.
    A scene file gives either kind in its [camera] table (from_table); Mitsuba's perspective sensor
    is the same camera (mitsuba_sensor, from_mitsuba)."""

    model = "perspective"
    keys = TABLE_LOOK_AT_KEYS + TABLE_INTRINSICS_KEYS + TABLE_INTRINSICS_OPTIONS
    struct = CAMERA
    mitsuba_plugin = "perspective"
    mitsuba_properties = (("fov", "float", None), ("focal_length", "string", None), ("fov_axis", "string", "x"),
                          ("principal_point_offset_x", "float", 0.0), ("principal_point_offset_y", "float", 0.0))

    eye: tuple[float, float, float]
    target: tuple[float, float, float] | None = None
    up: tuple[float, float, float] | None = None
    fov: float | None = None
    fov_axis: str | None = None
    K: tuple | None = None
    rotation: tuple | None = None
    size: tuple[int, int] | None = None
    distortion: tuple | None = None  # OpenCV's k1, k2, p1, p2, k3, k4, k5, k6 (zeros appended)

    def __post_init__(self):
        object.__setattr__(self, "eye", vector3("eye", self.eye))
        if self.K is not None or self.rotation is not None:
            self._check_intrinsics()
        else:
            self._check_look_at()
        self.basis()  # a degenerate basis is an error now, not a NaN image later

    def _check_look_at(self):
        mixed = next((key for key in INTRINSICS_KEYS if getattr(self, key) is not None), None)
        if mixed is not None:
            raise SceneError(f"a look-at camera (eye, target, up, fov) has no {mixed}: only a camera from intrinsics "
                             "and a pose does (Camera.from_intrinsics)", key=mixed)
        if self.target is None:
            raise SceneError("missing: a camera needs a target (or intrinsics and a pose: Camera.from_intrinsics)",
                             key="target")
        object.__setattr__(self, "target", vector3("target", self.target))
        object.__setattr__(self, "up", vector3("up", (0.0, 1.0, 0.0) if self.up is None else self.up))
        fov = number("fov", 45.0 if self.fov is None else self.fov)
        if not 0 < fov < 180:
            raise SceneError(f"expected 0 < fov < 180 (degrees), got {fov!r}", key="fov")
        object.__setattr__(self, "fov", fov)
        fov_axis = "x" if self.fov_axis is None else self.fov_axis
        if fov_axis not in ("x", "y"):
            raise SceneError(f'expected "x" or "y", got {fov_axis!r}', key="fov_axis")
        object.__setattr__(self, "fov_axis", fov_axis)

    def _check_intrinsics(self):
        mixed = next((key for key in LOOK_AT_KEYS if getattr(self, key) is not None), None)
        if mixed is not None:
            raise SceneError(f"a camera from intrinsics and a pose has no {mixed} (give either eye, target, up, fov, "
                             "fov_axis or intrinsics and a pose, not a mix)", key=mixed)
        for key in ("K", "rotation"):
            if getattr(self, key) is None:
                raise SceneError("missing: a camera from intrinsics needs both K and rotation", key=key)
        object.__setattr__(self, "K", _nested(_intrinsics("K", self.K)))
        object.__setattr__(self, "rotation", _nested(_rotation("rotation", _matrix("rotation", self.rotation, 3, 3))))
        if self.distortion is not None:
            object.__setattr__(self, "distortion", distortion_coefficients("distortion", self.distortion))
        if self.size is not None:
            if isinstance(self.size, (str, bytes)) or not hasattr(self.size, "__len__") or len(self.size) != 2:
                raise SceneError(f"expected (width, height), got {_shown(self.size)}", key="size")
            size = tuple(integer("size", side, minimum=1, maximum=MAX_IMAGE_SIDE) for side in self.size)
            object.__setattr__(self, "size", size)

    @classmethod
    def from_intrinsics(cls, K, pose, width: int | None = None, height: int | None = None, *, convention: str = "opencv",
                        pixel_origin: str = "center", distortion=None) -> "Camera":
        """The camera of pinhole intrinsics K (3x3, pixels: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],
        fx, fy > 0, no skew, principal point anywhere) and a rigid camera-to-world pose (4x4, last
        row 0 0 0 1). pixel (row j, column i) casts normalize(R K^-1 [i, j, 1]) from the pose's
        translation: OpenCV's pixel convention, pixel centres at integer coordinates
        (pixel_origin "center"); pixel_origin "corner" (COLMAP, NeRF, OpenGL) reads K with pixel
        centres at i + 0.5, j + 0.5 (the camera keeps the same K in OpenCV's convention: cx - 0.5,
        cy - 0.5). convention: the pose's axes, "opencv" (x right, y down, z forward: OpenCV,
        Open3D, BOP, COLMAP) or "opengl" (x right, y up, z backward: Blender, pyrender, NeRF).
        distortion: OpenCV's coefficients k1, k2, p1, p2[, k3[, k4, k5, k6]] (cv2.projectPoints'),
        each pixel's ray the exact inverse of that lens, pixels it cannot reach misses.
        width, height: the image K is in pixels of (both or neither); left out, the scene's image.
        Rendered at another size, K scales with the image (the pixels' edges: fx, cx + 1/2 by the
        ratio of widths; fy, cy + 1/2 of heights). Errors name the key: intrinsics, pose, width,
        height, convention, pixel_origin or distortion."""
        K = _intrinsics("intrinsics", K)
        if pixel_origin not in PIXEL_ORIGINS:
            raise SceneError(f'expected "center" (OpenCV: pixel centres at integers) or "corner" (centres at i + 0.5), '
                             f"got {_shown(pixel_origin)}", key="pixel_origin")
        if pixel_origin == "corner":
            K[0, 2] -= 0.5
            K[1, 2] -= 0.5
        pose = _matrix("pose", pose, 4, 4)
        if not np.array_equal(pose[3], [0.0, 0.0, 0.0, 1.0]):
            raise SceneError(f"expected a rigid camera-to-world pose, its last row 0 0 0 1, got "
                             f"{_shown(pose[3].tolist())}", key="pose")
        pose = opencv_pose(pose, convention)
        rotation = _rotation("pose", pose[:3, :3])
        if (width is None) != (height is None):
            raise SceneError("expected both width and height (the image K is in pixels of), or neither",
                             key="height" if height is None else "width")
        size = None
        if width is not None:
            size = (integer("width", width, minimum=1, maximum=MAX_IMAGE_SIDE),
                    integer("height", height, minimum=1, maximum=MAX_IMAGE_SIDE))
        if distortion is not None:
            distortion = distortion_coefficients("distortion", distortion)
        return cls(tuple(pose[:3, 3]), K=_nested(K), rotation=_nested(rotation), size=size, distortion=distortion)

    @classmethod
    def from_table(cls, table: dict) -> "Camera":
        """The [camera] table: eye, target, up, fov, fov_axis, or intrinsics and pose (scene-format.md,
        "Camera from intrinsics") with optional pixel_origin and distortion, never a mix."""
        if not any(key in table for key in TABLE_INTRINSICS_KEYS + TABLE_INTRINSICS_OPTIONS):
            no_unknown_keys(table, TABLE_LOOK_AT_KEYS, required=("eye", "target"))  # fov: 45 by default, as Camera(...)
            return cls(**table)
        no_unknown_keys(table, TABLE_LOOK_AT_KEYS + TABLE_INTRINSICS_KEYS + TABLE_INTRINSICS_OPTIONS)
        if not any(key in table for key in TABLE_INTRINSICS_KEYS):  # a look-at with an option of intrinsics
            key = next(key for key in TABLE_INTRINSICS_OPTIONS if key in table)
            raise SceneError("only a camera from intrinsics and a pose has it (give intrinsics and pose for a lens, "
                             "or leave it out)", key=key)
        for key in TABLE_LOOK_AT_KEYS:
            if key in table:
                raise SceneError("a camera is given either by eye, target, up, fov, fov_axis or by intrinsics and pose, "
                                 "not a mix (the pose holds the eye)", key=key)
        for key in TABLE_INTRINSICS_KEYS:
            if key not in table:
                raise SceneError("missing required key: a camera from intrinsics needs both intrinsics and pose", key=key)
        return cls.from_intrinsics(table["intrinsics"], table["pose"],
                                   pixel_origin=text("pixel_origin", table.get("pixel_origin", "center")),
                                   distortion=table.get("distortion"))

    @property
    def fixed_keys(self) -> tuple[str, ...]:
        """The fields an animation cannot key (pyclray.model.animation): the other kind's, and the
        size. A camera from intrinsics animates its eye (the pose's translation) and its lens's coefficients."""
        if self.K is None:
            return INTRINSICS_KEYS
        # a lens's coefficients may be keyed (each frame's lens solved); a pinhole does not become a lens
        return LOOK_AT_KEYS + ("K", "rotation", "size") + (("distortion",) if self.distortion is None else ())

    def basis(self) -> np.ndarray:
        """Rows u (left), v (up), w (forward): the world_from_camera columns, in float64 (read-only:
        computed once per camera, which is frozen; a warm render asks for it several times)."""
        cached = self.__dict__.get("_basis")
        if cached is None:
            cached = self._basis_of()
            cached.setflags(write=False)
            object.__setattr__(self, "_basis", cached)
        return cached

    def _basis_of(self) -> np.ndarray:
        if self.K is not None:
            R = np.array(self.rotation)
            return np.stack([-R[:, 0], -R[:, 1], R[:, 2]])  # OpenCV's x right, y down, z forward
        return look_at_rows(self.eye, self.target, self.up)


    def project(self, points, width: int, height: int):
        """A pinhole's projection by K and the pose (None with a lens's distortion)."""
        if self.distortion is not None:
            return None
        K, pose = self.intrinsics(width, height), self.pose()
        in_camera = (np.asarray(points, np.float64) - pose[:3, 3]) @ pose[:3, :3]
        z = in_camera[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            pixels = (in_camera @ K.T)[:, :2] / z[:, None]
        return pixels, z

    def intrinsics(self, width: int, height: int) -> np.ndarray:
        """K (3x3 float64): the pinhole intrinsics of this camera's pixel-centre rays at this image
        size, in OpenCV's convention (x right, y down, z forward; pixel (row j, column i) looks
        through K^-1 [i, j, 1]: pixel centres at integer coordinates). A look-at camera:
        fx = width / (2 tan_x), cx = (width - 1) / 2, and alike in y. A camera from intrinsics: its
        K as given at its size (in OpenCV's convention, also where it was given with pixel_origin
        "corner"), scaled with the image at another (fx and cx + 1/2 by width / its width, fy and
        cy + 1/2 by height / its height)."""
        if self.K is None:
            tan_x, tan_y = self.tangents(width, height)
            return np.array([[width / (2 * tan_x), 0.0, width / 2 - 0.5], [0.0, height / (2 * tan_y), height / 2 - 0.5],
                             [0.0, 0.0, 1.0]])
        return scaled_intrinsics(self.K, self.size, width, height)

    def image_plane(self, width: int, height: int) -> ImagePlane:
        """Where this camera's pixel-centre rays go at this image size (see ImagePlane): the one
        description of them that the kernel's camera struct, the oracle and the culling share."""
        if self.K is None:  # exactly the tangents, and the centre: a look-at camera's rays as ever
            return ImagePlane(*self.tangents(width, height), width / 2, height / 2)
        K = self.intrinsics(width, height)  # OpenCV's centres at integers: the plane's at i + 0.5
        return ImagePlane(float(width / (2 * K[0, 0])), float(height / (2 * K[1, 1])), float(K[0, 2]) + 0.5,
                          float(K[1, 2]) + 0.5)

    def tangents(self, width: int, height: int) -> tuple[float, float]:
        """tan of the half opening angles along x and y (square pixels for a look-at camera; for a
        camera from intrinsics, those of a centred camera of its focal lengths: width / (2 fx), ...)."""
        if self.K is not None:
            plane = self.image_plane(width, height)
            return plane.tan_x, plane.tan_y
        t = math.tan(math.radians(self.fov) / 2)
        if self.fov_axis == "x":
            return t, t * height / width
        return t * width / height, t

    def pack(self, width: int, height: int, precision: str, box_origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """The kernel's Camera struct (packed_camera) of this camera's space and image plane at this size."""
        return packed_camera(self.basis(), self.image_plane(width, height), width, height, precision, box_origin)

    def plane_coordinates(self, width: int, height: int, window=None) -> tuple[np.ndarray, np.ndarray]:
        """(sx, sy): the pixel centres' coordinates on the image plane at distance 1 (x left, y up),
        per column and per row (of the window (x0, y0, columns, rows), if given), float64:
        sx = tan_x (2 cx - 2 i - 1) / width, sy = tan_y (2 cy - 2 j - 1) / height (ImagePlane; a
        look-at camera: cx = width / 2, so sx = tan_x (width - 2 i - 1) / width). For a camera from
        intrinsics that is (cx - i) / fx (K's cx, OpenCV's convention): the x of K^-1 [i, j, 1], negated
        (OpenCV's x points right, the space's u left)."""
        col0, row0, columns, rows = (0, 0, width, height) if window is None else window
        plane = self.image_plane(width, height)
        sx = plane.tan_x * ((2 * plane.cx - 1.0) - 2.0 * np.arange(col0, col0 + columns)) / width
        sy = plane.tan_y * ((2 * plane.cy - 1.0) - 2.0 * np.arange(row0, row0 + rows)) / height
        return sx, sy

    def rays(self, width: int, height: int, window=None) -> tuple[np.ndarray, np.ndarray]:
        """(origins, directions) of the pixel-centre rays, each (rows, columns, 3) float64, unit
        directions: pixel (row j, column i) looks through (sx, sy) (plane_coordinates):
        d = normalize(w + sx u + sy v); for a camera from intrinsics that is
        normalize(R K^-1 [i, j, 1]). With a distortion: each pixel's undistorted direction
        (space_directions; a pixel the lens cannot reach gets its pinhole ray, which render and
        cast report as a miss there). The origins are the eye."""
        if self.distortion is not None:
            return self.rays_from_table(width, height, window)
        u, v, w = self.basis()
        sx, sy = self.plane_coordinates(width, height, window)
        d = w + sx[None, :, None] * u + sy[:, None, None] * v
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        origins = np.broadcast_to(np.array(self.eye), d.shape)
        return origins, d

    def space_directions(self, width: int, height: int):
        """With a distortion, each pixel's undistorted unit direction in the camera's space and
        whether the lens reaches it (lens.pinhole_table: Newton on OpenCV's forward model in
        float64), solved once per lens and image size (kept by value: a moving camera's frames, or a
        handle's views, share it); None for a pinhole."""
        if self.distortion is None:
            return None
        K = self.intrinsics(width, height)
        return lens.pinhole_table((float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])), self.distortion,
                                  width, height)

    def mitsuba_sensor(self, width: int, height: int) -> MitsubaSensor:
        """Mitsuba's perspective sensor of the same rays. A look-at camera is its look_at with its
        fov and fov_axis. A camera from intrinsics has to_world the matrix of its space (columns u
        left, v up, w forward: Mitsuba's camera space, OpenCV's x and y negated) and, since
        Mitsuba's pixels are square, only fx = fy (a SceneError otherwise): fov = 2 atan(width / (2 fx))
        along x, and the principal point through principal_point_offset_x/_y, which Mitsuba adds to
        the film position in [0, 1]^2 before projecting (perspective.cpp's sample_ray): the optical
        axis meets the film at 0.5 - offset, so offset_x = 0.5 - c_x / width and offset_y = 0.5 - c_y / height,
        c the principal point from the film's corner (ImagePlane's: K's cx + 0.5 in OpenCV's convention)."""
        if self.distortion is not None:
            raise SceneError("Mitsuba 3's perspective sensor has no lens distortion, so this camera cannot be checked "
                             "against Mitsuba or exported for it", key="distortion")
        if self.K is None:
            return MitsubaSensor(self.mitsuba_plugin, {"fov": self.fov, "fov_axis": self.fov_axis}, width, height,
                                 look_at=LookAt(list(self.eye), list(self.target), list(self.up)))
        K = self.intrinsics(width, height)
        plane = self.image_plane(width, height)  # the principal point with pixel centres at i + 0.5
        fx, fy = float(K[0, 0]), float(K[1, 1])
        if abs(fx - fy) > SQUARE_PIXELS * max(fx, fy):
            raise SceneError(f"Mitsuba's perspective sensor has square pixels only (fx = fy); this camera has fx = {fx:g}, "
                             f"fy = {fy:g} at {width}x{height}, so it cannot be checked against Mitsuba", key="intrinsics")
        to_world = np.eye(4)
        to_world[:3, :3] = self.basis().T  # columns u, v, w: Mitsuba's camera space
        to_world[:3, 3] = self.eye
        properties = {"fov": float(np.degrees(2 * np.arctan(width / (2 * fx)))), "fov_axis": "x",
                      "principal_point_offset_x": 0.5 - plane.cx / width,
                      "principal_point_offset_y": 0.5 - plane.cy / height}
        return MitsubaSensor(self.mitsuba_plugin, properties, width, height, to_world=to_world)

    @classmethod
    def from_mitsuba(cls, sensor: MitsubaSensor) -> "Camera":
        """The camera of Mitsuba's perspective sensor (its properties: mitsuba_properties, None where
        not given; to_world a rotation, translation and uniform scale, or a look-at). A look-at
        stays one (the same rays as Mitsuba's own look_at); with a principal point offset the camera
        is one from intrinsics. fov_axis smaller, larger and diagonal are turned into x or y as
        Mitsuba's perspective sensor does (src/sensors/perspective.cpp, parse_fov); a focal length
        is for a 35 mm film, along its diagonal."""
        values = sensor.properties
        fov, focal, axis = values["fov"], values["focal_length"], values["fov_axis"]
        if fov is None and focal is None:
            raise SceneError("missing property 'fov' (<float name=\"fov\" value=\"45\"/>) or 'focal_length'")
        if fov is None:
            found = re.fullmatch(r"\s*([0-9.eE+-]+)\s*(mm)?\s*", focal)
            if not found:
                raise SceneError(f"property 'focal_length': expected a length in mm such as \"50mm\", got {focal!r}")
            fov, axis = math.degrees(2 * math.atan(FILM_DIAGONAL_MM / (2 * float(found.group(1))))), "diagonal"
        width, height = sensor.width, sensor.height
        if not 0 < fov < 180:
            raise SceneError(f"property 'fov': expected 0 < fov < 180 degrees, got {fov!r}")
        fov, axis = _fov_along_x_or_y(fov, axis, width, height)
        offset = np.array([values["principal_point_offset_x"], values["principal_point_offset_y"]])
        if sensor.look_at is not None and not offset.any():
            origin, target, up = (tuple(float(c) for c in v) for v in sensor.look_at)
            return cls(origin, target, up, fov, axis)
        matrix = sensor.to_world
        columns = matrix[:3, :3].T  # left, up, forward
        left, up, forward = columns / np.linalg.norm(columns, axis=1)[:, None]
        eye = matrix[:3, 3]
        if not offset.any():
            return cls(tuple(eye), tuple(eye + forward), tuple(up), fov, axis)
        # a principal point off the centre: pinhole intrinsics (square pixels) and the pose in OpenCV's
        # convention (x right, y down, z forward); the optical axis meets the film at 0.5 - offset
        tan = math.tan(math.radians(fov) / 2)
        fx = width / (2 * tan) if axis == "x" else height / (2 * tan)
        K = [[fx, 0.0, width * (0.5 - offset[0])], [0.0, fx, height * (0.5 - offset[1])], [0.0, 0.0, 1.0]]
        pose = np.eye(4)
        pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = -left, -up, forward, eye
        return cls.from_intrinsics(K, pose, width, height, pixel_origin="corner")  # Mitsuba's film: centres at i + 0.5


def _fov_along_x_or_y(fov: float, axis: str, width: int, height: int) -> tuple[float, str]:
    """(fov, "x" or "y"): Mitsuba's fov_axis smaller and larger pick the image's shorter or longer
    side; diagonal turns into x through tan(fov_x / 2) = tan(fov / 2) width / diagonal."""
    if axis in ("x", "y"):
        return fov, axis
    if axis == "smaller":
        return fov, "x" if width <= height else "y"
    if axis == "larger":
        return fov, "x" if width >= height else "y"
    if axis == "diagonal":
        tangent = math.tan(math.radians(fov) / 2) * width / math.hypot(width, height)
        return math.degrees(2 * math.atan(tangent)), "x"
    raise SceneError(f"property 'fov_axis': expected x, y, smaller, larger or diagonal, got {axis!r}")


def opencv_pose(pose: np.ndarray, convention: str) -> np.ndarray:
    """A camera-to-world pose in OpenCV's axes (x right, y down, z forward) from one in convention
    "opencv" or "opengl" (x right, y up, z backward: y and z negated)."""
    if convention == "opencv":
        return pose
    if convention == "opengl":
        return pose * [1.0, -1.0, -1.0, 1.0]
    raise SceneError(f'expected "opencv" (x right, y down, z forward) or "opengl" (x right, y up, z backward), '
                     f"got {_shown(convention)}", key="convention")


def distortion_coefficients(key: str, value) -> tuple:
    """OpenCV's distortion vector k1, k2, p1, p2[, k3[, k4, k5, k6]] as 8 floats (zeros appended)."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) not in DISTORTION_LENGTHS:
        raise SceneError(f"expected OpenCV's coefficients [k1, k2, p1, p2], [k1, k2, p1, p2, k3] or "
                         f"[k1, k2, p1, p2, k3, k4, k5, k6], got {_shown(value)}", key=key)
    coefficients = tuple(number(f"{key}[{index}]", c) for index, c in enumerate(np.asarray(value, dtype=object).tolist()))
    return coefficients + (0.0,) * (8 - len(coefficients))


def look_at_rows(eye, target, up) -> np.ndarray:
    """Rows u (left), v (up), w (forward) of a camera at eye looking at target with up (float64);
    a SceneError naming the key where they make no frame."""
    with np.errstate(over="ignore"):
        forward = np.subtract(target, eye)
    length = norm3(forward)
    if not math.isfinite(length):
        raise SceneError("expected target - eye within the range of float64, got an overflow", key="target")
    if length == 0:
        raise SceneError("expected target != eye (the view direction is undefined)", key="target")
    w = forward / length
    up_length = norm3(up)
    if up_length == 0:
        raise SceneError("expected a non-zero up vector, got [0, 0, 0]", key="up")
    left = np.cross(np.array(up) / up_length, w)
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
