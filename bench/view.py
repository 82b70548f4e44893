"""`pyclray view`'s targets (issue 24), measured in the browser: Debian's chromium driven by
Playwright, the server in a process of its own, as a user runs it.

    python -m bench.view                       # tp02 and 100,000 spheres, 256x256 and 512x512
    python -m bench.view --scenes tp02 --sizes 256
    python -m bench.view --screenshot docs/view.png   # the README's picture of the page

For each scene and size:

- input to paint: a left drag of 90 mouse moves at 60 Hz; for each move, the time from the page
  sending it to the paint of the first image that includes it (the page stamps both with
  performance.now(); the server echoes the newest input each image includes): p50 and p95, and
  the images painted per second while dragging (coarse ones included);
- settle: from the last input to the paint of the full, lossless image, after the mouse is released
  (a drag) and after a wheel turn (no release: the server waits SETTLE for more);
- idle: images painted in the 2 s after it settled (0: nothing runs without input);
- edit to image: the scene file written (in place) with one shape changed, and with only a light
  changed, to the paint of the new image; bad edit to banner: a key made invalid, to #error shown.

The 100,000 spheres are bench/scale.py's field (one pyclray.Spheres batch from an .npz, over a
ground plane), tp02 is scenes/tp02.toml; both lit by one point light. Results go to
view.json under bench.OUT (outside the checkout) and are printed as a Markdown table with the machine's load.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from . import scale

REPO = Path(__file__).resolve().parent.parent
MOVES = 90
MOVE_SECONDS = 1 / 60
LIGHT = '\n[[lights]]\ntype = "point"\nname = "lamp"\nposition = [4.0, 8.0, 6.0]\nintensity = {intensity}\n'

SCENES = {
    "tp02": lambda folder: (REPO / "scenes/tp02.toml").read_text() + LIGHT,
    "spheres100k": lambda folder: _spheres(folder, 100_000),
}
# an edit of one shape, and of a light only, per scene: (old, new) text replaced in the file
SHAPE_EDIT = {"tp02": ("radius = 1.0", "radius = 0.8"), "spheres100k": ("offset = 0.0", "offset = 0.25")}
LIGHT_EDIT = ("intensity = 40.0", "intensity = 60.0")
BAD_EDIT = ("intensity = 40.0", "intensity = -1.0")


def _spheres(folder: Path, count: int) -> str:
    centres, radii = scale.sphere_field(count)
    np.savez(folder / "spheres.npz", centers=centres, radii=radii)
    camera = f"[camera]\neye = {list(scale.EYE)}\ntarget = {list(scale.TARGET)}\nfov = {scale.FOV}\n"
    shapes = ('\n[[shapes]]\ntype = "plane"\nname = "ground"\nnormal = [0.0, 1.0, 0.0]\noffset = 0.0\n'
              '\n[[shapes]]\ntype = "spheres"\nname = "field"\nfile = "spheres.npz"\n')
    return camera + "\n[image]\nwidth = 512\nheight = 512\n" + shapes + LIGHT


def _percentile(values, q):
    return float(np.percentile(values, q)) if values else float("nan")


def measure(browser, folder: Path, name: str, size: int) -> dict:
    import sys

    sys.path.insert(0, str(REPO / "tests"))
    from viewing import Viewer

    scene = folder / f"{name}.toml"
    text = SCENES[name](folder).replace("{intensity}", "40.0")
    scene.write_text(text)
    viewer = Viewer(scene, "--size", f"{size}x{size}")
    context = browser.new_context(bypass_csp=True, viewport={"width": 1200, "height": 900})
    page = context.new_page()
    page.goto(viewer.url)
    paints, count = "window.pyclrayView.paints", "window.pyclrayView.painted"
    # a full image that shows every input so far (not one of the view before the last moves)
    settled = f"n => {count} > n && {paints}.at(-1).lossless && {paints}.at(-1).seq >= window.pyclrayView.latest"
    page.wait_for_function(settled, arg=0, timeout=60_000)
    result = {"scene": name, "size": size}
    try:
        box = page.locator("#view").bounding_box()
        x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        # -- a drag: input to paint, frames per second, settle after the release ------------------
        n = page.evaluate(count)
        page.mouse.move(x, y)
        page.mouse.down()
        start = time.perf_counter()
        for k in range(1, MOVES + 1):
            page.mouse.move(x + 200 * np.sin(k / MOVES * np.pi), y + 40 * np.sin(k / MOVES * 2 * np.pi))
            time.sleep(max(0.0, start + k * MOVE_SECONDS - time.perf_counter()))
        page.mouse.up()
        page.wait_for_function(settled, arg=n, timeout=10_000)
        stats = page.evaluate("window.pyclrayView")
        sent = {int(k): v for k, v in stats["sent"].items()}
        drag = stats["paints"][len(stats["paints"]) - (stats["painted"] - n):]  # the paints since the drag began
        inputs = sorted(sent)[-(MOVES + 1):]  # the moves and the release
        moves = inputs[:-1]
        latencies = []
        for seq in moves:
            first = next((p for p in drag if p["seq"] is not None and p["seq"] >= seq), None)
            if first is not None:
                latencies.append(first["time"] - sent[seq])
        during = [p for p in drag if sent[moves[0]] <= p["time"] <= sent[moves[-1]] + 1]
        seconds = (sent[moves[-1]] - sent[moves[0]]) / 1000
        # the full image of the last move (before the release when the machine let the motion
        # pause longer than the server's SETTLE: then the release brings no new image)
        final = next(p for p in drag if p["lossless"] and p["seq"] >= moves[-1])
        result.update({
            "input_to_paint_p50_ms": _percentile(latencies, 50), "input_to_paint_p95_ms": _percentile(latencies, 95),
            "frames_per_s_dragging": len(during) / seconds, "coarsest_width": min(p["width"] for p in drag),
            "settle_after_release_ms": final["time"] - sent[moves[-1]],
        })
        # -- a wheel turn (no release): the full image SETTLE after the last notch ----------------
        n = page.evaluate(count)
        for _ in range(5):
            page.mouse.wheel(0, -100)
            time.sleep(MOVE_SECONDS)
        page.wait_for_function(settled, arg=n, timeout=10_000)
        last = max(int(k) for k in page.evaluate("Object.keys(window.pyclrayView.sent)"))
        wheel_sent = page.evaluate(f"window.pyclrayView.sent[{last}]")
        final = page.evaluate(f"{paints}.at(-1).time")
        result["settle_after_wheel_ms"] = final - wheel_sent
        # -- idle ----------------------------------------------------------------------------------
        n = page.evaluate(count)
        time.sleep(2.0)
        result["frames_while_idle_2s"] = page.evaluate(count) - n
        # -- edits: a shape, a light, a bad one and back ------------------------------------------
        for label, (old, new) in (("edit_shape_to_image_ms", SHAPE_EDIT[name]), ("edit_light_to_image_ms", LIGHT_EDIT)):
            text = scene.read_text()
            assert old in text, (name, old)
            n = page.evaluate(count)
            t0 = page.evaluate("performance.now()")
            scene.write_text(text.replace(old, new))
            page.wait_for_function(settled, arg=n, timeout=20_000)
            result[label] = page.evaluate(f"{paints}.at(-1).time") - t0
            scene.write_text(text)  # back, and wait for it
            page.wait_for_function(settled, arg=n + 1, timeout=20_000)
        page.evaluate("window.errorAt = null; new MutationObserver(() => { if (document.getElementById('error')"
                      ".textContent && window.errorAt === null) window.errorAt = performance.now(); })"
                      ".observe(document.getElementById('error'), {childList: true, characterData: true, subtree: true})")
        text = scene.read_text()
        t0 = page.evaluate("performance.now()")
        scene.write_text(text.replace(*BAD_EDIT))
        page.wait_for_function("window.errorAt !== null", timeout=10_000)
        result["bad_edit_to_banner_ms"] = page.evaluate("window.errorAt") - t0
        scene.write_text(text)
        page.wait_for_function("document.getElementById('error').textContent === ''", timeout=10_000)
    except Exception:
        context.close()
        print(f"{name} {size}: failed; the server said: {viewer.interrupt()[2]}", flush=True)
        viewer.close()
        raise
    context.close()
    status, _, _ = viewer.interrupt()
    viewer.close()
    result["exit_status"] = status
    return result


TARGETS = [("input_to_paint_p50_ms", "<=", 50), ("input_to_paint_p95_ms", "<=", 100), ("frames_per_s_dragging", ">=", 30),
           ("settle_after_release_ms", "<=", 300), ("settle_after_wheel_ms", "<=", 300), ("frames_while_idle_2s", "<=", 0),
           ("edit_shape_to_image_ms", "<=", 500), ("edit_light_to_image_ms", "<=", 500), ("bad_edit_to_banner_ms", "<=", 1000)]


def table(results: list[dict]) -> str:
    header = "| figure (target) | " + " | ".join(f"{r['scene']} {r['size']}" for r in results) + " |"
    lines = [header, "|---" * (len(results) + 1) + "|"]
    for key, op, goal in TARGETS:
        cells = []
        for r in results:
            value = r[key]
            met = value <= goal if op == "<=" else value >= goal
            cells.append(f"{value:.0f}" + ("" if met else " **(not met)**"))
        lines.append(f"| {key.replace('_', ' ')} ({op} {goal}) | " + " | ".join(cells) + " |")
    lines.append("| coarsest width while dragging | " + " | ".join(str(r["coarsest_width"]) for r in results) + " |")
    return "\n".join(lines)


def screenshot(browser, path: Path) -> None:
    """The page of scenes/shapes-lit.toml, orbited a little (the README's picture)."""
    import sys

    sys.path.insert(0, str(REPO / "tests"))
    from viewing import Viewer

    viewer = Viewer("scenes/shapes-lit.toml", "--size", "512x384", cwd=REPO)
    page = browser.new_context(bypass_csp=True, viewport={"width": 720, "height": 470}).new_page()
    try:
        page.goto(viewer.url)
        settled = "n => window.pyclrayView.painted > n && window.pyclrayView.paints.at(-1).lossless"
        page.wait_for_function(settled, arg=0, timeout=60_000)
        box = page.locator("#view").bounding_box()
        x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        n = page.evaluate("window.pyclrayView.painted")
        page.mouse.move(x, y)
        page.mouse.down()
        for k in range(1, 11):
            page.mouse.move(x - 1.5 * k, y - 0.5 * k)
        page.mouse.up()
        page.wait_for_function(settled, arg=n, timeout=10_000)
        page.screenshot(path=str(path))
    finally:
        page.context.close()
        viewer.interrupt()
        viewer.close()


def main(argv=None) -> None:
    from playwright.sync_api import sync_playwright

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--sizes", nargs="+", type=int, default=[256, 512])
    parser.add_argument("--screenshot", type=Path, metavar="PNG", help="only take the README's picture of the page")
    args = parser.parse_args(argv)
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if args.screenshot:
        with sync_playwright() as driver:
            browser = driver.chromium.launch(executable_path=chromium, args=["--headless=new", "--no-sandbox"])
            screenshot(browser, args.screenshot)
            browser.close()
        return
    results = []
    with tempfile.TemporaryDirectory() as folder, sync_playwright() as driver:
        browser = driver.chromium.launch(executable_path=chromium, args=["--headless=new", "--no-sandbox",
                                                                         "--disable-dev-shm-usage"])
        for name in args.scenes:
            for size in args.sizes:
                results.append(measure(browser, Path(folder), name, size))
                print(json.dumps(results[-1]), flush=True)
        browser.close()
    load = os.getloadavg()
    from bench import OUT as out  # outside the checkout
    out.mkdir(parents=True, exist_ok=True)
    (out / "view.json").write_text(json.dumps({"load": load, "results": results}, indent=1))
    print(f"\nload average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; medians of one run (ms unless said)\n")
    print(table(results))


if __name__ == "__main__":
    main()
