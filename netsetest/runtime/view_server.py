"""The live view's web server (``netsetest view``, ``run --view``): Rerun's web viewer and the view's stream on
one port of the loopback address, readable only by whoever holds the address it prints.

Why not Rerun's own server.  ``rerun --serve-web`` (and the SDK's ``serve_grpc``) host a gRPC proxy with no
credentials: in rerun-sdk 0.41 it has no authentication and listens on TCP only (no Unix socket), so any account
on the machine could read every message the view logs (the truth, every node's true fault) and write into the
recording that every open browser shows.  So nothing of Rerun listens here.  The view logs to Rerun's in-memory
RRD sink (``RecordingStream.binary_stream``); this server, Python's ``http.server`` bound to 127.0.0.1, hands that
stream out over HTTP (Rerun's web viewer loads an ``.rrd`` over HTTP as it arrives, the concatenated pieces
decoding as one stream) beside the viewer's own files:

``/<token>/``                 the viewer's page (redirected once to ``?url=`` the stream, at the address the browser used)
``/<token>/re_viewer.js`` …   its script, WebAssembly and icon, as the package's ``rerun`` binary serves them
``/<token>/recording.rrd``    the view's stream: what is kept for a late browser (:class:`StreamBuffer`), then live

``<token>`` is 32 random bytes from :mod:`secrets`, made in the view's process and printed only on its standard
output (never on a command line, which every account may read in ``/proc``); any other path answers 404, and
the server takes no write of any kind (GET and HEAD only), so a local account without the address can neither
read nor forge.  What remains (documented in docs/records.md): anyone who has the address (the user's terminal,
the browser's history, a browser started with it on its command line) and root.

Nothing leaves the machine.  The page comes from the package's ``rerun`` binary, fetched once at start-up from
its web-viewer-only mode (given a URL to show, it hosts no gRPC proxy) on the loopback address, its own usage
statistics off.  Three changes to what it serves: its links to Google Fonts are removed (the viewer draws with
fonts of its own); the page gets no browser storage (:data:`NO_STORAGE`): Rerun 0.41's web viewer has no switch for
its usage statistics (tel.rerun.io) and starts them only once it has stored an id for them, so without storage they
stay off (the viewer keeps no other state in the browser: ``persist=0``); and every response carries a
Content-Security-Policy that lets the page connect to its own origin only, so the browser refuses what is left, the
viewer's update check (GitHub, no switch either), before it leaves the machine, and anything a later Rerun adds
(tests/process/test_browser.py records every request the page makes).
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
import time
import urllib.request
from collections import deque
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

LOOPBACK = "127.0.0.1"  # the view shows the truth: it listens on this machine only (remote: ssh -L, docs/records.md)
TOKEN_BYTES = 32  # the address's capability: secrets.token_urlsafe of this many bytes
STREAM = "recording.rrd"
ASSETS = {  # the viewer's files the page loads, and their types
    "index.html": "text/html; charset=utf-8",
    "re_viewer.js": "text/javascript",
    "re_viewer_bg.wasm": "application/wasm",
    "favicon.ico": "image/x-icon",
}
PAGE_OPTIONS = {"persist": "0"}  # the viewer keeps no state of its own in the browser between runs
STREAM_MEMORY = 256 * 2**20  # bytes of the stream kept for a browser that connects late; older steps go first
REQUEST_TIMEOUT_S = 30.0  # a connection that sends no request within this is closed (no idle sockets held open)
STREAM_POLL_S = 1.0  # a stream's handler looks this often whether the view has stopped
CLOSE_FLUSH_S = 2.0  # the view's last frames (the run's end) go to the browsers within this when it stops
ASSETS_TIMEOUT_S = 60.0  # the package's viewer starts, and hands over its 43 MB of WebAssembly, within this
CSP = "; ".join(
    (
        "default-src 'none'",
        "script-src 'self' 'unsafe-inline' 'wasm-unsafe-eval'",  # the page's inline loader and the WebAssembly
        "style-src 'self' 'unsafe-inline'",
        "img-src 'self' data: blob:",
        "font-src 'self' data:",
        "connect-src 'self'",  # the stream and the WebAssembly: usage statistics and update checks are refused
        "worker-src 'self' blob:",
        "frame-ancestors 'none'",
        "base-uri 'none'",
        "form-action 'none'",
    )
)
HEADERS = {"Content-Security-Policy": CSP, "Referrer-Policy": "no-referrer", "X-Content-Type-Options": "nosniff", "Cache-Control": "no-store"}
HOST = re.compile(r"[A-Za-z0-9.\-]+(:[0-9]{1,5})?|\[[0-9A-Fa-f:.]+\](:[0-9]{1,5})?")  # a Host header fit to build the stream's address from
NO_STORAGE = (  # first in the page's head: before Rerun's script looks for the storage its usage statistics need
    "<script>Object.defineProperty(window, 'localStorage', {get() { throw new DOMException('netsetest: no storage', 'SecurityError'); }});</script>"
)
EXTERNAL_LINK = re.compile(r"<link\b[^>]*\bhref=\"https?://[^\"]*\"[^>]*>\s*", re.S)  # Google Fonts and its preconnects


class ViewError(Exception):
    """The live view did not start (its viewer, its port, or the view process of ``run --view``)."""


class PortTaken(ViewError):
    """The view's port cannot be had (another process listens there)."""


def check_port(port: int) -> None:
    """PortTaken unless ``port`` of the loopback address can be listened on now (0: any free one can)."""
    if port:
        _bind(port).server_close()


def _bind(port: int) -> _Server:
    try:
        return _Server((LOOPBACK, port), _Handler)
    except OSError as exc:
        raise PortTaken(f"{LOOPBACK}:{port} is taken ({exc.strerror}); choose another port, or 0 for a free one") from None


# ------------------------------------------------------------------------------------ the viewer's files


def rerun_binary() -> Path:
    """The package's own ``rerun`` binary (its Python wrapper would leave it orphaned when stopped)."""
    import rerun_cli

    return Path(rerun_cli.__file__).parent / "rerun"


def viewer_assets() -> dict[str, bytes]:
    """The web viewer's files, as the installed package's ``rerun`` binary serves them, the page without its
    links outside.  The binary runs in its web-viewer-only mode (a URL to show: no gRPC proxy) on a free port of
    the loopback address, in a session of its own (Ctrl-C at the terminal is the view's to handle), with its
    configuration in a private temporary directory (usage statistics off, nothing in the user's home), and is
    stopped as soon as the files are here."""
    home = tempfile.mkdtemp(prefix="netsetest-view-")  # mode 0700
    proc: subprocess.Popen | None = None
    try:
        env = {**os.environ, "RERUN_APP_ONLY": "true", "XDG_CONFIG_HOME": f"{home}/config", "XDG_DATA_HOME": f"{home}/data"}
        quiet: dict[str, Any] = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "env": env, "start_new_session": True}
        subprocess.run([str(rerun_binary()), "analytics", "disable"], timeout=ASSETS_TIMEOUT_S, check=False, **quiet)
        port = _free_port()
        url = f"http://{LOOPBACK}:{port}"
        proc = subprocess.Popen(
            [str(rerun_binary()), "--serve-web", "--bind", LOOPBACK, "--web-viewer-port", str(port), f"{url}/{STREAM}"], preexec_fn=die_with_parent, **quiet
        )
        deadline = time.monotonic() + ASSETS_TIMEOUT_S
        while not _listening(port):
            if proc.poll() is not None or time.monotonic() > deadline:
                raise ViewError(f"the package's Rerun viewer did not start (exit {proc.poll()})")
            time.sleep(0.05)
        files = {}
        for name in ASSETS:
            with urllib.request.urlopen(f"{url}/{name}", timeout=ASSETS_TIMEOUT_S) as r:
                files[name] = r.read()
    except (OSError, subprocess.SubprocessError) as exc:
        raise ViewError(f"the package's Rerun viewer did not hand over its page: {exc}") from None
    finally:
        if proc is not None:
            _stop(proc)
        shutil.rmtree(home, ignore_errors=True)
    page = EXTERNAL_LINK.sub("", files["index.html"].decode())
    if "<head>" not in page:
        raise ViewError("the package's Rerun viewer page has no <head>: a Rerun this version of netsetest does not know")
    files["index.html"] = page.replace("<head>", "<head>" + NO_STORAGE, 1).encode()
    return files


def _free_port() -> int:
    with socket.socket() as s:
        s.bind((LOOPBACK, 0))
        return s.getsockname()[1]


def _listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex((LOOPBACK, port)) == 0


def _stop(proc: subprocess.Popen, grace_s: float = 5.0) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(grace_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def die_with_parent() -> None:
    """In a child: SIGTERM when its parent dies (no orphan serving a finished run)."""
    import ctypes

    ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)


PR_SET_PDEATHSIG = 1  # prctl(2)


# ------------------------------------------------------------------------------------ the stream


@dataclass(frozen=True)
class Piece:
    """One read of the view's RRD sink: a complete stream of its own (Rerun decodes pieces one after another)."""

    seq: int
    data: bytes


@dataclass
class StreamBuffer:
    """The view's stream as pieces, for every browser: the pinned ones (the recording's start, the layouts, the
    series' styles) always, the others up to ``limit`` bytes, the oldest going first.  A browser reads from its
    own position on; one that fell behind what is kept skips what went (its view of those steps is lost)."""

    limit: int = STREAM_MEMORY
    pinned: list[Piece] = field(default_factory=list)
    recent: deque[Piece] = field(default_factory=deque)
    recent_bytes: int = 0
    next_seq: int = 0
    closed: bool = False
    cond: threading.Condition = field(default_factory=threading.Condition)

    def add(self, data: bytes, pinned: bool) -> None:
        with self.cond:
            piece = Piece(self.next_seq, data)
            self.next_seq += 1
            if pinned:
                self.pinned.append(piece)
            else:
                self.recent.append(piece)
                self.recent_bytes += len(data)
                while self.recent_bytes > self.limit and len(self.recent) > 1:
                    self.recent_bytes -= len(self.recent.popleft().data)
            self.cond.notify_all()

    def after(self, seq: int, timeout: float) -> tuple[list[bytes], int] | None:
        """The kept pieces from ``seq`` on (waiting up to ``timeout`` for one) and the position after them; None
        once the stream is closed and nothing is left to read."""
        with self.cond:
            self.cond.wait_for(lambda: self.next_seq > seq or self.closed, timeout)
            if self.next_seq <= seq:
                return None if self.closed else ([], seq)
            recent = []
            for p in reversed(self.recent):  # a browser keeping up reads from the end
                if p.seq < seq:
                    break
                recent.append(p)
            pieces = sorted([p for p in self.pinned if p.seq >= seq] + recent, key=lambda p: p.seq)
            return [p.data for p in pieces], self.next_seq

    def close(self) -> None:
        with self.cond:
            self.closed = True
            self.cond.notify_all()


# ------------------------------------------------------------------------------------ the server


class _Server(ThreadingHTTPServer):
    daemon_threads = True  # a browser's open stream never holds the view's exit
    request_queue_size = 16  # a page opens its script, WebAssembly, icon and stream at once
    token: str
    assets: dict[str, bytes]
    buffer: StreamBuffer

    def handle_error(self, request: Any, client_address: Any) -> None:
        """A browser that goes away mid-response is no error of the view's (the default prints a traceback)."""


class _Handler(BaseHTTPRequestHandler):
    server: _Server
    timeout = REQUEST_TIMEOUT_S
    server_version = "netsetest-view"
    sys_version = ""

    def log_message(self, format: str, *args: Any) -> None:
        """Quiet: the view's terminal shows its own lines only."""

    def send_error(self, code: int, message: str | None = None, explain: str | None = None) -> None:
        """Every refusal alike (a method it does not take: 501; a malformed request: 400): the status and no body."""
        self.close_connection = True
        self._empty(code)

    def do_GET(self) -> None:
        self._answer(body=True)

    def do_HEAD(self) -> None:
        self._answer(body=False)

    def _answer(self, body: bool) -> None:
        path, _, query = self.path.partition("?")
        parts = path.split("/")
        if len(parts) != 3 or parts[0] or not secrets.compare_digest(parts[1].encode(), self.server.token.encode()):
            self._empty(404)
            return
        name = parts[2] or "index.html"
        if name == STREAM:
            self._stream(body)
        elif name == "index.html" and "url=" not in query:
            self._to_page()
        elif name in ASSETS:
            data = self.server.assets[name]
            self._head(200, ASSETS[name], len(data))
            if body:
                self.wfile.write(data)
        else:
            self._empty(404)

    def _head(self, status: int, ctype: str | None = None, length: int | None = None, extra: dict[str, str] | None = None) -> None:
        self.send_response(status)
        for k, v in {**HEADERS, **(extra or {})}.items():
            self.send_header(k, v)
        if ctype is not None:
            self.send_header("Content-Type", ctype)
        if length is not None:
            self.send_header("Content-Length", str(length))
        self.end_headers()

    def _empty(self, status: int) -> None:
        self._head(status, length=0)

    def _to_page(self) -> None:
        """The page with the stream's address in ``?url=``, at the host and port the browser used (through
        ``ssh -L`` a local port may differ from the view's)."""
        host = self.headers.get("Host", "")
        if not HOST.fullmatch(host):
            host = f"{LOOPBACK}:{self.server.server_address[1]}"
        query = urlencode({"url": f"http://{host}/{self.server.token}/{STREAM}", **PAGE_OPTIONS})
        self._head(303, length=0, extra={"Location": f"/{self.server.token}/?{query}"})

    def _stream(self, body: bool) -> None:
        """Everything kept, then every new piece as the view sends it, until the view stops."""
        self._head(200, "application/octet-stream")
        if not body:
            return
        seq = 0
        while True:
            got = self.server.buffer.after(seq, STREAM_POLL_S)
            if got is None:
                return
            pieces, seq = got
            for data in pieces:
                self.wfile.write(data)
            self.wfile.flush()


@dataclass
class ViewerServer:
    """The view's server (module doc) and the Rerun recording stream whose pieces it hands out."""

    rec: Any  # a rerun.RecordingStream to Rerun's in-memory RRD sink
    sink: Any  # its rerun.BinaryStream
    http: _Server
    thread: threading.Thread
    url: str
    buffer: StreamBuffer

    def send(self, pinned: bool, timeout_s: float) -> None:
        """What has been logged, to every browser now (``pinned``: kept for every browser that connects later).
        RuntimeError when Rerun's encoder does not finish within ``timeout_s``."""
        data = self.sink.read(flush=True, flush_timeout_sec=timeout_s)
        if data:
            self.buffer.add(data, pinned)

    def close(self) -> None:
        """What is left goes to the browsers, then the stream ends for every one, the server closes and the
        recording stream disconnects (its sink read empty: Rerun warns of data it drops unread)."""
        with contextlib.suppress(RuntimeError):  # Rerun's encoder did not finish in time: the view is stopping anyway
            self.send(pinned=False, timeout_s=CLOSE_FLUSH_S)
        self.buffer.close()
        self.http.shutdown()
        self.http.server_close()
        self.thread.join()
        self.rec.disconnect()
        self.sink.read(flush=False)


def serve(port: int, app_id: str) -> ViewerServer:
    """The view's server on ``port`` of the loopback address (0: a free one) and a recording stream feeding it;
    PortTaken when the port is taken, ViewError when the viewer's files cannot be had."""
    import rerun as rr

    http = _bind(port)  # first: a taken port fails at once
    try:
        assets = viewer_assets()
    except ViewError:
        http.server_close()
        raise
    http.token, http.assets, http.buffer = secrets.token_urlsafe(TOKEN_BYTES), assets, StreamBuffer()
    thread = threading.Thread(target=http.serve_forever, name="view-http", daemon=True)
    thread.start()
    rec = rr.RecordingStream(app_id)
    sink = rr.binary_stream(recording=rec)
    return ViewerServer(rec, sink, http, thread, f"http://{LOOPBACK}:{http.server_address[1]}/{http.token}/", http.buffer)
