"""A request's checks and its result: the Frame a render or a cast returns (the public type), the
checks of the AOVs and precision asked for, and a render's camera as the vision tools take it."""
from __future__ import annotations

from ...model.aovs import AOVS
from ...model.errors import DeviceError, RequestError
from ...model.layout import PRECISIONS
from ..opencl.device import DeviceContext, has_fp64


class Frame(dict):
    """The images of a render (or the per-ray results of a cast): AOV name -> numpy array.

    depth: distance from the ray origin along the unit ray, +inf on a miss (float32; float64 with
    precision "fp64"); normal: unit world normal, (0, 0, 0) on a miss; id: int32, -1 on a miss.
    Renders may add zdepth (depth along the optical axis, +inf on a miss), position (world hit
    point, (0, 0, 0) on a miss), shaded (linear RGB, the background on a miss) and label (int32, the
    hit shape's label, -1 on a miss or for a shape without one).

    A render's frame also holds its camera as the vision tools take it: ``intrinsics`` (K, 3x3, in
    pixels of these images: a window's principal point is shifted by its corner) and ``pose`` (4x4
    camera-to-world), OpenCV's convention (x right, y down, z forward; pixel centres at integer
    coordinates), so that pose @ [depth * normalize(K^-1 [i, j, 1]), 1] is pixel (j, i)'s hit point
    (a pinhole's; a lens's K comes with its distortion, the camera's); None for a cast's, and K None
    for a camera model without one (orthographic, equirectangular).
    """

    def __init__(self, arrays, *, precision: str, device: str, intrinsics=None, pose=None, view=None):
        super().__init__(arrays)
        self.precision = precision
        self.device = device
        # view: (camera, width, height, col0, row0) of a render, whose intrinsics and pose are
        # computed when first asked for (a noticeable share of a warm render)
        self._camera = {"intrinsics": intrinsics, "pose": pose} if view is None else None
        self._view = view

    def _camera_of_view(self) -> dict:
        if self._camera is None:
            self._camera = frame_camera(*self._view)
        return self._camera

    @property
    def intrinsics(self):
        return self._camera_of_view()["intrinsics"]

    @intrinsics.setter
    def intrinsics(self, value):
        self._camera = {**self._camera_of_view(), "intrinsics": value}

    @property
    def pose(self):
        return self._camera_of_view()["pose"]

    @pose.setter
    def pose(self, value):
        self._camera = {**self._camera_of_view(), "pose": value}

    def __repr__(self) -> str:
        shapes = ", ".join(f"{k}: {v.dtype}{list(v.shape)}" for k, v in self.items())
        return f"Frame({shapes}; {self.precision} on {self.device})"


def check_request(aovs, precision: str, ctx: DeviceContext, known=AOVS) -> tuple[str, ...]:
    if isinstance(aovs, str):
        aovs = tuple(a.strip() for a in aovs.split(","))
    try:
        aovs = tuple(aovs)
    except TypeError:
        raise RequestError(f"aovs: expected a selection of {', '.join(known)}, got {type(aovs).__name__}") from None
    unknown = [a for a in aovs if not isinstance(a, str) or a not in known]
    if unknown or not aovs or len(set(aovs)) != len(aovs):
        raise RequestError(f"aovs: expected a non-empty selection of {', '.join(known)} without repeats, got {', '.join(a if isinstance(a, str) and a.isprintable() else repr(a) for a in aovs) or 'none'}")
    check_precision(precision, ctx)
    return tuple(a for a in known if a in aovs)  # canonical order: one program per set


def check_precision(precision: str, ctx: DeviceContext | None = None) -> str:
    """The precision's name, and (given a device) that the device has what it needs."""
    if not isinstance(precision, str) or precision not in PRECISIONS:
        raise RequestError(f"precision: expected one of {', '.join(PRECISIONS)}, got {precision!r}")
    if ctx is not None and precision == "fp64" and not has_fp64(ctx.device):
        raise DeviceError(
            f"precision fp64 needs the cl_khr_fp64 extension, which {ctx.device.name.strip()} lacks; "
            "use precision fp32 or another device"
        )
    return precision


def frame_camera(camera, width: int, height: int, col0: int = 0, row0: int = 0) -> dict:
    """The intrinsics and pose of a Frame (see Frame) of the window of a width x height image from
    column col0 and row row0 on."""
    K = camera.intrinsics(width, height)
    if K is not None:  # (None: a model without pinhole intrinsics)
        K[0, 2] -= col0
        K[1, 2] -= row0
    return {"intrinsics": K, "pose": camera.pose()}
