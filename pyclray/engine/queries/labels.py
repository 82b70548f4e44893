"""The `label` image: the hit shape's label, derived on the host from the id image after the kernel
(the kernel never sees labels: a label is one lookup per pixel, and a render with labels is the
same program as one with ids)."""
from __future__ import annotations

import numpy as np

from ...model.shapes.base import labels_of


def with_labels(scene, images: dict, asked) -> dict:
    """The images asked for, in their order: `label` made from `id` (labels[id]; -1 for a miss and
    for a shape without a label), and `id` dropped if it was made only for the labels."""
    if "label" not in asked:
        return images
    # the last entry answers id -1 (a miss): index -1 is the end of the array
    lookup = np.append(labels_of(scene.shapes), np.int32(-1))
    made = dict(images, label=lookup[images["id"]])
    return {name: made[name] for name in asked}
