"""`pyclray render`: a scene's images to one OpenEXR file and PNG previews, streamed in bands of
rows (bounded memory), here or on a Dask cluster."""
from __future__ import annotations

import time
from pathlib import Path

from .options import BadInput, add_cluster_options, aov_list, cluster_module, image_size, load, time_value
from .texts import EXIT_STATUS_HELP


def _band_renderer(scene, aovs, precision, device):
    """window (x0, y0, w, h) -> the images of that part of the image (pyclray.render's window)."""
    from ...engine.render import render

    return lambda window: render(scene, aovs=aovs, precision=precision, device=device, window=window)


def _camera(scene):
    """(K, pose) of the scene's camera at its image size: the EXR header's (io/exr.py)."""
    return scene.camera.intrinsics(scene.image.width, scene.image.height), scene.camera.pose()


def run(args) -> int:
    from ...io import exr, files, png
    from ...io.bands import band_rows, write_images
    from ...io.progress import progress, seconds
    from ...model.aovs import empty_images

    out = Path(args.output)
    scene = load(args.scene, args.size, args.time)
    targets = [out, *(png.preview_paths(out, args.aov).values() if args.png else ())]
    for target in targets:  # before the render: a path that cannot be written costs no time
        files.check_target(target)
    if args.workers is not None or args.scheduler is not None:
        return _render_on_cluster(args, scene, out)
    width, height = scene.image.width, scene.image.height
    render_band = _band_renderer(scene, args.aov, args.precision, args.device)
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
        written = write_images(out, bands(), width=width, height=height, aovs=args.aov, previews=args.png,
                                      comment=f"pyclray render of {args.scene}", camera=_camera(scene))
    total = time.perf_counter() - start
    channels = ", ".join(exr.exr_channel_arrays(empty_images(args.aov)))
    print(
        f"rendered {args.scene} ({width}x{height}, {args.precision}, {devices[0] if devices else '?'}) in "
        f"{seconds(total)} (render {seconds(spent['render'])}, write {seconds(total - spent['render'])}); "
        f"wrote {', '.join(map(str, written))} [{channels}]"
    )
    return 0


def _render_on_cluster(args, scene, out) -> int:
    """`pyclray render --workers N | --scheduler ADDRESS`: the image's bands of whole rows are the
    tasks (pyclray/apps/cluster.py); they come back in order and are streamed into the files as a local
    render streams its bands, so the files are the same bytes."""
    from ...io import exr
    from ...io.bands import write_images
    from ...io.progress import progress, seconds
    from ...model.aovs import empty_images

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
                for band in cluster.render_bands(client, scene, args.aov, args.precision, args.device, rows, bar):
                    devices.append(band.device)
                    yield band

            with progress(-(-height // rows), desc="pyclray render", unit="band") as bar:
                written = write_images(out, received(), width=width, height=height, aovs=args.aov,
                                              previews=args.png, comment=f"pyclray render of {args.scene}",
                                              camera=_camera(scene))
    except cluster.ClusterError as error:
        raise BadInput(str(error)) from None
    total = time.perf_counter() - start
    channels = ", ".join(exr.exr_channel_arrays(empty_images(args.aov)))
    count = -(-height // rows)
    print(
        f"rendered {args.scene} ({width}x{height}, {args.precision}, {devices[0] if devices else '?'}) in "
        f"{seconds(total)} (cluster start {seconds(start_time)}, {count} band{'s' if count != 1 else ''} of {rows} rows "
        f"on {where}, rendered there and written here as they came); wrote {', '.join(map(str, written))} [{channels}]"
    )
    return 0


def add_command(commands) -> None:
    render = commands.add_parser(
        "render",
        help="render a scene to a multi-channel OpenEXR file (and PNG previews)",
        description="Render SCENE with one ray per pixel centre and write one OpenEXR file with "
        "the channels Z (distance from the eye, inf on a miss), N.X N.Y N.Z (unit world normal, "
        "0 on a miss), id (UINT holding the int32 shape id; 4294967295 = -1 on a miss), and as asked "
        "zdepth (depth along the optical axis), P.X P.Y P.Z (world hit point) and R G B (shaded, linear RGB). "
        "Z, N and the other float images are 32-bit FLOAT channels also for --precision fp64 (rounded to "
        "float32): OpenEXR has no 64-bit "
        "float channel type. Large images are rendered and written in bands of rows, so memory stays "
        "bounded; a progress bar shows on a terminal.",
        epilog=EXIT_STATUS_HELP,
    )
    render.add_argument("scene", metavar="SCENE", help="scene file (TOML)")
    render.add_argument("-o", "--output", required=True, metavar="OUT.exr", help="the OpenEXR file to write")
    render.add_argument(
        "--aov", type=aov_list, default=("depth", "normal", "id"), metavar="LIST",
        help="comma-separated images to compute: depth,normal,id,zdepth,position,shaded "
        "(default: depth,normal,id); fewer is faster",
    )
    render.add_argument(
        "--png", action="store_true",
        help="also write a PNG preview of each image: OUT.depth.png and OUT.zdepth.png (near bright, far "
        "dark, misses black), OUT.normal.png (n*0.5+0.5), OUT.id.png (a colour per shape, misses black), "
        "OUT.shaded.png (clamped, sRGB)",
    )
    render.add_argument(
        "--precision", choices=("fp32", "fp64"), default="fp32",
        help="kernel precision (default fp32); fp64 depth and normals are stored in the EXR as 32-bit floats",
    )
    render.add_argument("--size", type=image_size, metavar="WxH",
                        help="override the scene's image size (each side at most 65536)")
    render.add_argument("--time", type=time_value, metavar="T", help="render the scene at time T (seconds) of its [animation]")
    render.add_argument(
        "--device", metavar="DEV",
        help="OpenCL device: P:D indices (see `pyclray devices`) or part of its name; default "
        "$PYOPENCL_CTX, else PoCL's CPU device",
    )
    add_cluster_options(render, "the image's bands of rows")
    render.set_defaults(run=run)
