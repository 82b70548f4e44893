"""`--format bop`: the BOP layout (the BOP toolkit's docs/bop_datasets_format.md; what each file
holds as its bop_toolkit_lib/inout.py and scripts/calc_gt_info.py, calc_gt_coco.py write it), and the
COCO instance annotations beside it.

OUT/models/obj_{obj_id:06d}.ply and models_info.json, OUT/camera.json, and one scene,
OUT/train/000000/ (a `train` split of scene id 0, as BOP's synthetic training scenes): rgb/, depth/,
mask/, mask_visib/, scene_camera.json, scene_gt.json, scene_gt_info.json, scene_gt_coco.json.

Objects are the labelled shapes (obj_id = label; each needs a triangle model, Shape.object_model);
the others are scenery: in depth and rgb, not in the annotations or masks. Each image lists every
object in the scene's order (gt_id), seen or not, as BOP's synthetic scenes do. Lengths are in mm:
scene units times 1000 * unit (--unit, metres per scene unit). The amodal mask (mask/) is a render
of the object alone with the same camera (DatasetViews prepares each object's shape alone); where it
reaches the image's border a render on a canvas three times the image's size counts its pixels
beyond the image, as calc_gt_info does (px_count_all, bbox_obj)."""
from __future__ import annotations

import json

import numpy as np

from ..png import srgb_preview
from .images import mask_image, png_bytes
from .models import model_info, model_pose, object_models, ply_bytes
from .views import EncodedView

SPLIT = "train"
SCENE_ID = 0
SCENE_FOLDER = f"{SPLIT}/{SCENE_ID:06d}"
DEPTH_MAX = 65535  # uint16: a depth beyond it (in depth_scale units) is stored as 0, no measurement


def bop_json(content: dict) -> bytes:
    """A JSON object as the toolkit's inout.save_json writes one: a line per key (numeric keys in
    numeric order), each value json.dumps(..., sort_keys=True)."""
    items = sorted(content.items(), key=lambda item: (int(item[0]) if str(item[0]).lstrip("-").isdigit() else 0,
                                                      str(item[0])))
    lines = [f'  "{key}": {json.dumps(value, sort_keys=True)}' for key, value in items]
    return ("{\n" + ",\n".join(lines) + ("\n" if lines else "") + "}").encode()


def bbox(xs, ys) -> list[int]:
    """The toolkit's misc.calc_2d_bbox: [x, y, w, h] with w = max x - min x (and h likewise)."""
    x0, y0, x1, y1 = int(min(xs)), int(min(ys)), int(max(xs)), int(max(ys))
    return [x0, y0, x1 - x0, y1 - y0]


def mask_box(mask: np.ndarray):
    """(x0, y0, x1, y1) of a mask's pixels, or None."""
    rows, columns = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if not len(rows):
        return None
    return int(columns[0]), int(rows[0]), int(columns[-1]), int(rows[-1])


def run_lengths(mask: np.ndarray, columns=None) -> list[int]:
    """The runs of 0s and 1s of a mask in column-major order, starting with a run of 0s (COCO's RLE
    counts; the toolkit's pycoco_utils.binary_mask_to_rle). columns: (first, last) holding every 1
    of the mask, if known: only those columns are read, the others' 0s added to the end runs."""
    mask = np.asarray(mask, bool)
    first, last = (0, mask.shape[1] - 1) if columns is None or not mask.size else columns
    flat = mask[:, first:last + 1].ravel(order="F")
    changes = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    counts = np.diff(np.concatenate([[0], changes, [flat.size]])).tolist()
    counts = [0] + counts if flat.size and flat[0] else counts
    before, after = first * mask.shape[0], (mask.shape[1] - 1 - last) * mask.shape[0]
    if before:
        counts[0] += before
    if after:  # onto the last run of 0s, or a new one after a last run of 1s
        if len(counts) % 2:
            counts[-1] += after
        else:
            counts.append(after)
    return counts


def coco_rle(mask: np.ndarray, columns=None) -> dict:
    """COCO's compressed run-length encoding of a mask, as pycocotools.mask.encode makes it: size
    [height, width] and counts, the run lengths as a string (maskApi.c's rleToString: from the
    third run on, each run less the one two before it, in 5-bit groups, low first, with a
    continuation bit, as characters 48 + value). pycocotools.mask.decode reads it as it is.
    columns: as run_lengths."""
    counts = run_lengths(mask, columns)
    text = []
    for i, count in enumerate(counts):
        x = count - counts[i - 2] if i > 2 else count
        more = True
        while more:
            c = x & 0x1F
            x >>= 5  # arithmetic: a negative difference ends in -1
            more = x != -1 if c & 0x10 else x != 0
            text.append(chr(48 + (c | 0x20 if more else c)))
    return {"size": list(mask.shape), "counts": "".join(text)}


class BopFormat:
    """The BOP writer: what a view renders (zdepth, id, shaded, and each object alone), a view's
    files and record, and the files of the whole set."""

    name = "bop"
    aovs = ("zdepth", "id", "shaded")
    needs_alone = True

    def __init__(self, unit: float = 1.0, depth_scale: float = 1.0):
        self.unit, self.depth_scale = float(unit), float(depth_scale)
        self.millimetres = 1000.0 * self.unit  # mm per scene unit

    def settings(self) -> dict:
        return {"unit": self.unit, "depth_scale": self.depth_scale}

    @staticmethod
    def objects(scene) -> list:
        return [shape for shape in scene.shapes if shape.label is not None]

    @staticmethod
    def object_ids(scene) -> list[int]:
        """The ids (indices in scene.shapes) of the objects, in the scene's order (gt_id)."""
        return [i for i, shape in enumerate(scene.shapes) if shape.label is not None]

    def check(self, scene) -> None:
        """A RequestError now (before anything is written) for a scene BOP cannot hold."""
        object_models(self.objects(scene), self.millimetres)

    # -- the files of the whole set ----------------------------------------------------------------
    def fixed_files(self, scene) -> dict:
        """Files that depend on the scene alone (written once, before the views): the models,
        models_info.json, camera.json (the scene camera's K, for sensor simulation)."""
        models = object_models(self.objects(scene), self.millimetres)
        files = {f"models/obj_{obj_id:06d}.ply": ply_bytes(model) for obj_id, model in sorted(models.items())}
        files["models/models_info.json"] = bop_json({obj_id: model_info(model) for obj_id, model in models.items()})
        width, height = scene.image.width, scene.image.height
        K = scene.camera.intrinsics(width, height)
        if K is not None:
            camera = {"cx": float(K[0, 2]), "cy": float(K[1, 2]), "depth_scale": self.depth_scale,
                      "fx": float(K[0, 0]), "fy": float(K[1, 1]), "height": height, "width": width}
            files["camera.json"] = json.dumps(camera, sort_keys=True, indent=2).encode()
        return files

    def folders(self) -> list[str]:
        return ["models", *(f"{SCENE_FOLDER}/{name}" for name in ("rgb", "depth", "mask", "mask_visib"))]

    def index_files(self, scene, records: list[dict]) -> dict:
        """The scene's JSON files from every view's record, in view order (deterministic bytes)."""
        width, height = scene.image.width, scene.image.height
        camera = {r["im_id"]: r["scene_camera"] for r in records}
        gt = {r["im_id"]: r["scene_gt"] for r in records}
        info = {r["im_id"]: r["scene_gt_info"] for r in records}
        obj_ids = sorted({shape.label for shape in self.objects(scene)})
        coco = {
            "info": {"description": f"pyclray data set, {SPLIT} scene {SCENE_ID}", "url": "", "version": "1.0",
                     "contributor": ""},
            "licenses": [],
            "categories": [{"id": obj_id, "name": str(obj_id), "supercategory": "pyclray"} for obj_id in obj_ids],
            "images": [{"id": r["im_id"], "file_name": f"rgb/{r['im_id']:06d}.png", "width": width, "height": height,
                        "license": 1, "coco_url": "", "flickr_url": ""} for r in records],
            "annotations": [a for r in records for a in r["coco_annotations"]],
        }
        return {
            f"{SCENE_FOLDER}/scene_camera.json": bop_json(camera),
            f"{SCENE_FOLDER}/scene_gt.json": bop_json(gt),
            f"{SCENE_FOLDER}/scene_gt_info.json": bop_json(info),
            f"{SCENE_FOLDER}/scene_gt_coco.json": json.dumps(coco).encode(),
        }

    # -- one view ---------------------------------------------------------------------------------
    def encode(self, scene, rendered) -> EncodedView:
        k, camera, images = rendered.index, rendered.camera, rendered.images
        ids = images["id"]
        height, width = ids.shape
        mm = self.millimetres
        K = camera.intrinsics(width, height)
        pose = camera.pose()
        R_w2c = pose[:3, :3].T
        t_w2c = -R_w2c @ pose[:3, 3]  # scene units
        # depth: z along the optical axis, in mm / depth_scale, rounded; a miss or a depth beyond
        # uint16 is 0 (BOP's "no measurement")
        with np.errstate(invalid="ignore", over="ignore"):
            scaled = np.round(images["zdepth"].astype(np.float64) * (mm / self.depth_scale))
        valid = np.isfinite(scaled) & (scaled <= DEPTH_MAX)
        depth = np.where(valid, scaled, 0).astype(np.uint16)
        name = f"{k:06d}"
        files = {f"{SCENE_FOLDER}/rgb/{name}.png": lambda: png_bytes(srgb_preview(images["shaded"])),
                 f"{SCENE_FOLDER}/depth/{name}.png": lambda: png_bytes(depth)}
        gts, infos, annotations = [], [], []
        shapes = scene.shapes
        object_ids = self.object_ids(scene)
        cached = getattr(self, "_poses", None)
        if cached is None or cached[0] is not shapes:  # the objects' rigid poses, once per scene
            cached = self._poses = (shapes, {i: model_pose(shapes[i])[0] for i in object_ids})
        for gt_id, (shape_id, (alone, outside_count, outside_box)) in enumerate(zip(object_ids, rendered.alone)):
            shape = shapes[shape_id]
            visible = ids == shape_id
            mask = alone | visible  # (the object alone covers what it shows among the others)
            world_from_model = cached[1][shape_id]
            R_m2c = R_w2c @ world_from_model[:3, :3]
            t_m2c = (R_w2c @ world_from_model[:3, 3] + t_w2c) * mm
            gts.append({"cam_R_m2c": R_m2c.ravel().tolist(), "cam_t_m2c": t_m2c.tolist(), "obj_id": shape.label})
            # the counts and boxes over the box of the amodal mask, which holds the visible mask
            whole = mask_box(mask)
            x0, y0, x1, y1 = whole or (0, 0, -1, -1)
            inside, seen_inside = mask[y0:y1 + 1, x0:x1 + 1], visible[y0:y1 + 1, x0:x1 + 1]
            count_visible = int(np.count_nonzero(seen_inside))
            count_all = int(np.count_nonzero(inside)) + outside_count
            seen = mask_box(seen_inside)
            if seen is not None:
                seen = (seen[0] + x0, seen[1] + y0, seen[2] + x0, seen[3] + y0)
            box_all = box_visible = [-1, -1, -1, -1]
            if count_visible > 0:  # as calc_gt_info: no boxes for an object not seen
                corners = [c for c in (whole, outside_box) if c is not None]
                box_all = bbox([c[0] for c in corners] + [c[2] for c in corners],
                               [c[1] for c in corners] + [c[3] for c in corners])
                box_visible = bbox([seen[0], seen[2]], [seen[1], seen[3]])
            infos.append({
                "bbox_obj": box_all, "bbox_visib": box_visible, "px_count_all": count_all,
                "px_count_valid": int(np.count_nonzero(depth[y0:y1 + 1, x0:x1 + 1][inside])),
                "px_count_visib": count_visible,
                "visib_fract": count_visible / count_all if count_all > 0 else 0.0,
            })
            stem = f"{name}_{gt_id:06d}"
            files[f"{SCENE_FOLDER}/mask/{stem}.png"] = (lambda m=mask: png_bytes(mask_image(m)))
            files[f"{SCENE_FOLDER}/mask_visib/{stem}.png"] = (lambda m=visible: png_bytes(mask_image(m)))
            if count_visible > 0:  # calc_gt_coco: an annotation per instance seen, ids counting every instance
                annotations.append({
                    "id": k * len(object_ids) + gt_id + 1, "image_id": k, "category_id": shape.label, "iscrowd": 0,
                    "area": count_visible,
                    "bbox": [seen[0], seen[1], seen[2] - seen[0] + 1, seen[3] - seen[1] + 1],
                    "segmentation": coco_rle(visible, (seen[0], seen[2])), "width": width, "height": height,
                })
        record = {
            "im_id": k,
            "scene_camera": {"cam_K": K.ravel().tolist(), "cam_R_w2c": R_w2c.ravel().tolist(),
                             "cam_t_w2c": (t_w2c * mm).tolist(), "depth_scale": self.depth_scale},
            "scene_gt": gts, "scene_gt_info": infos, "coco_annotations": annotations,
        }
        return EncodedView(k, files, record)
