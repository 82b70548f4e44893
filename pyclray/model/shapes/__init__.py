"""The shape types. One shape = one module here (its frozen dataclass and everything about it: keys
and validation, packed struct, float64 oracle, bounds, error-model terms, Mitsuba counterpart: the
scene, device and reference parts of base.py's Shape, and the capabilities of capabilities.py a
mesh-like type takes), one kernel file (kernels/<type>.cl), its tests, and one line in the registry below.
"""
from __future__ import annotations

from .box import Box
from .cylinder import Cylinder
from .disk import Disk
from .instance import Instances
from .mesh import Mesh
from .plane import Plane
from .rectangle import Rectangle
from .sphere import Sphere
from .spheres import Spheres

# type name in scene files -> shape class, in the order the kernel visits them
REGISTRY = {cls.type: cls for cls in (Plane, Sphere, Cylinder, Disk, Rectangle, Box, Spheres, Mesh)}
# what the prepared scene packs: the scene's types, and the meshes that share their arrays packed as
# instances (Mesh.packed_as; never a scene type of its own)
KINDS = {**REGISTRY, Instances.type: Instances}

__all__ = ["KINDS", "REGISTRY", "Box", "Cylinder", "Disk", "Mesh", "Plane", "Rectangle", "Sphere", "Spheres"]
