"""`pyclray view`'s server without a browser (issue 24, item 5): the URL line, the token and the
Origin checked on every request and WebSocket handshake, nothing but the page's own files served,
bad messages ignored, at most two frames in flight, and Ctrl-C quiet with a page connected. The
page itself is driven in a browser in test_view_page.py."""
import asyncio
import http.client
import json
import subprocess
import sys

import pytest

from conftest import REPO
from viewing import Viewer

websockets = pytest.importorskip("websockets", reason="pyclray view needs websockets (the view extra)")
from websockets.asyncio.client import connect  # noqa: E402
from websockets.exceptions import ConnectionClosed, InvalidStatus  # noqa: E402


@pytest.fixture(scope="module")
def viewer():
    viewer = Viewer(REPO / "scenes/tp02.toml", "--size", "64x48")
    yield viewer
    viewer.close()


def get(viewer, path, headers=()):
    """(status, headers, body) of a GET of this raw path (sent as written: nothing normalised)."""
    connection = http.client.HTTPConnection("127.0.0.1", viewer.port, timeout=10)
    connection.putrequest("GET", path, skip_accept_encoding=True)
    for name, value in headers:
        connection.putheader(name, value)
    connection.endheaders()
    response = connection.getresponse()
    answer = response.status, dict(response.getheaders()), response.read()
    connection.close()
    return answer


def test_the_page_needs_the_token_and_sets_it_as_a_cookie_for_its_assets(viewer):
    status, headers, body = get(viewer, f"/?token={viewer.token}")
    assert status == 200 and b'id="view"' in body
    cookie = headers["Set-Cookie"].split(";")[0]
    assert cookie == f"pyclray_view_{viewer.port}={viewer.token}" and "HttpOnly" in headers["Set-Cookie"]
    for path in ("/view.js", "/controls.js", "/view.css"):  # what the page loads, with its cookie
        assert get(viewer, path, [("Cookie", cookie)])[0] == 200, path
    # without the token, or with a wrong one (in the query or the cookie): 403 and no content
    for path, headers in [("/", ()), ("/?token=", ()), ("/?token=x" + viewer.token, ()), ("/view.js", ()),
                          ("/view.js", [("Cookie", f"pyclray_view_{viewer.port}=wrong")]),
                          ("/view.js", [("Cookie", f"other={viewer.token}")]), ("/ws", ())]:
        status, _, body = get(viewer, path, headers)
        assert (status, body) == (403, b""), (path, headers)


def test_a_foreign_origin_is_refused_even_with_the_token(viewer):
    page = f"/?token={viewer.token}"
    assert get(viewer, page, [("Origin", viewer.origin)])[0] == 200  # the page's own origin
    for origin in ("http://evil.example", f"http://127.0.0.1:{viewer.port + 1}", "null", f"https://127.0.0.1:{viewer.port}"):
        assert get(viewer, page, [("Origin", origin)])[:3:2] == (403, b""), origin


@pytest.mark.parametrize("path", ["/../setup.cfg", "/..%2f..%2fsetup.cfg", "/%2e%2e/%2e%2e/etc/passwd", "//etc/passwd",
                                  "/view.js/../../../../etc/passwd", "/page/index.html", "/pyclray/apps/view/page/view.js",
                                  "/index.html", "/view.js%00.png", "/.%2fview.js", "/VIEW.JS", "/scenes/tp02.toml"])
def test_no_path_of_a_request_reaches_the_file_system(viewer, path):
    """Only the four paths of the page's own files are answered (from memory): anything else is a
    404 with no content, whatever it spells, with the token."""
    separator = "&" if "?" in path else "?"
    status, _, body = get(viewer, f"{path}{separator}token={viewer.token}")
    assert (status, body) == (404, b"")


def test_the_websocket_needs_the_token_and_its_own_origin(viewer):
    async def status_of(url, origin):
        try:
            async with connect(url, origin=origin, open_timeout=10):
                return 101
        except InvalidStatus as error:
            return error.response.status_code

    base = f"ws://127.0.0.1:{viewer.port}/ws"
    cases = [(f"{base}?token={viewer.token}", viewer.origin, 101), (f"{base}?token={viewer.token}", None, 101),
             (base, viewer.origin, 403), (f"{base}?token=wrong", viewer.origin, 403),
             (f"{base}?token={viewer.token}", "http://evil.example", 403),
             (f"{base}?token={viewer.token}", f"http://localhost:{viewer.port}", 403)]
    for url, origin, expected in cases:
        assert asyncio.run(status_of(url, origin)) == expected, (url, origin)


async def _frames(connection, seconds: float, until=None) -> list[dict]:
    """The headers of the images received within this time (text messages skipped), or until
    until(headers) holds."""
    frames = []
    loop = asyncio.get_running_loop()
    end = loop.time() + seconds
    while (left := end - loop.time()) > 0:
        try:
            message = await asyncio.wait_for(connection.recv(), left)
        except asyncio.TimeoutError:
            break
        if isinstance(message, bytes):
            length = int.from_bytes(message[:4], "big")
            frames.append(json.loads(message[4:4 + length]))
            if until is not None and until(frames):
                break
    return frames


def test_bad_messages_are_ignored_and_at_most_two_frames_are_in_flight(viewer):
    bad = ["", "{", "null", "[]", "42", '"orbit"', json.dumps({"type": "orbit"}), json.dumps({"type": "orbit", "dx": "1", "dy": 0}),
           '{"type": "orbit", "dx": NaN, "dy": 0}', '{"type": "pan", "dx": Infinity, "dy": 0}',
           json.dumps({"type": "dolly", "notches": 1e300}), json.dumps({"type": "orbit", "dx": True, "dy": 0}),
           json.dumps({"type": "aov", "name": "../../etc/passwd"}), json.dumps({"type": "aov", "name": ["shaded"]}),
           json.dumps({"type": "time", "t": 0.5}),  # a static scene has no time
           json.dumps({"type": {"nested": 1}}), json.dumps({"type": "__init__"}), json.dumps({"type": "receive"}),
           json.dumps({"type": "painted", "frame": 1e9}), "[" * 30_000 + "]" * 30_000, b"\x00\xff binary"]

    async def scenario():
        async with connect(f"ws://127.0.0.1:{viewer.port}/ws?token={viewer.token}", max_size=None) as connection:
            first = await _frames(connection, 10, until=len)
            assert len(first) == 1 and first[0]["lossless"]  # the first image, unacknowledged
            for message in bad:
                await connection.send(message)
            assert await _frames(connection, 0.5) == []  # nothing changed the view
            # twenty motions and no image acknowledged: one more frame at most (two in flight)
            for k in range(20):
                await connection.send(json.dumps({"type": "orbit", "dx": 0.01, "dy": 0.0}))
            moved = await _frames(connection, 1.0)
            assert len(moved) == 1 and moved[0]["eye"] != first[0]["eye"]
            # painted: the latest motion's view comes, rendered once (the stale ones never are)
            await connection.send(json.dumps({"type": "painted", "frame": moved[-1]["frame"]}))
            await connection.send(json.dumps({"type": "painted", "frame": first[0]["frame"]}))
            await connection.send(json.dumps({"type": "end"}))
            more = await _frames(connection, 10, until=lambda frames: frames[-1]["lossless"])
            assert 1 <= len(more) <= 2 and more[-1]["lossless"] and more[-1]["seq"] == 0
        # a message over the size limit closes that connection only
        async with connect(f"ws://127.0.0.1:{viewer.port}/ws?token={viewer.token}", max_size=None) as connection:
            await connection.send("x" * (1 << 17))
            with pytest.raises(ConnectionClosed):
                for _ in range(10):
                    await asyncio.wait_for(connection.recv(), 5)

    asyncio.run(scenario())
    assert get(viewer, f"/?token={viewer.token}")[0] == 200  # still serving
    assert viewer.process.poll() is None


def test_ctrl_c_with_a_page_connected_ends_quietly_within_5_s():
    viewer = Viewer(REPO / "scenes/tp02.toml", "--size", "64x48")
    try:
        async def scenario():
            async with connect(f"ws://127.0.0.1:{viewer.port}/ws?token={viewer.token}", max_size=None) as connection:
                assert await _frames(connection, 10, until=len)
                return await asyncio.get_running_loop().run_in_executor(None, viewer.interrupt)

        status, seconds, stderr = asyncio.run(scenario())
    finally:
        viewer.close()
    assert status in (130, 0) and seconds < 5 and "Traceback" not in stderr, (status, seconds, stderr)


@pytest.mark.parametrize("args, expected", [
    (["scenes/nope.toml"], "pyclray view: error: scenes/nope.toml: cannot read the scene file"),
    (["scenes/tp02.toml", "--aov", "position"], "pyclray view: error: argument --aov: expected one of shaded, depth"),
    (["scenes/tp02.toml", "--port", "70000"], "pyclray view: error: argument --port: expected a port 0 to 65535"),
    (["scenes/tp02.toml", "--size", "0x4"], "pyclray view: error: argument --size: expected WIDTHxHEIGHT"),
])
def test_bad_input_is_one_line_and_exit_2(args, expected):
    result = subprocess.run([sys.executable, "-m", "pyclray", "view", *args, "--no-browser"], capture_output=True,
                            text=True, cwd=REPO, timeout=60)
    assert result.returncode == 2 and result.stdout == "" and result.stderr.startswith(expected), result.stderr
    assert len(result.stderr.splitlines()) == 1


def test_a_port_in_use_is_one_line_and_exit_2():
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = subprocess.run([sys.executable, "-m", "pyclray", "view", "scenes/tp02.toml", "--port", str(port),
                                 "--no-browser"], capture_output=True, text=True, cwd=REPO, timeout=60)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr == f"pyclray view: error: --port {port}: cannot listen on 127.0.0.1:{port}: address already in use\n"


def test_a_render_loop_ended_by_an_error_closes_its_page_with_a_word(capsys):
    """A page's render loop that an error ends (a bug of ours) is said on the terminal and closes its
    connection, so that the page says the server stopped instead of waiting for images for ever;
    a loop ended by its connection's close says nothing."""
    from pyclray.apps.view.server import _ended

    class Connection:
        closed_with = None

        async def close(self, code, reason):
            self.closed_with = code

    async def failing():
        raise RuntimeError("a bug of ours")

    async def closed():
        raise ConnectionClosed(None, None)

    async def scenario(loop_body):
        connection = Connection()
        task = asyncio.create_task(loop_body())
        task.add_done_callback(lambda task: _ended(task, connection))
        await asyncio.gather(task, return_exceptions=True)
        await asyncio.sleep(0.01)  # the close it scheduled
        return connection.closed_with

    assert asyncio.run(scenario(failing)) == 1011
    assert capsys.readouterr().err == "pyclray view: warning: a page's images stopped: RuntimeError: a bug of ours\n"
    assert asyncio.run(scenario(closed)) is None
    assert capsys.readouterr().err == ""


def test_a_clip_longer_than_100_s_is_shown_at_any_of_its_times(tmp_path):
    """The time slider's value is bound by the clip's duration only (it once went through the bound
    of a mouse motion, 100, and a time past 100 s was ignored); past the duration it is ignored."""
    scene = tmp_path / "long.toml"
    scene.write_text((REPO / "scenes/tp02.toml").read_text() + """
[animation]
fps = 1.0
duration = 300.0

[[animation.keys]]
target = "camera"
time = 0.0
eye = [0.0, 2.0, 6.0]

[[animation.keys]]
target = "camera"
time = 300.0
eye = [6.0, 2.0, 0.0]
""")
    viewer = Viewer(scene, "--size", "32x24")
    try:
        async def scenario():
            async with connect(f"ws://127.0.0.1:{viewer.port}/ws?token={viewer.token}", max_size=None) as connection:
                shown = await _frames(connection, 10, until=len)
                for t in (150.0, 300.0, 300.5, float("nan")):
                    for frame in shown:  # painted, as the page says of each
                        await connection.send(json.dumps({"type": "painted", "frame": frame["frame"]}))
                    shown = []
                    await connection.send(json.dumps({"type": "time", "t": t}))
                    await connection.send(json.dumps({"type": "end"}))
                    frames = await _frames(connection, 10 if t <= 300 else 1, until=lambda f: f[-1]["lossless"])
                    if t <= 300:
                        assert frames and frames[-1]["t"] == t, (t, frames)
                        shown = frames
                        last = frames[-1]
                    else:
                        assert frames == [], t  # past the clip (or not a number): ignored
                assert last["eye"] == pytest.approx([6.0, 2.0, 0.0])

        asyncio.run(scenario())
    finally:
        viewer.close()
