"""`pyclray render`: a scene's images to one OpenEXR file, an .npz of numpy arrays or a PNG preview
(by -o's extension) and PNG previews, streamed in bands of rows (bounded memory), here or on a Dask
cluster."""
from __future__ import annotations

import time
from pathlib import Path

from ...model.aovs import RENDER_AOVS
from .options import BadInput, add_cluster_options, aov_list, cluster_module, image_size, load, time_value
from .texts import EXIT_STATUS_HELP


def _band_renderer(scene, aovs, precision, device, time=None):
    """window (x0, y0, w, h) -> the images of that part of the image (pyclray.render's window; time:
    of the animated scene, for its flow)."""
    from ...engine.api import render

    return lambda window: render(scene, aovs=aovs, precision=precision, device=device, window=window, time=time)


def _outputs(args) -> tuple[str, tuple[str, ...], list[Path]]:
    """The output's format (from -o's extension), the AOVs it holds and every file the command will
    write, checked before the scene is read: another extension, --png beside a .png, a .png of an
    AOV without a preview, or a file that is the scene itself is a one-line error."""
    from ...io import png
    from ...io.bands import output_format
    from ...model.errors import RequestError

    if args.output is None:  # the scene's name as an .exr, here (not beside the scene)
        args.output = f"{Path(args.scene).stem}.exr"
    out, scene = Path(args.output), Path(args.scene)

    def is_scene(target: Path) -> bool:
        return target.resolve() == scene.resolve() or (target.exists() and scene.exists() and target.samefile(scene))

    if is_scene(out):
        raise BadInput(f"-o {args.output}: is the scene file itself; give another output path")
    try:
        kind = output_format(out)
    except RequestError:
        raise BadInput(f"-o {args.output}: expected OUT.exr (OpenEXR channels), OUT.npz (numpy arrays, with the "
                       "camera's K and pose), OUT.png (the preview of one image) or OUT.ply (the hit pixels as a point cloud); the "
                       "format follows the extension") from None
    aovs = args.aov
    if kind == "png":
        if args.png:
            raise BadInput(f"--png: -o {args.output} is itself a preview; --png writes previews beside an .exr or .npz")
        if aovs[0] not in png.PREVIEWS:
            raise BadInput(f"-o {args.output}: a .png is the preview of the first image of --aov, and {aovs[0]} has "
                           f"none (those with one: {', '.join(png.PREVIEWS)})")
        aovs = aovs[:1]  # the one image a .png shows: the others are not rendered
        targets = [out]
    else:
        targets = [out, *(png.preview_paths(out, aovs).values() if args.png else ())]
    for target in targets[1:]:  # a preview's name too (a scene file named OUT.depth.png)
        if is_scene(target):
            raise BadInput(f"-o {args.output}: its preview {target} is the scene file itself; give another output path")
    return kind, aovs, targets


def _camera(scene):
    """(K, pose) of the scene's camera at its image size: the EXR header's (io/exr.py) and the
    .npz's K and pose arrays."""
    # (K None for a model without one: its pose alone)
    return scene.camera.intrinsics(scene.image.width, scene.image.height), scene.camera.pose()


def _written(kind: str, aovs, intrinsics=True) -> str:
    """What the files hold, for the last line: the EXR's channels, the .npz's arrays, the AOV a .png shows."""
    from ...io import exr
    from ...model.aovs import empty_images

    if kind == "exr":
        return ", ".join(exr.exr_channel_arrays(empty_images(aovs)))
    if kind == "npz":
        return ", ".join((*aovs, "K", "pose") if intrinsics else (*aovs, "pose"))  # (no K: a model without one)
    return f"the {aovs[0]} preview"


def run(args) -> int:
    from ...io import files
    from ...io.bands import band_rows, write_images
    from ...io.progress import progress, seconds

    if args.output is not None and Path(args.output).suffix.lower() == ".ply":  # a point cloud of the hit pixels
        return _render_cloud(args)
    # the options first: a wrong -o costs no scene read, no device and no render
    kind, aovs, targets = _outputs(args)
    for target in targets:  # a path that cannot be written costs no time either
        files.check_target(target)
    out = targets[0]
    on_cluster = args.workers is not None or args.scheduler is not None
    if on_cluster:
        cluster_module()  # installed? (says what to install before the scene is read)
    scene = load(args.scene, args.size, args.time)
    # flow goes to the next frame: the animated scene and the time (scene.at(T) does not move)
    moving = load(args.scene, args.size) if args.time is not None and "flow" in aovs else None
    width, height = scene.image.width, scene.image.height
    if on_cluster:
        return _render_on_cluster(args, scene, out, aovs, kind, moving)
    render_band = _band_renderer(moving or scene, aovs, args.precision, args.device, args.time if moving else None)
    rows = band_rows(width)
    spent = {"render": 0.0}
    devices = []

    def bands():
        """The image in bands of whole rows, rendered as they are written (bounded memory)."""
        for top in range(0, height, rows):
            count = min(rows, height - top)
            start = time.perf_counter()
            frame = render_band((0, top, width, count))
            spent["render"] += time.perf_counter() - start
            devices.append(frame.device)
            yield frame
            bar.update(count)

    start = time.perf_counter()
    with progress(height, desc="pyclray render", unit="row") as bar:
        written = write_images(out, bands(), width=width, height=height, aovs=aovs, previews=args.png,
                               comment=f"pyclray render of {args.scene}", camera=_camera(scene))
    total = time.perf_counter() - start
    print(
        f"rendered {args.scene} ({width}x{height}, {args.precision}, {devices[0] if devices else '?'}) in "
        f"{seconds(total)} (render {seconds(spent['render'])}, write {seconds(total - spent['render'])}); "
        f"wrote {', '.join(map(str, written))} [{_written(kind, aovs, _camera(scene)[0] is not None)}]"
    )
    return 0


# what a point cloud of a render holds (io/ply.py): each hit pixel's world position, normal, id and label
CLOUD_AOVS = ("position", "normal", "id", "label")


def _render_cloud(args) -> int:
    """`pyclray render SCENE -o OUT.ply`: the hit pixels as a binary PLY point cloud (x y z, nx ny nz,
    id, label, row, column), rendered in bands of rows, written once whole."""
    import numpy as np

    from ...io import files
    from ...io.ply import write_ply
    from ...io.progress import progress, seconds

    out, scene_path = Path(args.output), Path(args.scene)
    if out.resolve() == scene_path.resolve() or (out.exists() and scene_path.exists() and out.samefile(scene_path)):
        raise BadInput(f"-o {args.output}: is the scene file itself; give another output path")
    if args.png:
        raise BadInput(f"--png: -o {args.output} is a point cloud; --png writes previews beside an .exr or .npz")
    if args.workers is not None or args.scheduler is not None:
        raise BadInput(f"-o {args.output}: a point cloud is rendered here; --workers and --scheduler write .exr, "
                       ".npz or .png")
    files.check_target(out)
    scene = load(args.scene, args.size, args.time)
    width, height = scene.image.width, scene.image.height
    render_band = _band_renderer(scene, CLOUD_AOVS, args.precision, args.device)
    rows = _band_rows(width)
    parts: dict[str, list] = {name: [] for name in CLOUD_AOVS}
    start = time.perf_counter()
    with progress(height, desc="pyclray render", unit="row") as bar:
        for top in range(0, height, rows):
            count = min(rows, height - top)
            band = render_band((0, top, width, count))
            for name in CLOUD_AOVS:
                parts[name].append(band[name])
            bar.update(count)
    frame = {name: np.concatenate(arrays) for name, arrays in parts.items()}
    write_ply(out, frame, comment=f"pyclray render of {args.scene}")
    hits = int((frame["id"] >= 0).sum())
    print(f"rendered {args.scene} ({width}x{height}, {args.precision}) in {seconds(time.perf_counter() - start)}; "
          f"wrote {out} [{hits} hit pixels: x y z nx ny nz id label row column]")
    return 0


def _band_rows(width: int) -> int:
    from ...io.bands import band_rows

    return band_rows(width)


def _render_on_cluster(args, scene, out, aovs, kind, moving=None) -> int:
    """`pyclray render --workers N | --scheduler ADDRESS`: the image's bands of whole rows are the
    tasks (pyclray/apps/cluster.py); they come back in order and are streamed into the files as a local
    render streams its bands, so the files are the same bytes."""
    from ...io.bands import write_images
    from ...io.progress import progress, seconds

    cluster = cluster_module()
    width, height = scene.image.width, scene.image.height
    start = time.perf_counter()
    try:
        with cluster.connect(args.workers, args.scheduler) as client:
            start_time = time.perf_counter() - start
            where = cluster.describe(client)
            rows = cluster.band_rows(width, height)
            devices = []

            def received():
                for band in cluster.render_bands(client, moving or scene, aovs, args.precision, args.device, rows, bar,
                                                 time=args.time if moving else None):
                    devices.append(band.device)
                    yield band

            with progress(-(-height // rows), desc="pyclray render", unit="band") as bar:
                written = write_images(out, received(), width=width, height=height, aovs=aovs, previews=args.png,
                                       comment=f"pyclray render of {args.scene}", camera=_camera(scene))
    except cluster.ClusterError as error:
        raise BadInput(str(error)) from None
    total = time.perf_counter() - start
    count = -(-height // rows)
    print(
        f"rendered {args.scene} ({width}x{height}, {args.precision}, {devices[0] if devices else '?'}) in "
        f"{seconds(total)} (cluster start {seconds(start_time)}, {count} band{'s' if count != 1 else ''} of {rows} rows "
        f"on {where}, rendered there and written here as they came); wrote {', '.join(map(str, written))} "
        f"[{_written(kind, aovs, _camera(scene)[0] is not None)}]"
    )
    return 0


def add_command(commands) -> None:
    render = commands.add_parser(
        "render",
        help="render a scene to an OpenEXR file, an .npz of numpy arrays or a PNG preview",
        description="Render SCENE with one ray per pixel centre. -o decides the format from its extension: "
        "OUT.exr (one OpenEXR file with the channels Z (distance from the eye, inf on a miss), N.X N.Y N.Z "
        "(unit world normal, 0 on a miss), id (UINT holding the int32 shape id; 4294967295 = -1 on a miss), "
        "and as asked zdepth (depth along the optical axis), P.X P.Y P.Z (world hit point), R G B (shaded, "
        "linear RGB), primitive (UINT, the triangle or batch member hit), bary.u bary.v (barycentric: (u, v) "
        "in the triangle hit) and label (UINT, the shape's label)); OUT.npz (every image as a numpy array under its "
        "name, in its own type, with the camera's intrinsics K (3x3) and pose (4x4 camera-to-world, OpenCV's "
        "convention), deflated as numpy.savez_compressed writes it); OUT.png (the preview of the first image of --aov). "
        "Z, N and the other float images are 32-bit FLOAT channels also for --precision fp64 (rounded to "
        "float32): OpenEXR has no 64-bit "
        "float channel type (an .npz keeps float64). Large images are rendered and written in bands of rows, so "
        "memory stays bounded; a progress bar shows on a terminal.",
        epilog=EXIT_STATUS_HELP,
    )
    render.add_argument("scene", metavar="SCENE", help="scene file (TOML, or Mitsuba 3 XML)")
    render.add_argument("-o", "--output", metavar="OUT.exr|OUT.npz|OUT.png|OUT.ply",
                        help="the file to write; its extension decides the format (.exr, .npz, .png, or .ply: the "
                        "hit pixels as a point cloud with normals, id, label, row and column); "
                        "default: SCENE's name with .exr, in the current folder (scenes/tp02.toml: ./tp02.exr)")
    render.add_argument(
        "--aov", type=aov_list, default=("depth", "normal", "id"), metavar="LIST",
        help=f"comma-separated images to compute, of {', '.join(RENDER_AOVS)} (default: depth,normal,id; flow of an "
        "animated scene needs --time); fewer is faster",
    )
    render.add_argument(
        "--png", action="store_true",
        help="also write a PNG preview of each image beside OUT.exr or OUT.npz: OUT.depth.png and "
        "OUT.zdepth.png (near bright, far dark, misses black), OUT.normal.png (n*0.5+0.5), OUT.id.png (a "
        "colour per shape, misses black), OUT.label.png (a colour per label), OUT.shaded.png (clamped, sRGB)",
    )
    render.add_argument(
        "--precision", choices=("fp32", "fp64"), default="fp32",
        help="kernel precision (default fp32); fp64 depth and normals are stored in the EXR as 32-bit floats",
    )
    render.add_argument("--size", type=image_size, metavar="WxH",
                        help="override the scene's image size (each side at most 65536); a camera from "
                        "intrinsics scales its K with the image")
    render.add_argument("--time", type=time_value, metavar="T", help="render the scene at time T (seconds) of its [animation]")
    render.add_argument(
        "--device", metavar="DEV",
        help="OpenCL device: P:D indices (see `pyclray devices`) or part of its name; default "
        "$PYOPENCL_CTX, else PoCL's CPU device",
    )
    add_cluster_options(render, "the image's bands of rows")
    render.set_defaults(run=run)
