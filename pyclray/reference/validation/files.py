"""What ``pyclray check --save`` writes: both renders as EXR and the depth-difference heat map."""
from __future__ import annotations

from pathlib import Path

import numpy as np

HEAT_LOW, HEAT_HIGH = -9.0, -4.0  # log10 of the relative depth difference at the two ends of the ramp
RAMP = np.array(
    [[0, 0, 96], [0, 96, 255], [0, 208, 160], [160, 224, 0], [255, 160, 0], [224, 0, 0]], np.float64
)


def heat_map(relative: np.ndarray, judged: np.ndarray, outside: np.ndarray) -> np.ndarray:
    """RGB uint8: log10 of the relative depth difference from 1e-9 (dark blue) to 1e-4 (red), a zero
    difference dark blue; white where outside the tolerance; black where not compared."""
    with np.errstate(divide="ignore", invalid="ignore"):
        level = (np.log10(np.where(judged, relative, np.nan)) - HEAT_LOW) / (HEAT_HIGH - HEAT_LOW)
    level = np.clip(np.nan_to_num(level, nan=0.0, neginf=0.0), 0.0, 1.0) * (len(RAMP) - 1)
    low = np.floor(level).astype(int).clip(0, len(RAMP) - 2)
    weight = (level - low)[..., None]
    rgb = (1 - weight) * RAMP[low] + weight * RAMP[low + 1]
    rgb[~judged] = 0
    rgb[outside] = 255
    return np.round(rgb).astype(np.uint8)


def save(result, folder: Path, stem: str) -> list[Path]:
    """Write both renders of an ImageCheck as EXR and the depth-difference heat map as PNG."""
    from ...io.bands import write_exr
    from ...io.files import write_together
    from ...io.png import write_png

    ours, theirs = result.images["ours"], result.images["theirs"]
    paths = [
        folder / f"{stem}.pyclray.exr",
        folder / f"{stem}.mitsuba-{result.variant}.exr",
        folder / f"{stem}.depth-error.png",
    ]
    heat = heat_map(result.images["relative"], result.images["judged"], result.images["outside"])
    return write_together([  # the three files replaced together or not at all
        (paths[0], lambda tmp: write_exr(tmp, ours, comment="pyclray fp32 render (pyclray check)")),
        (paths[1], lambda tmp: write_exr(tmp, {k: theirs[k] for k in ("depth", "normal", "id")},
                                         comment=f"Mitsuba {result.variant} render in pyclray's conventions (pyclray check)")),
        (paths[2], lambda tmp: write_png(tmp, heat)),
    ])
