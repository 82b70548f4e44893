"""The pictures of docs/lidar.md and the README: a sweeping OS1-64 scan of scenes/lidar.toml at t = 1 s,
as its range image (docs/lidar.range.png: near bright, far dark, misses black; each row drawn 3
pixels high) and as its points seen from above (docs/lidar.top.png: each point in its label's
colour, 1 pixel = 0.1 scene units, the sensor at the centre), beside a static scan's car
(docs/lidar.car.png: the car's points from above, still and swept).

    python -m bench.lidar_pictures
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

import pyclray
from pyclray.io.png import colors_of, preview, write_png

ROOT = Path(__file__).resolve().parent.parent


def top_view(points: np.ndarray, labels: np.ndarray, size: int, scale: float, centre=(0.0, 0.0), dot: int = 1):
    """(size, size, 3) uint8: the points seen from above (x up the picture, y to its left), each
    pixel the colour of the label of the highest point there, a point dot x dot pixels."""
    rgb = np.zeros((size, size, 3), np.uint8)
    order = np.argsort(points[:, 2])  # the highest drawn last
    rows = np.round(size / 2 - (points[order, 0] - centre[0]) / scale).astype(int)
    columns = np.round(size / 2 - (points[order, 1] - centre[1]) / scale).astype(int)
    colours = colors_of(np.maximum(labels[order], 0))
    for dr in range(dot):
        for dc in range(dot):
            r, c = rows + dr, columns + dc
            inside = (r >= 0) & (r < size) & (c >= 0) & (c < size)
            rgb[r[inside], c[inside]] = colours[inside]
    return rgb


def main() -> None:
    scene = pyclray.load_scene(ROOT / "scenes" / "lidar.toml")
    scan = pyclray.scan(scene, time=1.0)
    range_rgb = np.repeat(preview("depth", scan["range"]), 3, axis=0)
    write_png(ROOT / "docs" / "lidar.range.png", range_rgb)
    labels = scan["label"][scan["ring"], scan["column"]]
    write_png(ROOT / "docs" / "lidar.top.png", top_view(scan["points_world"], labels, 480, 0.1))
    # the car from above: still (the scene at t = 1 s) and swept (the revolution starting at 1 s)
    still = pyclray.scan(scene.at(1.0), dataclasses.replace(scene.lidars[0], sweep=False))
    pictures = []
    for one in (still, scan):
        car = one["label"][one["ring"], one["column"]] == 5  # the car's label
        pictures.append(top_view(one["points_world"][car], np.full(car.sum(), 5), 200, 0.03, centre=(8.0, 0.5),
                                 dot=3))
    write_png(ROOT / "docs" / "lidar.car.png", np.concatenate([pictures[0], np.full((200, 4, 3), 255, np.uint8),
                                                               pictures[1]], axis=1))


if __name__ == "__main__":
    main()
