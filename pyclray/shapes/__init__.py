"""The shape types. One shape = one kernel file (kernels/<type>.cl), one module here (its frozen
dataclass, its packed struct and its float64 oracle) and one test file (tests/test_<type>.py).
Adding a shape touches those three places and the registry line below, nothing else.
"""
from __future__ import annotations

from .plane import Plane
from .sphere import Sphere

# type name in scene files -> shape class, in the order the kernel visits them
REGISTRY = {cls.type: cls for cls in (Plane, Sphere)}

__all__ = ["REGISTRY", "Plane", "Sphere"]
