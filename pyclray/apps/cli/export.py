"""`pyclray export`: a scene (TOML or Mitsuba XML) written as a Mitsuba 3 XML scene
(pyclray.reference.mitsuba_export; Mitsuba itself is not needed)."""
from __future__ import annotations

from pathlib import Path

from .options import BadInput, image_size, load, time_value


def add_command(subparsers) -> None:
    parser = subparsers.add_parser(
        "export",
        help="write a scene as a Mitsuba 3 XML scene",
        description="Write SCENE as a Mitsuba 3 XML scene: the same camera (a perspective sensor, one ray per pixel "
        "centre), shapes (their Mitsuba counterparts: a plane as a large disk, a capped cylinder as a cylinder and "
        "two disks, a box as a cube, a batch of spheres as spheres), colours (two-sided diffuse BSDFs) and lights "
        "(point and directional emitters), rendered by the aov integrator around the direct integrator. "
        "Mitsuba is not needed to write it.",
    )
    parser.add_argument("scene", metavar="SCENE", help="scene file (TOML or Mitsuba XML)")
    parser.add_argument("-o", "--output", required=True, metavar="OUT.xml",
                        help="the Mitsuba scene to write (a triangle mesh goes to OUT.ID.ply beside it)")
    parser.add_argument("--size", type=image_size, metavar="WxH", help="override the scene's image size")
    parser.add_argument("--time", type=time_value, metavar="T", help="the time (seconds) of an animated scene")
    parser.set_defaults(run=run)


def run(args) -> int:
    out = Path(args.output)
    if out.suffix.lower() != ".xml":
        raise BadInput(f"-o {args.output}: expected OUT.xml (a Mitsuba 3 scene)")
    scene_path = Path(args.scene)
    if out.resolve() == scene_path.resolve() or (out.exists() and scene_path.exists() and out.samefile(scene_path)):
        raise BadInput(f"-o {args.output}: is the scene file itself; give another output path")
    from ...io.files import check_target, replace_together

    check_target(out)
    scene = load(args.scene, args.size, args.time)
    from ...reference.mitsuba import sensor_of
    from ...reference.mitsuba_export import export_files

    sensor_of(scene)  # a camera Mitsuba has no sensor for (fx != fy) is bad input
    files = export_files(scene, out)  # the XML and a PLY file per triangle mesh, replaced together
    if any(path.resolve() == scene_path.resolve() for path in files):
        raise BadInput(f"-o {args.output}: a file it writes, {next(p for p in files if p.resolve() == scene_path.resolve())}, "
                       "is the scene file itself; give another output path")
    with replace_together(list(files)) as temporaries:
        for temporary, content in zip(temporaries, files.values()):
            Path(temporary).write_bytes(content)
    print("wrote " + ", ".join(map(str, files)))
    return 0
