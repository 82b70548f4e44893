"""The orthographic camera's images (a render by casting, its shaded image shaded on the host with
occluded shadow rays: engine/queries/shade.py) against the perspective render of the same scene, in
one process, in blocks of calls with short pauses between the systems (docs/benchmarks.md).

    python -m bench.orthographic
"""
import dataclasses
import time

import numpy as np

import pyclray


def main(size: int = 256, blocks: int = 3, calls: int = 3) -> dict:
    scene = pyclray.load_scene("scenes/tp02-lit.toml").with_size(size, size)
    ortho = dataclasses.replace(scene, camera=pyclray.Orthographic(scene.camera.eye, scene.camera.target, height=5.0))
    cases = {"perspective shaded": (scene, ("shaded",)), "orthographic shaded": (ortho, ("shaded",)),
             "orthographic depth": (ortho, ("depth",))}
    for view, aovs in cases.values():  # the programs built, the handle prepared
        pyclray.render(view, aovs=aovs)
    times = {name: [] for name in cases}
    for _ in range(blocks):
        for name, (view, aovs) in cases.items():
            start = time.perf_counter()
            for _ in range(calls):
                pyclray.render(view, aovs=aovs)
            times[name].append((time.perf_counter() - start) / calls)
            time.sleep(0.2)
    return {name: float(np.median(t)) for name, t in times.items()}


if __name__ == "__main__":
    found = main()
    for name, seconds in found.items():
        print(f"{name}: median {1e3 * seconds:.1f} ms, {seconds / found['perspective shaded']:.1f}x perspective shaded")
