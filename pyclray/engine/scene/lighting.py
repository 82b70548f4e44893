"""The shaded image: what the kernel needs of the scene's materials and lights (packed in the
camera's space; kernels/shading.h). Its float64 reference is pyclray.reference.shading.
"""
from __future__ import annotations

import numpy as np

from ...model.layout import layout
from ...model.lights import LIGHT, MATERIAL, PointLight, effective_lights

SHADOW_OFFSET_K = 16  # kernels/shading.h: the shadow ray's offset K eps |n_s| . |p|, where it is offset


def shadow_reach(distance, eps: float) -> np.ndarray:
    """How far a shadow ray's start may lie from the exact hit point at ``distance`` from the eye
    (kernels/shading.h): the hit's rounding and the offset, K eps |n_s| . |p| <= K eps |p|, whatever
    the shape's size (skip-self starts at p itself)."""
    return SHADOW_OFFSET_K * eps * np.asarray(distance, np.float64)


def pack_materials(shapes, precision: str) -> np.ndarray:
    """Each shape's material, by id."""
    out = np.zeros(max(len(shapes), 1), dtype=layout(MATERIAL, precision).dtype)
    for index, shape in enumerate(shapes):
        material = shape.material
        out["color"][index] = (*material.color, material.specular)
        out["shininess"][index] = material.shininess
    return out


def pack_lights(scene, precision: str) -> np.ndarray:
    """The scene's lights (or its headlight) in the camera's space, computed in float64."""
    lights = effective_lights(scene)
    rotation = scene.camera.basis()  # rows u, v, w: space_from_world
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
