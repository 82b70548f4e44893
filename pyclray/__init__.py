"""pyclray: an exact OpenCL ray caster for analytic scenes, driven from Python.

    import pyclray
    scene = pyclray.load_scene("scenes/tp02.toml")
    frame = pyclray.render(scene, aovs=("depth", "normal", "id"))   # AOV name -> numpy array
"""
import os as _os
import signal as _signal
import sys as _sys


def _quiet_interrupt(number, frame):
    raise SystemExit(130)


# Run as the command line (the pyclray script, or python -m pyclray while the package is found),
# Ctrl-C during these imports exits quietly with status 130; apps.cli.main takes over from there.
if _os.path.basename(_sys.argv[0]) in ("pyclray", "pyclray.exe", "-m") if _sys.argv else False:
    _signal.signal(_signal.SIGINT, _quiet_interrupt)

from .engine.opencl.device import list_devices, select_device
from .engine.api import clear as clear_cache
from .engine.api import render, render_animation, render_views
from .engine.queries.requests import Frame
from .engine.tracer import Tracer, prepare
from .model.animation import Animation, Key
from .model.aovs import AOVS
from .model.camera import Camera, Image
from .model.cameras import Equirectangular, Fisheye, Orthographic
from .model.errors import BuildError, DeviceError, OutputError, PyclrayError, PyclrayWarning, RequestError, SceneError
from .model.lidar import Lidar
from .model.lights import DirectionalLight, Material, PointLight, Shading
from .model.loader import load_scene, scene_from_dict
from .model.scene import Scene
from .model.shapes import Box, Cylinder, Disk, Mesh, Plane, Rectangle, Sphere, Spheres
from .version import __version__


__all__ = [
    "AOVS", "Animation", "Box", "BuildError", "Camera", "clear_cache", "Cylinder", "DeviceError", "DirectionalLight", "Disk", "Frame",
    "Image", "Key", "Lidar", "Material", "OutputError", "Plane", "PointLight", "PyclrayError", "PyclrayWarning", "Rectangle",
    "Mesh", "RequestError", "Scene", "SceneError", "Shading", "Sphere", "Spheres", "Tracer", "all_hits", "cast", "count_hits", "list_devices", "load_scene", "render",
    "read_exr", "read_npz", "render_animation", "render_views", "occluded", "prepare", "closest_points", "distance", "signed_distance", "occupancy", "Scan", "scan", "scene_from_dict", "select_device", "write_exr",
    "write_npz", "write_ply", "Equirectangular", "Fisheye", "Orthographic",
]


# Imported when first asked for: the files' readers and writers and the casts are not on the render
# path (a first render of a new process pays for every module it imports), and pyclray.cluster needs
# the cluster extra (importing distributed takes a while). name -> (module, attribute)
_LAZY = {
    "cast": (".engine.api", "cast"), "occluded": (".engine.api", "occluded"), "scan": (".engine.api", "scan"),
    "Scan": (".engine.queries.scan", "Scan"), "write_ply": (".io.ply", "write_ply"),
    "closest_points": (".engine.api", "closest_points"), "distance": (".engine.api", "distance"),
    "signed_distance": (".engine.api", "signed_distance"), "occupancy": (".engine.api", "occupancy"),
    "count_hits": (".engine.api", "count_hits"), "all_hits": (".engine.api", "all_hits"),
    "write_exr": (".io.bands", "write_exr"), "write_npz": (".io.bands", "write_npz"),
    "read_exr": (".io.exr", "read_exr"), "read_npz": (".io.npz", "read_npz"),
    "cluster": (".apps.cluster", None),
}


def __getattr__(name: str):
    """The names of _LAZY, imported at their first use (then kept as the package's attributes)."""
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from importlib import import_module

    module, attribute = _LAZY[name]
    value = import_module(module, __name__)
    value = value if attribute is None else getattr(value, attribute)
    if attribute is not None:
        globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
