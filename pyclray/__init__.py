"""pyclray: an exact OpenCL ray caster for analytic scenes, driven from Python.

    import pyclray
    scene = pyclray.load_scene("scenes/tp02.toml")
    frame = pyclray.render(scene, aovs=("depth", "normal", "id"))   # AOV name -> numpy array
"""
from .device import AOVS, list_devices, select_device
from .errors import BuildError, DeviceError, PyclrayError, SceneError
from .lighting import DirectionalLight, Material, PointLight, Shading
from .render import Frame, cast, render
from .scene import Camera, Image, Scene, load_scene, scene_from_dict
from .shapes import Plane, Sphere

__version__ = "0.1.0"

__all__ = [
    "AOVS", "BuildError", "Camera", "DeviceError", "DirectionalLight", "Frame", "Image", "Material", "Plane",
    "PointLight", "PyclrayError", "Shading",
    "Scene", "SceneError", "Sphere", "cast", "list_devices", "load_scene", "render",
    "scene_from_dict", "select_device",
]
