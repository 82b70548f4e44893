"""The shaded image: what the kernel needs of the scene's materials and lights (packed in the
camera's frame; kernels/shading.h). Its float64 reference is pyclray.reference.shading.
"""
from __future__ import annotations

import numpy as np

from ..model.layout import Struct, layout
from ..model.lights import PointLight, effective_lights

# Per shape id: its material, and its extent R (the size of the coordinates its intersection works
# with, for the shadow rays' offset: kernels/shading.h).
MATERIAL = Struct(
    "Material",
    (
        ("color", "real4"),  # albedo rgb; w: specular
        ("shininess", "real"),
        ("extent", "real"),  # R: how far the shape reaches from its own centre (0: unbounded)
    ),
    "A shape's material by id: color.xyz albedo, color.w specular, shininess; its extent R.",
)
# Per light: a point light's position in the frame (w = 1) or a directional light's unit direction
# toward the light in the frame (w = 0), and its intensity or irradiance.
LIGHT = Struct(
    "Light",
    (
        ("position", "real4"),  # point: xyz in the frame, w = 1; directional: toward the light, w = 0
        ("power", "real4"),  # rgb intensity (point) or irradiance (directional)
    ),
    "A light in the camera's frame: position.w = 1 point (xyz its position), 0 directional (xyz toward it).",
)
STRUCTS = (MATERIAL, LIGHT)


def shape_extent(shape) -> float:
    """R for the shadow rays' offset: the radius of a sphere around the shape's centre that holds it
    (from the shape's own bounds where it has them), 0 for a shape without bounds (a plane), whose
    intersection works with the ray's origin only."""
    if getattr(shape, "bounded", True) is False:
        return 0.0
    if hasattr(shape, "bounding_spheres"):  # a batch: its largest primitive's
        return float(shape.bounding_spheres([shape])[1].max(initial=0.0))
    return float(getattr(shape, "radius", 0.0))


def pack_materials(shapes, precision: str) -> np.ndarray:
    """Each shape's material and extent, by id."""
    out = np.zeros(max(len(shapes), 1), dtype=layout(MATERIAL, precision).dtype)
    for index, shape in enumerate(shapes):
        material = shape.material
        out["color"][index] = (*material.color, material.specular)
        out["shininess"][index] = material.shininess
        out["extent"][index] = shape_extent(shape)
    return out


def pack_lights(scene, precision: str) -> np.ndarray:
    """The scene's lights (or its headlight) in the camera's frame, computed in float64."""
    lights = effective_lights(scene)
    rotation = scene.camera.basis()  # rows u, v, w: frame_from_world
    eye = np.array(scene.camera.eye)
    out = np.zeros(len(lights), dtype=layout(LIGHT, precision).dtype)
    for index, light in enumerate(lights):
        if isinstance(light, PointLight):
            out["position"][index] = (*(rotation @ (np.array(light.position) - eye)), 1.0)
            out["power"][index, :3] = light.intensity
        else:
            out["position"][index, :3] = rotation @ light.toward_light()
            out["power"][index, :3] = light.irradiance
    return out
