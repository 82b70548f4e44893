"""Cross-checks of pyclray against Mitsuba 3 (``pyclray check``), in parts a reader can hold:

- ``summary``: Summary (max, p99, median) and plain text tables;
- ``images``: ``cross_check``, the image comparison (pyclray's render against Mitsuba's);
- ``rays``: ``ray_level``, Mitsuba's own primary rays cast through both;
- ``files``: the depth-difference heat map and the files ``--save`` writes;
- ``shaded``: ``cross_check_shaded``, the shaded image against Mitsuba's direct integrator.

The error model they judge by is ``pyclray.reference.error_model``; the command is ``pyclray.apps.cli.check``.
"""
from .images import ImageCheck, cross_check, format_image_check
from .rays import RayCheck, format_ray_check, ray_level
from .summary import Summary, table

__all__ = ["ImageCheck", "RayCheck", "Summary", "cross_check", "format_image_check", "format_ray_check",
           "ray_level", "table"]
