"""pyclray: an exact OpenCL ray caster for analytic scenes, driven from Python.

    import pyclray
    scene = pyclray.load_scene("scenes/tp02.toml")
    frame = pyclray.render(scene, aovs=("depth", "normal", "id"))   # AOV name -> numpy array
"""
from .animate import render_animation
from .animation import Animation, Key
from .device import AOVS, list_devices, select_device
from .errors import BuildError, DeviceError, PyclrayError, SceneError
from .render import Frame, cast, render
from .scene import Camera, Image, Scene, load_scene, scene_from_dict
from .shapes import Plane, Sphere

__version__ = "0.1.0"

__all__ = [
    "AOVS", "Animation", "BuildError", "Camera", "DeviceError", "Frame", "Image", "Key", "Plane", "PyclrayError",
    "Scene", "SceneError", "Sphere", "cast", "list_devices", "load_scene", "render", "render_animation",
    "scene_from_dict", "select_device",
]
