"""The live view's web server (runtime/view_server.py) without Rerun: what it keeps of the stream for a late
browser, and what it answers, to whom (the page, its files and the stream under the address's token only; no
write of any kind; a Content-Security-Policy on every answer).  The server with the package's viewer, another
account and a real browser: tests/process/test_view_security.py and tests/process/test_browser.py."""

from __future__ import annotations

import http.client
import threading
from collections.abc import Iterator
from urllib.parse import parse_qs, urlsplit

import pytest

from netsetest.runtime.view_server import CSP, EXTERNAL_LINK, STREAM, PortTaken, StreamBuffer, _bind, _Server, check_port

PAGE = b"""<html><head>
    <link rel="preconnect" href="https://fonts.googleapis.com" />
    <link rel="preconnect" href="https://fonts.gstatic.com" crossorigin />
    <link
      href="https://fonts.googleapis.com/css2?family=Inter:wght@100;500&display=swap"
      rel="stylesheet"
    />
    <link rel="icon" href="favicon.ico" sizes="16x16 32x32 48x48" />
    <title>Rerun Viewer</title></head><body><script src="re_viewer.js"></script></body></html>"""  # Rerun 0.41's page's head, shortened


def test_the_pages_links_outside_are_removed_and_its_own_kept() -> None:
    page = EXTERNAL_LINK.sub("", PAGE.decode())
    assert "https://" not in page
    assert 'href="favicon.ico"' in page and "re_viewer.js" in page


def test_a_late_reader_gets_the_pinned_pieces_and_the_newest_within_the_limit() -> None:
    buf = StreamBuffer(limit=10)
    buf.add(b"start", pinned=True)
    for k in range(6):
        buf.add(bytes([k]) * 4, pinned=False)  # 24 bytes: only the newest two fit in 10
    buf.add(b"layout", pinned=True)
    got = buf.after(0, timeout=0)
    assert got is not None
    pieces, nxt = got
    assert pieces == [b"start", b"\x04" * 4, b"\x05" * 4, b"layout"] and nxt == 8
    assert buf.after(nxt, timeout=0) == ([], nxt)  # nothing new yet
    buf.add(b"more", pinned=False)
    assert buf.after(nxt, timeout=0) == ([b"more"], nxt + 1)
    buf.close()
    assert buf.after(nxt + 1, timeout=0) is None  # closed and read to its end: the browser's stream ends
    assert buf.after(nxt, timeout=0) == ([b"more"], nxt + 1)  # a reader behind still gets what is left


def test_a_reader_waits_for_the_next_piece() -> None:
    buf = StreamBuffer()
    threading.Timer(0.05, buf.add, (b"x", False)).start()
    assert buf.after(0, timeout=10) == ([b"x"], 1)


TOKEN = "t" * 43
ASSETS = {"index.html": PAGE, "re_viewer.js": b"js", "re_viewer_bg.wasm": b"\0asm", "favicon.ico": b"ico"}


@pytest.fixture(scope="module")
def _http() -> Iterator[_Server]:
    """One server for the module (its shutdown waits out a poll of half a second)."""
    http_server = _bind(0)
    http_server.token, http_server.assets = TOKEN, ASSETS
    t = threading.Thread(target=http_server.serve_forever, daemon=True)
    t.start()
    try:
        yield http_server
    finally:
        http_server.shutdown()
        http_server.server_close()
        t.join()


@pytest.fixture
def server(_http: _Server) -> Iterator[tuple[int, StreamBuffer]]:
    """The server's port and a fresh stream for each test, ended after it."""
    _http.buffer = buf = StreamBuffer()
    try:
        yield _http.server_address[1], buf
    finally:
        buf.close()


def _ask(port: int, method: str, path: str, headers: dict[str, str] | None = None, body: bytes | None = None) -> tuple[int, dict[str, str], bytes]:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        c.request(method, path, body=body, headers=headers or {})
        r = c.getresponse()
        return r.status, dict(r.getheaders()), r.read()
    finally:
        c.close()


@pytest.mark.parametrize(
    "path",
    [
        "/",
        "/index.html",
        f"/{STREAM}",
        "/re_viewer_bg.wasm",
        "/proxy",
        f"/{TOKEN[:-1]}x/",
        f"/{TOKEN[:-1]}x/{STREAM}",
        f"/{TOKEN}",
        f"/{TOKEN}/../{STREAM}",
        f"/{TOKEN}/x",
    ],
)
def test_without_the_token_nothing_is_served(server: tuple[int, StreamBuffer], path: str) -> None:
    port, buf = server
    buf.add(b"RRF2 the truth", pinned=True)
    status, headers, body = _ask(port, "GET", path)
    assert status == 404 and body == b""
    assert headers["Content-Security-Policy"] == CSP


@pytest.mark.parametrize("method", ["POST", "PUT", "DELETE", "PATCH", "OPTIONS"])
def test_nothing_can_be_written(server: tuple[int, StreamBuffer], method: str) -> None:
    port, buf = server
    for path in (f"/{TOKEN}/{STREAM}", f"/{TOKEN}/", "/proxy"):
        status, headers, body = _ask(port, method, path, body=b"FORGED")
        assert status == 501 and body == b"" and headers["Content-Security-Policy"] == CSP, (method, path)
    assert buf.after(0, timeout=0) == ([], 0)  # the stream got nothing


def test_the_page_points_at_the_stream_through_the_address_the_browser_used(server: tuple[int, StreamBuffer]) -> None:
    """Through ``ssh -L 8000:127.0.0.1:PORT`` the browser asks for localhost:8000: the stream is there too."""
    port, _ = server
    for host in (f"127.0.0.1:{port}", "localhost:8000", "[::1]:8000"):
        status, headers, _ = _ask(port, "GET", f"/{TOKEN}/", {"Host": host})
        assert status == 303
        loc = urlsplit(headers["Location"])
        assert loc.path == f"/{TOKEN}/" and parse_qs(loc.query)["url"] == [f"http://{host}/{TOKEN}/{STREAM}"]
    status, headers, _ = _ask(port, "GET", f"/{TOKEN}/", {"Host": "evil\\.example/x"})  # not a host: the view's own address
    assert parse_qs(urlsplit(headers["Location"]).query)["url"] == [f"http://127.0.0.1:{port}/{TOKEN}/{STREAM}"]


def test_with_the_token_the_page_its_files_and_the_stream(server: tuple[int, StreamBuffer]) -> None:
    port, buf = server
    status, headers, body = _ask(port, "GET", f"/{TOKEN}/?url=x")
    assert status == 200 and body == PAGE and headers["Content-Type"].startswith("text/html")
    assert headers["Content-Security-Policy"] == CSP and headers["Referrer-Policy"] == "no-referrer"
    assert "connect-src 'self'" in CSP and "default-src 'none'" in CSP
    for name in ("re_viewer.js", "re_viewer_bg.wasm", "favicon.ico"):
        status, headers, body = _ask(port, "GET", f"/{TOKEN}/{name}")
        assert status == 200 and body == ASSETS[name] and headers["Content-Security-Policy"] == CSP
    status, _, body = _ask(port, "HEAD", f"/{TOKEN}/{STREAM}")
    assert status == 200 and body == b""
    buf.add(b"one", pinned=True)
    buf.add(b"two", pinned=False)
    threading.Timer(0.2, buf.close).start()  # the view stops: the stream ends
    status, _, body = _ask(port, "GET", f"/{TOKEN}/{STREAM}")
    assert status == 200 and body == b"onetwo"


def test_a_taken_port_is_named(server: tuple[int, StreamBuffer]) -> None:
    port, _ = server
    with pytest.raises(PortTaken, match=f"127.0.0.1:{port} is taken"):
        check_port(port)
    check_port(0)
