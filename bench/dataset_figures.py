"""The pictures of docs/datasets.md, from scenes/dataset.toml at t = 1 s: the rgb image, the masks
(each object's visible mask in its colour, the part hidden by the ball (its amodal mask less the
visible one) lighter), and the flow to the next frame (hue: direction, brightness: length; still surfaces black).

    python bench/dataset_figures.py      # writes docs/dataset.rgb.png, dataset.masks.png, dataset.flow.png
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

import pyclray
from pyclray.io.dataset.images import png_bytes
from pyclray.io.png import srgb_preview

ROOT = Path(__file__).resolve().parent.parent
T = 1.0
COLOURS = np.array([[230, 160, 60], [70, 140, 230]], np.float64)


def flow_colours(flow: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """Hue from the direction, value from the length (relative to the longest), black off the shapes."""
    dx, dy = flow[..., 0].astype(np.float64), flow[..., 1].astype(np.float64)
    length = np.hypot(dx, dy)
    hue = (np.arctan2(dy, dx) / (2 * np.pi)) % 1.0
    value = np.clip(length / max(float(length[hit].max()), 1e-9), 0, 1) ** 0.5
    k = (hue[..., None] * 6 + np.array([5.0, 3.0, 1.0])) % 6  # HSV to RGB, saturation 1
    rgb = value[..., None] * (1 - np.clip(np.minimum(k, 4 - k), 0, 1))
    return np.where(hit[..., None], rgb * 255, 0).round().astype(np.uint8)


def main() -> None:
    scene = pyclray.load_scene(ROOT / "scenes/dataset.toml")
    frame = pyclray.render(scene, aovs=("shaded", "id", "flow"), time=T)
    still = scene.at(T)
    (ROOT / "docs/dataset.rgb.png").write_bytes(png_bytes(srgb_preview(frame["shaded"])))
    masks = np.full(frame["id"].shape + (3,), 24.0)
    objects = [i for i, shape in enumerate(still.shapes) if shape.label is not None]
    for colour, shape_id in zip(COLOURS, objects):
        alone = pyclray.render(replace(still, shapes=(still.shapes[shape_id],), lights=(), animation=None),
                               aovs=("id",))["id"] >= 0
        visible = frame["id"] == shape_id
        masks[alone & ~visible] = 0.35 * colour + 0.65 * 255  # hidden: in mask/, not in mask_visib/
        masks[visible] = colour
    (ROOT / "docs/dataset.masks.png").write_bytes(png_bytes(masks.round().astype(np.uint8)))
    (ROOT / "docs/dataset.flow.png").write_bytes(png_bytes(flow_colours(frame["flow"], frame["id"] >= 0)))


if __name__ == "__main__":
    main()
