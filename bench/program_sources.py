"""The closest-point query's programs at the default lane width (8 lanes fp32, 4 fp64 on PoCL's
CPU), written out to compare two checkouts' (a change for one lane width must leave the CPU's
programs as they were):

    cd CHECKOUT && PYTHONPATH=. python /path/to/bench/program_sources.py write OUT_DIR
    python bench/program_sources.py compare MAIN_DIR BRANCH_DIR

write: closest_points, distance, signed_distance and occupancy (both signs) on the bunny alone and
on a mixed scene (a closed and an open mesh, a sphere batch, a sphere, a box, a cylinder, a disk, a
plane), fp32 and fp64; each closest variant's source with and without PoCL's inlining
(Variant.source(inline_builtins)), one file each. compare: how many files are the same text, and
the same after the C preprocessor (cpp -P: comments, directives and unused branches gone, the
program the compiler sees). Only pyclray is imported: the script runs against any checkout.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np


def write(out: Path) -> None:
    import pyclray
    from pyclray.engine.launch import programs

    os.environ.pop("PYCLRAY_LANES", None)  # the default lane width
    out.mkdir(parents=True, exist_ok=True)
    built = []
    original = programs._build

    def recording(ctx, variant):
        built.append(variant)
        return original(ctx, variant)

    programs._build = recording
    base = pyclray.Mesh.load(Path(pyclray.__file__).resolve().parent.parent / "scenes" / "meshes" / "bunny.ply")
    rng = np.random.default_rng(0)
    scenes = {
        "bunny": (pyclray.Mesh(base.vertices, base.faces),),
        "mixed": (pyclray.Mesh(base.vertices, base.faces), pyclray.Spheres(rng.uniform(-1, 1, (50, 3)), np.full(50, 0.01)),
                  pyclray.Sphere((0, 0, 0), 0.1), pyclray.Box((0, 0, 0), (0.1, 0.1, 0.1)),
                  pyclray.Cylinder((0, 0, 0), (1, 0, 0), 0.1), pyclray.Disk((0, 0, 0), (0, 0, 1), 0.1),
                  pyclray.Plane((0, 1, 0), 0.0),
                  pyclray.Mesh(base.vertices, base.faces[: len(base.faces) // 2], translate=(2, 0, 0))),
    }
    points = rng.uniform(-1, 1, (200, 3))
    for name, shapes in scenes.items():
        scene = pyclray.Scene(pyclray.Camera((0, 0, 5), (0, 0, 0)), pyclray.Image(8, 8), shapes)
        for precision in ("fp32", "fp64"):
            programs.clear()
            built.clear()
            pyclray.closest_points(scene, points, precision=precision)
            pyclray.distance(scene, points, precision=precision)
            pyclray.signed_distance(scene, points, precision=precision)
            for sign in ("parity", "winding"):
                pyclray.occupancy(scene, points, sign, precision=precision)
            for variant in built:
                if variant.query == "closest":
                    for inline in (False, True):
                        key = f"{name}-{precision}-{'-'.join(variant.aovs)}-{'inlined' if inline else 'plain'}"
                        (out / f"{key}.cl").write_text(variant.source(inline_builtins=inline))
    programs.clear()
    print(f"{len(list(out.glob('*.cl')))} programs of {Path(pyclray.__file__).parent} in {out}")


def preprocessed(path: Path) -> bytes:
    return subprocess.run(["cpp", "-P", "-w", str(path)], capture_output=True, check=False).stdout


def compare(a: Path, b: Path) -> None:
    names = sorted(p.name for p in a.glob("*.cl"))
    assert names == sorted(p.name for p in b.glob("*.cl")), "the two checkouts built other variants"
    text = sum((a / n).read_bytes() == (b / n).read_bytes() for n in names)
    after = [n for n in names if preprocessed(a / n) == preprocessed(b / n)]
    print(f"{len(names)} programs: {text} the same text, {len(after)} the same after cpp -P")
    for n in sorted(set(names) - set(after)):
        print(f"  differs: {n}")


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "write":
        write(Path(sys.argv[2]))
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        compare(Path(sys.argv[2]), Path(sys.argv[3]))
    else:
        sys.exit(__doc__)
