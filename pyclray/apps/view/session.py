"""One page's view: its camera, image and time, what it asks for (the page's messages, checked and
applied at once), and when to render (jupyter-rfb's flow control).

Inputs only change the state and bump its version; one loop renders the latest version, so requests
that came while a frame was rendering are never rendered (stale ones dropped). At most
MAX_IN_FLIGHT frames are sent and not yet painted. While the user moves, a frame is rendered at a
coarser size when the full one would take longer than MOVING_BUDGET, and sent as JPEG; SETTLE after
the last motion (or at once when the mouse is released) the full image is sent as PNG. Without input
nothing runs: the loop waits on an event."""
from __future__ import annotations

import asyncio
import json
import math
import sys
import time

from websockets.exceptions import ConnectionClosed

from ...model.errors import PyclrayError
from .controls import Orbit, camera_toml
from .frames import encode, render_picture

SETTLE = 0.08  # seconds without motion after which the motion has stopped (mouse events come every ~16 ms)
# seconds a frame's render and preview may take while moving: >= 30 frames/s with its JPEG, the page's
# decode and paint (docs/benchmarks.md, "Why the engine does what it does")
MOVING_BUDGET = 0.022
MAX_IN_FLIGHT = 2
MAX_DIVISOR = 8  # the coarsest frame while moving: an eighth of each side
COST_WEIGHT = 0.5  # the weight of the newest frame in the estimate of a frame's seconds per pixel
LIMIT = 100.0  # the largest motion a message may carry (image heights, wheel notches)


class Ignored(Exception):
    """A message the page should not have sent: dropped, the view unchanged."""


def _number(message: dict, key: str) -> float:
    value = message.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or abs(value) > LIMIT:
        raise Ignored
    return float(value)


class Session:
    def __init__(self, app, connection):
        self.app, self.connection = app, connection
        self.orbit: Orbit | None = None  # None: the camera of the scene file (at the time shown)
        self.aov = app.aov
        self.t = 0.0
        self.version = 0  # of what the page should show; bumped by every change
        self.shown, self.settled = -1, False  # the version last sent; whether full and lossless
        self.full = None  # (version, rgb) of the last full-size render: settles without a new render
        self.moving_until = 0.0
        self.in_flight = self.sent = self.seq = 0
        self.render_error = None
        self.cost = {}  # AOV -> seconds per pixel of a frame's render and preview
        self.wake = asyncio.Event()
        self.timer = None
        self._scene_at = (None, None, None)

    # -- the page's messages ------------------------------------------------------------------------
    def receive(self, text) -> None:
        """Apply one message of the page; anything malformed is ignored (never an error)."""
        try:
            message = json.loads(text) if isinstance(text, str) else None
        except (ValueError, RecursionError):
            return
        kind = message.get("type") if isinstance(message, dict) else None
        handler = self.HANDLERS.get(kind) if isinstance(kind, str) else None
        if handler is None:
            return
        try:
            handler(self, message)
        except (Ignored, PyclrayError, ArithmeticError, ValueError):
            return
        except Exception as error:  # a bug of ours, not of the page's: said, and the view goes on
            print(f"pyclray view: warning: message {kind!r} ignored: {type(error).__name__}: {error}", file=sys.stderr)
            return
        seq = message.get("seq")  # the page's count of its inputs: echoed with the frames (latency)
        if isinstance(seq, int) and not isinstance(seq, bool):
            self.seq = max(self.seq, seq)

    def _move(self, moved) -> None:
        """Apply a motion to the controls (from the camera shown), if the camera it makes is valid."""
        orbit = moved(self.orbit or Orbit.of(self.scene().camera))
        orbit.camera()  # a degenerate or overflowing camera raises: the motion is ignored
        self.orbit = orbit
        self.changed(moving=True)

    def _orbit(self, message):
        dx, dy = _number(message, "dx"), _number(message, "dy")
        self._move(lambda orbit: orbit.orbit(dx, dy))

    def _pan(self, message):
        dx, dy = _number(message, "dx"), _number(message, "dy")
        image = self.app.scene.image
        self._move(lambda orbit: orbit.pan(dx, dy, image.width, image.height))

    def _dolly(self, message):
        notches = _number(message, "notches")
        self._move(lambda orbit: orbit.dolly(notches))

    def _end(self, message):
        """The mouse was released: the motion is over, the full image is due now."""
        self.moving_until = 0.0
        self.wake.set()

    def _reset(self, message):
        self.orbit = None
        self.changed()

    def _aov(self, message):
        name = message.get("name")
        if name not in self.app.aovs():
            raise Ignored
        self.aov = name
        self.changed()

    def _time(self, message):
        # a time is bound by the animation's duration, not by LIMIT (a motion's bound: a clip may be
        # longer than 100 s)
        animation = self.app.scene.animation
        t = message.get("t")
        if animation is None or isinstance(t, bool) or not isinstance(t, (int, float)) or \
                not 0 <= t <= animation.duration:  # (NaN is not)
            raise Ignored
        t = float(t)
        self.t = t
        self.changed(moving=True)  # a slider dragged or a clip played: coarse frames allowed

    def _painted(self, message):
        """The page is done with image number `frame` (painted, or failed to): one frame less in
        flight. The frame is a count, checked against the frames sent only: through _number, whose
        LIMIT bounds a motion, every acknowledgement past the hundredth image was refused, two
        frames stayed in flight for ever and the view stopped answering any input."""
        frame = message.get("frame")
        if isinstance(frame, bool) or not isinstance(frame, int) or not 1 <= frame <= self.sent:
            raise Ignored
        if self.in_flight:
            self.in_flight -= 1
            self.wake.set()

    HANDLERS = {"orbit": _orbit, "pan": _pan, "dolly": _dolly, "end": _end, "reset": _reset, "aov": _aov,
                "time": _time, "painted": _painted}

    # -- changes ------------------------------------------------------------------------------------
    def changed(self, moving: bool = False) -> None:
        self.version += 1
        if moving:
            self.moving_until = time.monotonic() + SETTLE
        self.wake.set()

    def reloaded(self, camera_changed: bool) -> None:
        """The scene file was loaded again: the new scene, from the user's camera unless the file's
        camera changed; the time kept within the new duration."""
        if camera_changed:
            self.orbit = None
        animation = self.app.scene.animation
        self.t = min(self.t, animation.duration) if animation is not None else 0.0
        if self.aov not in self.app.aovs():
            self.aov = self.app.aov
        self.cost.clear()
        self.changed()

    def scene(self):
        """The scene at the time shown (the scene file's, as last loaded)."""
        scene = self.app.scene
        if scene.animation is None:
            return scene
        if self._scene_at[:2] != (scene, self.t):
            self._scene_at = (scene, self.t, scene.at(self.t))
        return self._scene_at[2]

    def camera(self):
        return self.orbit.camera() if self.orbit is not None else self.scene().camera

    # -- the loop -----------------------------------------------------------------------------------
    async def run(self) -> None:
        """Send what is due whenever woken, until the connection closes. Nothing but a closed
        connection ends this loop: the server's reader keeps taking the page's messages whether it
        runs or not, so a loop ended by a bug of ours would leave the page deaf without a word."""
        try:
            await self.send_scene()
        except ConnectionClosed:
            raise
        except Exception as error:  # a bug of ours: said, and the images still come
            print(f"pyclray view: warning: the scene's description failed: {type(error).__name__}: {error}",
                  file=sys.stderr)
        self.wake.set()  # the first image
        while True:
            await self.wake.wait()
            self.wake.clear()
            try:
                while self.in_flight < MAX_IN_FLIGHT and await self.step():
                    pass
            except ConnectionClosed:
                raise
            except Exception as error:  # a bug of ours: said on the terminal, and the next input tries again
                self.shown, self.settled = self.version, True
                print(f"pyclray view: warning: a frame failed: {type(error).__name__}: {error}", file=sys.stderr)

    def _wake_at(self, when: float) -> None:
        if self.timer is not None:
            self.timer.cancel()
        self.timer = asyncio.get_running_loop().call_later(max(0.0, when - time.monotonic()), self.wake.set)

    def _size(self, moving: bool) -> tuple[int, int]:
        """The full size, or while moving the largest 1/d of it whose frame takes MOVING_BUDGET."""
        image = self.app.scene.image
        width, height = image.width, image.height
        cost = self.cost.get(self.aov)
        if not moving or cost is None:
            return width, height
        divisor = min(MAX_DIVISOR, max(1, math.ceil(math.sqrt(cost * width * height / MOVING_BUDGET))))
        return max(1, round(width / divisor)), max(1, round(height / divisor))

    async def step(self) -> bool:
        """Send the frame that is due, if one is: False when none is (now)."""
        now = time.monotonic()
        moving = now < self.moving_until
        if self.shown == self.version and (self.settled or moving):
            if not self.settled:
                self._wake_at(self.moving_until)  # the full image once the motion has stopped
            return False
        # what this frame shows, taken before the render's await (inputs may change them meanwhile)
        version, aov, seq, t, orbit, camera = self.version, self.aov, self.seq, self.t, self.orbit, None
        try:
            camera = self.camera()
            full_size = (self.app.scene.image.width, self.app.scene.image.height)
            rendered = 0.0
            if self.full is not None and self.full[0] == version and not moving:
                rgb = self.full[1]  # the full image shown while moving, now lossless
            else:
                size = self._size(moving)
                picture = await self.app.run(render_picture, self.scene(), camera, aov, size)
                rgb, rendered = picture.rgb, picture.seconds
                self.full = (version, rgb) if size == full_size else None
            lossless = not moving and rgb.shape[:2] == full_size[::-1]
            start = time.perf_counter()
            kind, data = await self.app.run(encode, rgb, lossless)
            seconds = rendered + time.perf_counter() - start
        except PyclrayError as error:  # a camera or a scene the device cannot render: said, not fatal
            self.shown, self.settled = version, True
            self.render_error = str(error)
            await self.send_error()
            return False
        if rendered:
            known = self.cost.get(aov)
            per_pixel = rendered / rgb.shape[0] / rgb.shape[1]
            self.cost[aov] = per_pixel if known is None else COST_WEIGHT * per_pixel + (1 - COST_WEIGHT) * known
        if self.render_error is not None:
            self.render_error = None
            await self.send_error()
        self.shown, self.settled = version, lossless
        await self.send_frame(kind, data, rgb.shape, lossless, seconds, camera, (orbit, aov, t, seq))
        return True

    # -- what the page receives ---------------------------------------------------------------------
    async def send_scene(self) -> None:
        """The scene's image size, AOVs and animation (sent at the start and after every reload)."""
        scene = self.app.scene
        animation = scene.animation
        await self.connection.send(json.dumps({
            "type": "scene", "width": scene.image.width, "height": scene.image.height, "aovs": self.app.aovs(),
            "aov": self.aov, "source": self.app.name,
            "animation": None if animation is None else {"duration": animation.duration, "fps": animation.fps},
            "t": self.t}))
        await self.send_error()

    async def send_error(self) -> None:
        await self.connection.send(json.dumps({"type": "error", "message": self.app.error or self.render_error or ""}))

    async def send_frame(self, kind, data, shape, lossless, seconds, camera, shown) -> None:
        """One image and what it shows: shown is (orbit, aov, t, seq) as they were when it was rendered."""
        orbit, aov, t, seq = shown
        orbit = orbit or Orbit.of(camera)
        self.sent += 1
        self.in_flight += 1
        header = json.dumps({
            "frame": self.sent, "type": kind, "width": shape[1], "height": shape[0], "lossless": lossless,
            "ms": round(seconds * 1000, 1), "eye": orbit.eye, "target": orbit.target, "camera": camera_toml(camera),
            "aov": aov, "t": t, "seq": seq}).encode()
        await self.connection.send(len(header).to_bytes(4, "big") + header + data)
