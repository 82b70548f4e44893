"""LiDAR sensors (scene-format.md, "LiDAR"): the Lidar (sensor.py) and the makers' beam tables its
presets come from (presets.py)."""
from __future__ import annotations

from .presets import PRESETS, Preset
from .sensor import DEFAULT_RATE, Lidar

__all__ = ["DEFAULT_RATE", "Lidar", "PRESETS", "Preset"]
