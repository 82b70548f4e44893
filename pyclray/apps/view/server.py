"""`pyclray view`'s server: one port on 127.0.0.1 serves the page (HTTP) and its WebSocket, both
through the `websockets` library (its process_request hook answers the page's requests).

Safe by default: only the loopback interface; a random token required on every request (in the
query, or the cookie the tokened page sets); a request whose Origin is not the page's own refused
(WebSocket handshakes included); only the package's own page and assets served, from memory (no
path of a request reaches the file system); the page's messages checked, a bad one ignored."""
from __future__ import annotations

import asyncio
import concurrent.futures
import hmac
import http.cookies
import logging
import os
import secrets
import signal
import sys
import threading
from importlib import resources
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

from ...model.errors import PyclrayError
from . import watch
from .frames import offered_aovs, render_picture
from .session import Session

HOST = "127.0.0.1"
# URL path -> (file of the package's page folder, content type): everything the server answers
ASSETS = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/view.js": ("view.js", "text/javascript; charset=utf-8"),
    "/controls.js": ("controls.js", "text/javascript; charset=utf-8"),
    "/view.css": ("view.css", "text/css; charset=utf-8"),
}
SOCKET_PATH = "/ws"
MAX_MESSAGE = 1 << 16  # the page's messages are a few hundred bytes
SECURITY_HEADERS = (
    ("Cache-Control", "no-store"),
    ("X-Content-Type-Options", "nosniff"),
    ("Referrer-Policy", "no-referrer"),  # the token stays in this page
    ("Content-Security-Policy", "default-src 'self'; img-src 'self' blob: data:; connect-src 'self'; "
                                "frame-ancestors 'none'"),
)


class ListenError(Exception):
    """The port cannot be listened on (taken, or privileged): the command's one-line error."""


def page_assets() -> dict[str, bytes]:
    """The page's files, read once from the package (package data)."""
    folder = resources.files(__package__).joinpath("page")
    return {path: folder.joinpath(name).read_bytes() for path, (name, _) in ASSETS.items()}


class App:
    """The scene being viewed (as last loaded without error), its pages, and the one thread that
    renders (the device renders one view at a time; the event loop stays free for input)."""

    def __init__(self, path, scene, aov: str, size):
        self.path, self.scene, self.aov, self.size = Path(path), scene, aov, size
        self.name = str(path)
        self.error = None  # the one-line error of the scene file's last load, if it failed
        self.files = watch.named_files(path)
        self.loaded = watch.signature(self.files)
        self.sessions: set[Session] = set()
        self.token = secrets.token_urlsafe(24)
        self.assets = page_assets()
        self.executor = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="pyclray-view")
        self.cookie = ""

    def aovs(self) -> tuple[str, ...]:
        return offered_aovs(self.scene, self.aov)

    async def run(self, function, *args):
        """function(*args) on the render thread."""
        return await asyncio.get_running_loop().run_in_executor(self.executor, function, *args)

    # -- HTTP ---------------------------------------------------------------------------------------
    def answer(self, connection, request):
        """process_request: the page and its assets, or None to go on with the WebSocket's handshake
        at SOCKET_PATH; 403 without the token or from another origin, 404 for any other path."""
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        def response(status: int, reason: str, body: bytes = b"", kind: str | None = None, cookie: bool = False):
            headers = Headers([("Content-Length", str(len(body))), ("Connection", "close"), *SECURITY_HEADERS])
            if kind:
                headers["Content-Type"] = kind
            if cookie:
                headers["Set-Cookie"] = f"{self.cookie}={self.token}; Path=/; HttpOnly; SameSite=Strict"
            return Response(status, reason, headers, body)

        headers = request.headers
        origins, hosts = headers.get_all("Origin"), headers.get_all("Host")
        if len(origins) > 1 or len(hosts) != 1 or (origins and origins[0] != f"http://{hosts[0]}"):
            return response(403, "Forbidden")
        url = urlsplit(request.path)
        if not hmac.compare_digest(self._token_of(url.query, headers).encode(), self.token.encode()):
            return response(403, "Forbidden")
        if url.path == SOCKET_PATH:
            return None
        if url.path not in ASSETS:
            return response(404, "Not Found")
        return response(200, "OK", self.assets[url.path], ASSETS[url.path][1], cookie=url.path == "/")

    def _token_of(self, query: str, headers) -> str:
        """The token of a request: its query's, else its cookie's ('' when neither)."""
        tokens = parse_qs(query).get("token")
        if tokens:
            return tokens[0]
        jar = http.cookies.SimpleCookie()
        for line in headers.get_all("Cookie"):
            try:
                jar.load(line)
            except http.cookies.CookieError:
                continue
        return jar[self.cookie].value if self.cookie in jar else ""

    # -- the WebSocket ------------------------------------------------------------------------------
    async def connected(self, connection) -> None:
        from websockets.exceptions import ConnectionClosed

        session = Session(self, connection)
        self.sessions.add(session)
        loop = asyncio.create_task(session.run())
        loop.add_done_callback(lambda task: _ended(task, connection))
        try:
            async for message in connection:
                session.receive(message)
        except ConnectionClosed:
            pass
        finally:
            self.sessions.discard(session)
            loop.cancel()
            try:
                await loop
            except (asyncio.CancelledError, ConnectionClosed):
                pass
            except Exception:  # the loop's own error: said by _ended, which closed this connection
                pass

    # -- live editing -------------------------------------------------------------------------------
    async def watch(self) -> None:
        """Poll the files; load the scene again once a change has held for one poll. Nothing ends
        this loop but the server's end: a watcher ended by an error would leave every page showing
        a scene that no save changes any more, without a word."""
        seen = self.loaded
        while True:
            await asyncio.sleep(watch.POLL_SECONDS)
            try:
                now = watch.signature(self.files)
                if now != self.loaded and now == seen:
                    await self.reload(now)
                    now = self.loaded
            except Exception as error:  # a bug of ours: said, and the next save tries again
                print(f"pyclray view: warning: reloading failed: {type(error).__name__}: {error}", file=sys.stderr,
                      flush=True)
                now = self.loaded
            seen = now

    async def reload(self, signature) -> None:
        self.loaded = signature
        try:
            scene, files = await self.run(watch.load, self.path, self.size, self.scene)
        except Exception as error:  # a bad edit (or a file caught half-written): said, the last image kept
            self.error = str(error) if isinstance(error, PyclrayError) else \
                f"{self.path}: cannot load: {type(error).__name__}: {error}"
            print(f"pyclray view: error: {self.error}", file=sys.stderr, flush=True)
            for session in list(self.sessions):
                await _quietly(session.send_error())
            return
        camera_changed = scene.camera != self.scene.camera
        self.scene, self.error = scene, None
        if files != self.files:
            self.files = files
            self.loaded = watch.signature(files)
        for session in list(self.sessions):
            session.reloaded(camera_changed)
            await _quietly(session.send_scene())

    # -- serving ------------------------------------------------------------------------------------
    async def serve(self, port: int, open_browser: bool) -> int:
        """Serve until SIGINT or SIGTERM; the exit status (130: interrupted)."""
        from websockets.asyncio.server import serve

        loop = asyncio.get_running_loop()
        stop = asyncio.Event()
        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(signum, stop.set)
        quiet = logging.getLogger("pyclray.view")  # refused requests are answered, not logged
        quiet.addHandler(logging.NullHandler())
        quiet.propagate = False
        try:
            server = await serve(self.connected, HOST, port, process_request=self.answer, compression=None,
                                 max_size=MAX_MESSAGE, close_timeout=1, server_header=None, logger=quiet)
        except OSError as error:
            reason = os.strerror(error.errno) if error.errno else str(error)  # (asyncio's text repeats the address)
            raise ListenError(f"cannot listen on {HOST}:{port}: {reason.lower()}") from None
        async with server:
            port = server.sockets[0].getsockname()[1]
            self.cookie = f"pyclray_view_{port}"  # cookies ignore ports: one per server
            # the first frame's program and prepared scene, made while the browser starts
            first = self.executor.submit(render_picture, self.scene, self.scene.camera, self.aov,
                                         (self.scene.image.width, self.scene.image.height))
            url = f"http://{HOST}:{port}/?token={self.token}"
            print(f"pyclray view: {url}", flush=True)
            if open_browser:
                threading.Thread(target=_open, args=(url,), daemon=True).start()
            watcher = asyncio.create_task(self.watch())
            await stop.wait()
            watcher.cancel()
            first.cancel()
        self.executor.shutdown(wait=False, cancel_futures=True)
        return 130


def _ended(task: asyncio.Task, connection) -> None:
    """A page's render loop has ended: by its connection's close (or cancelled then), or by an error
    no handler took, which is said and closes the connection, so that the page says the server has
    stopped rather than waiting on images that will not come."""
    from websockets.exceptions import ConnectionClosed

    if task.cancelled() or task.exception() is None or isinstance(task.exception(), ConnectionClosed):
        return
    error = task.exception()
    print(f"pyclray view: warning: a page's images stopped: {type(error).__name__}: {error}", file=sys.stderr,
          flush=True)
    asyncio.ensure_future(connection.close(1011, "the server's render loop failed"))


async def _quietly(sending) -> None:
    """Send to a page that may have gone."""
    from websockets.exceptions import ConnectionClosed

    try:
        await sending
    except ConnectionClosed:
        pass


def _open(url: str) -> None:
    import webbrowser

    try:
        webbrowser.open(url)
    except Exception:  # no browser here: the printed URL is there to open by hand
        pass
