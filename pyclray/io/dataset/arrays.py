"""`--format npz` and `--format exr`: one file per view, OUT/{k:06d}.npz or .exr, holding every image
asked for and the camera beside them, and the index OUT/views.json listing the views.

An .npz holds each AOV under its name (as pyclray.render returns it: id -1 on a miss) and `K`
(3x3), `pose` (4x4 camera-to-world) and `extrinsic` (4x4 world-to-camera), OpenCV's axes; an .exr
holds the AOVs' channels with K and the pose in its header (pyclray.io.exr). Where `id` is asked,
{k:06d}.id.png beside it is the 16-bit id image of image formats: 0 background, id + 1 for shape id
(images.id_image)."""
from __future__ import annotations

import io
import json

import numpy as np

from ..exr import ExrWriter, exr_channel_arrays
from .images import id_image, png_bytes
from .views import EncodedView


def extrinsic(pose: np.ndarray) -> np.ndarray:
    """World-to-camera (4x4) of a rigid camera-to-world pose."""
    out = np.eye(4)
    out[:3, :3] = pose[:3, :3].T
    out[:3, 3] = -pose[:3, :3].T @ pose[:3, 3]
    return out


class ArraysFormat:
    """Per-view files of every AOV asked (npz or exr) and their index."""

    needs_alone = False

    def __init__(self, kind: str, aovs):
        self.name, self.aovs = kind, tuple(aovs)

    def settings(self) -> dict:
        return {"aovs": list(self.aovs)}

    @staticmethod
    def objects(scene) -> list:
        return []

    def check(self, scene) -> None:
        if "id" in self.aovs and len(scene.shapes) >= 65535:
            from ...model.errors import RequestError

            raise RequestError(f"--aov id: {len(scene.shapes)} shapes do not fit the 16-bit id image (id + 1 <= 65535)")

    def fixed_files(self, scene) -> dict:
        return {}

    def folders(self) -> list[str]:
        return []

    def index_files(self, scene, records: list[dict]) -> dict:
        index = {"format": self.name, "aovs": list(self.aovs), "width": scene.image.width,
                 "height": scene.image.height, "views": records}
        return {"views.json": (json.dumps(index, indent=1) + "\n").encode()}

    def encode(self, scene, rendered) -> EncodedView:
        k, camera, images = rendered.index, rendered.camera, rendered.images
        height, width = next(iter(images.values())).shape[:2]
        K, pose = camera.intrinsics(width, height), camera.pose()
        w2c = extrinsic(pose)
        name = f"{k:06d}.{self.name}"
        arrays = {aov: images[aov] for aov in self.aovs}
        if self.name == "npz":
            def write():
                buffer = io.BytesIO()
                np.savez(buffer, **arrays, K=K, pose=pose, extrinsic=w2c)
                return buffer.getvalue()
        else:
            def write():
                buffer = io.BytesIO()
                channels = exr_channel_arrays(arrays)
                writer = ExrWriter(buffer, width, height, {n: kind for n, (_, kind) in channels.items()},
                                   comment="pyclray dataset", camera=(K, pose))
                writer.write({n: array for n, (array, _) in channels.items()})
                writer.close()
                return buffer.getvalue()
        files = {name: write}
        record = {"file": name, "K": K.tolist(), "pose": pose.tolist(), "extrinsic": w2c.tolist()}
        if "id" in self.aovs:
            files[f"{k:06d}.id.png"] = lambda: png_bytes(id_image(images["id"], 16))
            record["id_png"] = f"{k:06d}.id.png"
        return EncodedView(k, files, record)
