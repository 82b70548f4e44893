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
# Ctrl-C during these imports exits quietly with status 130; cli.main takes over from there.
if _os.path.basename(_sys.argv[0]) in ("pyclray", "pyclray.exe", "-m") if _sys.argv else False:
    _signal.signal(_signal.SIGINT, _quiet_interrupt)

from .animate import render_animation
from .animation import Animation, Key
from .device import AOVS, list_devices, select_device
from .errors import BuildError, DeviceError, OutputError, PyclrayError, PyclrayWarning, RequestError, SceneError
from .lighting import DirectionalLight, Material, PointLight, Shading
from .render import Frame, cast, occluded, render
from .scene import Camera, Image, Scene, load_scene, scene_from_dict
from .shapes import Box, Cylinder, Disk, Plane, Rectangle, Sphere

__version__ = "0.1.0"

__all__ = [
    "AOVS", "Animation", "Box", "BuildError", "Camera", "Cylinder", "DeviceError", "DirectionalLight", "Disk", "Frame",
    "Image", "Key", "Material", "OutputError", "Plane", "PointLight", "PyclrayError", "PyclrayWarning", "Rectangle",
    "RequestError", "Scene", "SceneError", "Shading", "Sphere", "cast", "list_devices", "load_scene", "render",
    "render_animation", "occluded", "scene_from_dict", "select_device",
]
