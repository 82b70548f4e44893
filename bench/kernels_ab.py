"""Render workloads with this checkout's kernels against another checkout's kernels, in one process,
alternating (issue 42: the exact pixel rays' cost on flat shapes and mesh instances).

    .venv/bin/python bench/kernels_ab.py --against /path/to/other/checkout [--rounds 6] [--block 7]
    .venv/bin/python bench/kernels_ab.py --without-pixel-exact [--rounds 6] [--block 7]

The host side (scenes, structs, the per-view pass) is this checkout's; only the kernels/ folder is
swapped (pyclray.engine.launch.programs.kernel_dir), so the other checkout's kernels must read the
structs this one packs (fields this one added are ignored there): a checkout from before a change
of the structs or of the kernels' files cannot be the other side. --without-pixel-exact makes the
other side this checkout's own kernels with the exact pixel rays compiled out (a copy in a
temporary folder whose kernels/lanes.h never defines PYCLRAY_PIXEL_EXACT: the camera rays, flat
shapes and instances as before issue 42's item 1, everything else the same). Both sides'
kernels are built once and kept (programs' in-memory kernels swapped with the folder: a switch
rebuilds nothing); each workload is then timed in blocks of renders (median wall
and process CPU time; --block renders, more where those would take less than --block-ms), one
block per side in each round, the sides' order alternating from round to round. The report is the
median over the rounds of each side's time and of the ratio this / other of each round's two
blocks, which run side by side in time (a loaded machine's slow drift cancels in it).
bench/engine_ab.py is the whole-engine comparison (other processes, other host code); this one
isolates the kernels on the workloads engine_ab has none of: flat shapes in numbers and mesh
instances. 512x512, fp32, depth, normal and id:

- tp02: scenes/tp02.toml (a ground plane and three balls);
- 100k spheres: bench/engine_ab.py's field (a ground plane and a batch of 100,000 spheres);
- boxes and disks: a ground plane, 121 boxes and 121 disks seen from 3 units above it;
- 20 instances: scenes/meshes/bunny.ply placed 20 times on a ground plane (mesh instances).
"""
from __future__ import annotations

import argparse
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import pyclray
from pyclray.engine.launch import programs

REPO = Path(__file__).resolve().parent.parent


def workloads(size: int = 512) -> dict:
    tp02 = pyclray.load_scene(REPO / "scenes" / "tp02.toml").with_size(size, size)
    rng = np.random.default_rng(0)
    centers = rng.uniform((-50.0, 0.0, -50.0), (50.0, 4.0, 50.0), (100_000, 3))
    radii = rng.uniform(0.05, 0.3, 100_000)
    field = pyclray.Scene(pyclray.Camera((0.0, 30.0, 80.0), (0.0, 0.0, 0.0), fov=50.0), pyclray.Image(size, size),
                          (pyclray.Plane((0.0, 1.0, 0.0), 0.0), pyclray.Spheres(centers, radii)))
    boxes = [pyclray.Box(center=(float(x), 0.5, float(z)), size=(0.8, 1.0, 0.8), axis=(0, 1, 0), angle=float(x * 7 + z))
             for x in range(-10, 11, 2) for z in range(-10, 11, 2)]
    disks = [pyclray.Disk(center=(x + 1.0, 0.01, z + 1.0), normal=(0, 1, 0), radius=0.4)
             for x in range(-10, 11, 2) for z in range(-10, 11, 2)]
    flat = pyclray.Scene(pyclray.Camera((0.0, 3.0, 14.0), (0.0, 0.0, 0.0), fov=60.0), pyclray.Image(size, size),
                         [pyclray.Plane((0.0, 1.0, 0.0), 0.0)] + boxes + disks)
    bunny = pyclray.Mesh.load(REPO / "scenes" / "meshes" / "bunny.ply")
    instances = pyclray.Scene(pyclray.Camera((0.0, 0.3, 0.5), (0.0, 0.1, 0.0), fov=40.0), pyclray.Image(size, size),
                              [pyclray.Plane((0.0, 1.0, 0.0), 0.033)]
                              + [bunny.placed(translate=(0.2 * i - 0.4, 0.0, -0.2 * j)) for i in range(5) for j in range(4)])
    return {"tp02": tp02, "100k spheres": field, "boxes and disks": flat, "20 instances": instances}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    other = parser.add_mutually_exclusive_group(required=True)
    other.add_argument("--against", help="the other checkout's root (its pyclray/engine/kernels/ is read)")
    other.add_argument("--without-pixel-exact", action="store_true",
                       help="the other side: this checkout's kernels with PYCLRAY_PIXEL_EXACT compiled out")
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--block", type=int, default=7)
    parser.add_argument("--block-ms", type=float, default=100.0,
                        help="a block has at least --block renders and lasts about this long at least (tp02's 1 ms renders)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as temporary:
        if args.without_pixel_exact:
            other_kernels = without_pixel_exact(programs.kernel_dir(), Path(temporary) / "kernels")
        else:
            other_kernels = Path(args.against) / "pyclray" / "engine" / "kernels"
        compare({"this": programs.kernel_dir(), "other": other_kernels}, args.rounds, args.block, args.block_ms / 1e3)


def without_pixel_exact(kernels: Path, copy: Path) -> Path:
    """A copy of the kernels folder whose lanes.h never defines PYCLRAY_PIXEL_EXACT."""
    shutil.copytree(kernels, copy)
    lanes = copy / "lanes.h"
    text = lanes.read_text(encoding="utf-8")
    define = "#define PYCLRAY_PIXEL_EXACT 1\n"
    if text.count(define) != 1:
        raise SystemExit(f"{kernels / 'lanes.h'}: expected one line {define.strip()!r}")
    lanes.write_text(text.replace(define, ""), encoding="utf-8")
    return copy


def compare(folders: dict, rounds: int, block: int, block_s: float) -> None:
    """Each workload rendered with each side's kernels in alternating blocks; the table of the
    medians and of the median ratio of adjacent blocks."""
    scenes = workloads()
    aovs = ("depth", "normal", "id")
    built = {}
    for side, folder in folders.items():  # each side's kernels built once and kept: a switch costs nothing
        programs.kernel_dir = lambda folder=folder: folder
        programs._programs = {}
        for scene in scenes.values():
            pyclray.render(scene, aovs=aovs)
        built[side] = programs._programs

    def use(side):
        programs.kernel_dir = lambda folder=folders[side]: folder
        programs._programs = built[side]

    times = {(w, side): [] for w in scenes for side in folders}
    for name, scene in scenes.items():
        w0 = time.perf_counter()
        pyclray.render(scene, aovs=aovs)  # not timed: it sizes the block
        renders = max(block, int(block_s / max(time.perf_counter() - w0, 1e-6)))
        for r in range(rounds):
            for side in (("this", "other") if r % 2 == 0 else ("other", "this")):
                use(side)
                pyclray.render(scene, aovs=aovs)  # not timed: the switch
                wall, cpu = [], []
                for _ in range(renders):
                    c0, w0 = time.process_time(), time.perf_counter()
                    pyclray.render(scene, aovs=aovs)
                    cpu.append(time.process_time() - c0)
                    wall.append(time.perf_counter() - w0)
                times[(name, side)].append((statistics.median(wall) * 1e3, statistics.median(cpu) * 1e3))
                time.sleep(0.1)
    print("| workload | this: wall ms (CPU) | other: wall ms (CPU) | this / other: wall | CPU |")
    print("|---|---|---|---|---|")
    for name in scenes:
        this, other = np.array(times[(name, "this")]), np.array(times[(name, "other")])
        ratio = np.median(this / other, axis=0)  # each round's blocks side by side in time
        this, other = np.median(this, axis=0), np.median(other, axis=0)
        print(f"| {name} | {this[0]:.2f} ({this[1]:.2f}) | {other[0]:.2f} ({other[1]:.2f}) | "
              f"{ratio[0]:.3f} | {ratio[1]:.3f} |")


if __name__ == "__main__":
    main()
