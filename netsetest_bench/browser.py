"""A page in headless Chromium (Debian's ``chromium``, installed by .ci/run), driven over the DevTools
protocol on a pipe (``--remote-debugging-pipe``: JSON messages separated by NUL on fds 3 and 4), so it
needs no websocket client and no browser download.  The browser tests (tests/process/test_browser.py)
and the benchmark's report-page figures (netsetest_bench/view.py) use it.

:func:`load_page` opens a page, waits until a JavaScript condition holds (:data:`BOKEH_READY`: BokehJS
has rendered every root), evaluates the caller's expressions, collects every console error and uncaught
exception, times the page (its load event, first contentful paint and the condition; the CPU its renderer
used), and takes a full-page screenshot.  The browser's profile and temporary files live in the caller's directory
(nothing in the system's /tmp).
"""

from __future__ import annotations

import base64
import fcntl
import io
import json
import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
RENDER_TIMEOUT_S = 60.0  # the machine is shared: a loaded core still renders a 1.5 MB page within this
PAGE_WIDTH = 1200  # px
PAGE_HEIGHT = 900  # px: the window's height (a screenshot takes the whole page's)
UNTIL_POLL_S = 0.5  # how often this process evaluates the caller's ``until`` condition
READY_POLL_MS = 5  # the page checks the caller's condition this often (its own timer: the ready time is the page's)


class NoBrowser(Exception):
    """No Chromium on this machine (the message says how to install it)."""


def chromium() -> str:
    """The browser's path (:class:`NoBrowser` when none is installed)."""
    for name in CHROMIUM_NAMES:
        path = shutil.which(name)
        if path:
            return path
    raise NoBrowser("no Chromium on this machine (.ci/run installs Debian's chromium with apt-get; install it to open pages headless)")


@dataclass
class Page:
    """What the browser saw: the results of the expressions, console errors, the screenshot (PNG), and
    when it got there, in ms from the navigation's start (``timings``: ``load_event_ms`` the load event's
    end and ``ready_ms`` the first check at which the caller's condition held, by the page's clock;
    ``first_contentful_paint_ms`` DevTools' lifecycle event; ``main_thread_cpu_ms`` / ``renderer_cpu_ms``
    the CPU the page's renderer used, its main thread and all its threads: the page's own cost, which a
    loaded machine does not inflate as it does the times; a value the browser did not report is None)."""

    values: dict[str, Any]
    errors: list[str] = field(default_factory=list)
    failed_requests: list[str] = field(default_factory=list)  # URLs the page asked for and did not get
    requests: list[str] = field(default_factory=list)  # every URL the page asked for (DevTools' Network domain), in order
    screenshot: bytes = b""
    load_s: float = 0.0  # wall time from navigating to the condition seen true by this process
    timings: dict[str, float | None] = field(default_factory=dict)

    def pixel_std(self) -> float:
        """Standard deviation of the screenshot's grey levels: about 0 for a blank page."""
        from PIL import Image

        img = np.asarray(Image.open(io.BytesIO(self.screenshot)).convert("L"), dtype=float)
        return float(img.std())


class _Cdp:
    """Commands and events of the DevTools protocol over the pipe."""

    def __init__(self, proc: subprocess.Popen, to_browser: int, from_browser: int, timeout: float) -> None:
        self.timeout = timeout
        self.proc, self._out, self._in = proc, os.fdopen(to_browser, "wb", buffering=0), os.fdopen(from_browser, "rb", buffering=0)
        self._buf = b""
        self._id = 0
        self.events: list[dict] = []
        self.log: Path | None = None  # the browser's stderr (load_page writes it beside the profile)

    def _read(self, deadline: float) -> dict:
        while b"\0" not in self._buf:
            if time.monotonic() > deadline:
                raise TimeoutError("the browser did not answer")
            chunk = self._in.read(65536)
            if not chunk:
                raise RuntimeError(f"the browser closed the pipe (exit {self.proc.poll()}): {self._said()}")
            self._buf += chunk
        msg, self._buf = self._buf.split(b"\0", 1)
        return json.loads(msg)

    def _said(self) -> str:
        """The tail of the browser's stderr (load_page writes it beside the profile)."""
        return self.log.read_text(errors="replace")[-2000:] if self.log is not None and self.log.exists() else "(no log)"

    def send(self, method: str, params: dict | None = None, session: str | None = None, timeout: float | None = None) -> dict:
        self._id += 1
        cmd: dict[str, Any] = {"id": self._id, "method": method, "params": params or {}}
        if session:
            cmd["sessionId"] = session
        self._out.write(json.dumps(cmd).encode() + b"\0")
        deadline = time.monotonic() + (timeout or self.timeout)
        while True:
            msg = self._read(deadline)
            if msg.get("id") == self._id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            self.events.append(msg)

    def close(self) -> None:
        self._out.close()
        self._in.close()


def _errors(events: list[dict]) -> list[str]:
    out = []
    for e in events:
        m, p = e.get("method"), e.get("params", {})
        if m == "Runtime.exceptionThrown":
            d = p.get("exceptionDetails", {})
            out.append(f"exception: {d.get('exception', {}).get('description') or d.get('text')}")
        elif m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
            out.append("console.error: " + " ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", [])))
        elif m == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
            out.append(f"log: {p['entry'].get('text')} ({p['entry'].get('url', '')})")
    return out


def _requests(events: list[dict]) -> list[str]:
    """Every request the page made, as the browser's network stack saw it: fetches, scripts, styles, fonts,
    images, workers (``Network.requestWillBeSent``) and WebSockets (``Network.webSocketCreated``)."""
    return [
        e["params"]["request"]["url"] if e["method"] == "Network.requestWillBeSent" else e["params"]["url"] for e in events if e.get("method") in REQUEST_EVENTS
    ]


REQUEST_EVENTS = ("Network.requestWillBeSent", "Network.webSocketCreated")


def _failed_requests(events: list[dict]) -> list[str]:
    """The URLs of the requests the page did not get: ``Network.loadingFailed``, except one the browser reports as
    cancelled after the page had every byte its response declared (its Content-Length, the sum of its
    ``Network.dataReceived``).  Measured with the live view's 43 MB viewer on two loaded cores: the page read the
    whole body (43 166 975 bytes of 43 166 975) and started, and Chromium then reported the fetch as
    ``net::ERR_ABORTED``, cancelled: its renderer had finished with the body before the network service's word
    that the load was complete reached it.  That is a load the page completed; one short of its length, or failed
    for any other reason, is not."""
    urls = {e["params"]["requestId"]: e["params"]["request"]["url"] for e in events if e.get("method") == "Network.requestWillBeSent"}
    declared: dict[str, int] = {}
    got: dict[str, int] = {}
    for e in events:
        p = e.get("params", {})
        if e.get("method") == "Network.responseReceived":
            length = next((v for k, v in p["response"].get("headers", {}).items() if k.lower() == "content-length"), None)
            if length is not None and str(length).isdigit():
                declared[p["requestId"]] = int(length)
        elif e.get("method") == "Network.dataReceived":
            got[p["requestId"]] = got.get(p["requestId"], 0) + p.get("dataLength", 0)

    def whole(rid: str) -> bool:
        return rid in declared and got.get(rid, 0) >= declared[rid]

    return [
        urls.get(e["params"]["requestId"], "?")
        for e in events
        if e.get("method") == "Network.loadingFailed" and not (e["params"].get("canceled") and whole(e["params"]["requestId"]))
    ]


READY_MARK = "__netsetestReadyMs"  # set by the page's own timer once the caller's condition holds


def _ready_timer(ready: str) -> str:
    """A script run before the page's own: every READY_POLL_MS it checks ``ready`` (an exception counts as
    not yet: the page's libraries may not be there) and, once true, keeps the page's clock in READY_MARK."""
    return (
        f"(() => {{ const t = setInterval(() => {{ let ok = false; try {{ ok = !!({ready}); }} catch (e) {{}} "
        f"if (ok) {{ window.{READY_MARK} = performance.now(); clearInterval(t); }} }}, {READY_POLL_MS}); }})();"
    )


TIMINGS = (
    "(() => { const n = performance.getEntriesByType('navigation')[0]; "
    f"return {{load_event_ms: n && n.loadEventEnd > 0 ? n.loadEventEnd : null, ready_ms: window.{READY_MARK} ?? null}}; }})()"
)
"""An expression: the load event's end and the ready time (ms from the navigation's start, the page's clock)."""


def _devtools_timings(events: list[dict], metrics: list[dict]) -> dict[str, float | None]:
    """What DevTools reports of the page: its first contentful paint (the lifecycle event, ms from the
    navigation's start: headless Chromium leaves the page's own paint entries empty) and the CPU its
    renderer used (main thread, whole process), from the renderer's start to now."""
    m = {x["name"]: x["value"] for x in metrics}
    paints = [e["params"]["timestamp"] for e in events if e.get("method") == "Page.lifecycleEvent" and e["params"]["name"] == "firstContentfulPaint"]
    start = m.get("NavigationStart")
    return {
        "first_contentful_paint_ms": 1000.0 * (paints[-1] - start) if paints and start else None,
        "main_thread_cpu_ms": 1000.0 * m["ThreadTime"] if "ThreadTime" in m else None,
        "renderer_cpu_ms": 1000.0 * m["ProcessTime"] if "ProcessTime" in m else None,
    }


WASM_BASELINE = ("--liftoff", "--no-wasm-tier-up")
"""V8 flags that keep a WebAssembly module on its baseline compiler: a large module (the Rerun viewer, 30 MB)
is not compiled a second time by the optimising tier in the background, which on two shared cores took the
CPU the page's own work needed (a test of the live view: 111 s → 61 s at load 10)."""


def load_page(
    url: str,
    workdir: Path,
    expressions: dict[str, str],
    ready: str,
    height: int | None = None,
    settle_s: float = 0.0,
    timeout: float = RENDER_TIMEOUT_S,
    js_flags: tuple[str, ...] = (),
    width: int = PAGE_WIDTH,
    until: Callable[[Callable[[str], Any]], bool] | None = None,
    window_height: int = PAGE_HEIGHT,
) -> Page:
    """Open ``url``, wait until the JavaScript expression ``ready`` is true (and then until ``until(evaluate)``
    holds, a check too costly for the page's own timer, made by this process every UNTIL_POLL_S: ``evaluate``
    gives an expression's value, None where it throws), evaluate ``expressions``
    (name → expression, JSON-serialisable results) after ``settle_s`` more seconds, and screenshot the whole
    page (or its top ``height`` px); ``timeout`` bounds each step (a page compiling a large WebAssembly module
    on a loaded machine answers late); ``js_flags``: V8's flags for the page (:data:`WASM_BASELINE`); ``width``
    and ``window_height``: the window's, px."""
    browser = chromium()
    profile = workdir / "chromium-profile"
    profile.mkdir(parents=True, exist_ok=True)
    to_r, to_w = os.pipe()  # the browser reads commands on its fd 3
    from_r, from_w = os.pipe()  # and writes answers on its fd 4

    def fds() -> None:  # in the child: the two pipe ends where Chromium expects them, moved above 4 first so
        # that neither dup2 overwrites the other's source (a pipe end may itself be fd 3 or 4)
        r, w = fcntl.fcntl(to_r, fcntl.F_DUPFD, 10), fcntl.fcntl(from_w, fcntl.F_DUPFD, 10)
        os.dup2(r, 3)
        os.dup2(w, 4)

    # Chromium's singleton socket lives under TMPDIR, and a socket path has at most 107 bytes: a pytest-xdist
    # tmp_path is too long ("Socket path too long", then an abort), so a short directory of the session's own
    short = Path(tempfile.mkdtemp(prefix="cr-"))
    env = {**os.environ, "TMPDIR": str(short), "HOME": str(workdir)}
    log = (workdir / "chromium.log").open("wb")  # its own words, quoted when it dies (_Cdp._read)
    proc = subprocess.Popen(
        [
            browser,
            "--headless",
            "--disable-gpu",
            "--no-sandbox",
            "--remote-debugging-pipe",
            f"--user-data-dir={profile}",
            "--no-first-run",
            "--disable-extensions",
            "--disable-background-networking",
            "--disable-crash-reporter",
            "--hide-scrollbars",
            *([f"--js-flags={' '.join(js_flags)}"] if js_flags else []),
            "about:blank",
        ],
        preexec_fn=fds,
        pass_fds=(3, 4),  # kept open across exec (preexec_fn runs before the other fds are closed)
        stdout=subprocess.DEVNULL,
        stderr=log,
        env=env,
    )
    log.close()
    os.close(to_r)
    os.close(from_w)
    cdp = _Cdp(proc, to_w, from_r, timeout)
    cdp.log = workdir / "chromium.log"
    try:
        target = cdp.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = cdp.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Runtime", "Log", "Page", "Network", "Performance"):
            cdp.send(f"{domain}.enable", session=session)
        cdp.send("Emulation.setDeviceMetricsOverride", {"width": width, "height": window_height, "deviceScaleFactor": 1, "mobile": False}, session=session)
        cdp.send("Page.addScriptToEvaluateOnNewDocument", {"source": _ready_timer(ready)}, session=session)
        cdp.send("Page.setLifecycleEventsEnabled", {"enabled": True}, session=session)
        start = time.monotonic()
        cdp.send("Page.navigate", {"url": url}, session=session)
        deadline = start + timeout
        while not cdp.send("Runtime.evaluate", {"expression": f"window.{READY_MARK} !== undefined", "returnByValue": True}, session=session)["result"].get(
            "value"
        ):
            if time.monotonic() > deadline:
                raise TimeoutError(f"the page did not become ready ({ready}) within {timeout:g} s")
            time.sleep(0.1)
        load_s = time.monotonic() - start
        timings = cdp.send("Runtime.evaluate", {"expression": TIMINGS, "returnByValue": True}, session=session)["result"].get("value") or {}
        timings |= _devtools_timings(cdp.events, cdp.send("Performance.getMetrics", session=session)["metrics"])

        def evaluate(expr: str) -> Any:
            res = cdp.send("Runtime.evaluate", {"expression": expr, "returnByValue": True}, session=session)
            return None if "exceptionDetails" in res else res["result"].get("value")

        while until is not None and not until(evaluate):
            if time.monotonic() > deadline:
                raise TimeoutError(f"the page was ready, but the caller's condition did not hold within {timeout:g} s")
            time.sleep(UNTIL_POLL_S)
        time.sleep(settle_s)
        values = {}
        for name, expr in expressions.items():
            res = cdp.send("Runtime.evaluate", {"expression": expr, "returnByValue": True}, session=session)
            if "exceptionDetails" in res:
                raise RuntimeError(f"{name}: {res['exceptionDetails'].get('exception', {}).get('description')}")
            values[name] = res["result"].get("value")
        full = cdp.send("Runtime.evaluate", {"expression": "document.documentElement.scrollHeight", "returnByValue": True}, session=session)["result"]["value"]
        h = min(int(full), height) if height else int(full)
        cdp.send("Emulation.setDeviceMetricsOverride", {"width": width, "height": h, "deviceScaleFactor": 1, "mobile": False}, session=session)
        time.sleep(0.5)  # a resize re-renders the canvases
        shot = base64.b64decode(cdp.send("Page.captureScreenshot", {"format": "png"}, session=session)["data"])
        errors = _errors(cdp.events)
        failed = _failed_requests(cdp.events)
        requests = _requests(cdp.events)
        try:
            cdp.send("Browser.close", timeout=10)
        except (RuntimeError, TimeoutError):
            pass
        return Page(values, errors, failed, requests, shot, load_s, timings)
    finally:
        cdp.close()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        shutil.rmtree(short, ignore_errors=True)


BOKEH_READY = (
    "window.Bokeh !== undefined && Bokeh.documents.length > 0 && Bokeh.index !== undefined && "
    "Bokeh.documents[0].roots().every(r => Bokeh.index[r.id] !== undefined)"
)
"""BokehJS has built a view for every root of the page."""


def named(name: str) -> str:
    """An expression: the data of the renderer called ``name`` (its ``node`` column), or null."""
    return f"(() => {{ const m = Bokeh.documents[0].get_model_by_name({json.dumps(name)}); if (m === null) return null; const d = m.data_source.data; return Array.from(d instanceof Map ? d.get('node') : d['node']); }})()"
