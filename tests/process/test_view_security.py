"""The live view (``netsetest view``, ``run --view``) as processes: another account can neither read nor write it
(issue 41, item 2), Ctrl-C ends it with 130 and leaves nothing behind (item 4), and it serves on the one port it
is given, with one clear line when that port is taken (item 5).  The server's answers in detail:
tests/unit/test_view_server.py; the page in a browser: tests/process/test_browser.py."""

from __future__ import annotations

import json
import os
import pwd
import re
import signal
import subprocess
import sys
import sysconfig
import threading
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from zenoh_helpers import PAPER6, ProcessGuard, cli, free_ports, new_run_id, wait_for

from netsetest.runtime.report import EXIT_BAD_INPUT, EXIT_INTERRUPTED

pytest.importorskip("rerun")

URL = re.compile(r"live view(?: of run \S+)?: (http://127\.0\.0\.1:(\d+)/\S*)")
STREAM = "recording.rrd"
RUN_STEPS = 3000  # far more than the test needs: the run is still going when it is interrupted
RUN_PACE_S = 0.2  # s a step: the run goes on, at a small cost
START_S = 120.0  # the view imports Rerun and fetches its page; a loaded machine is slow at it
FORGED = "FORGED-BY-NOBODY"
PROBE_S = 240.0  # the second account's whole probe (every port: a few requests of at most 3 s each, a forged log)
SYSTEM_PYTHONS = ("/usr/bin/python3", "/usr/local/bin/python3")  # outside any home: runnable by another account
STEP0 = "are ready; clock"  # the vehicle's line right before step 0 (bench/zenoh_runs.py STEP0_LINE)


def _url(text: str) -> tuple[str, int] | None:
    m = URL.search(text)
    return (m.group(1), int(m.group(2))) if m else None


class Reader(threading.Thread):
    """A browser's fetch of the view's stream: reads until the stream ends (or fails)."""

    def __init__(self, url: str) -> None:
        super().__init__(daemon=True)
        self.url, self.data, self.error = url, bytearray(), None

    def run(self) -> None:
        try:
            with urllib.request.urlopen(self.url, timeout=60) as r:
                while chunk := r.read1(65536):
                    self.data += chunk
        except (OSError, urllib.error.URLError) as exc:
            self.error = repr(exc)


def _env(tmp: Path) -> dict[str, str]:
    """The view's (and the run's) temporary files go to ``tmp``, so that what is left there is theirs."""
    tmp.mkdir()
    return {**os.environ, "TMPDIR": str(tmp)}


def _start(procs: ProcessGuard, how: str, tmp: Path, extra: list[str]) -> tuple[str, str]:
    """``view`` (of a run that is not there: it serves anyway) or ``run --view`` (a secured run); its name."""
    if how == "view":
        (zport,) = free_ports(1)
        procs.start("view", cli("view", "--run-id", new_run_id("view"), "--connect", f"tcp/127.0.0.1:{zport}", *extra), env=_env(tmp))
        return "view", "view.out"
    run_id = new_run_id("runview")
    procs.markers.add(run_id)
    argv = cli("run", PAPER6, "--run-id", run_id, "--steps", str(RUN_STEPS), "--pace", str(RUN_PACE_S), "--view", *extra)
    procs.start("run", argv, env=_env(tmp))
    return "run", "run.err"


def _view_url(procs: ProcessGuard, name: str, log: str) -> tuple[str, int]:
    got = wait_for(
        lambda: _url((procs.logdir / log).read_text(errors="replace")) if (procs.logdir / log).exists() else None, START_S, what="the view's address"
    )
    assert procs.procs[name].poll() is None, procs.logs()
    return got  # type: ignore[return-value]  # wait_for returns the value once true


def _stepping(procs: ProcessGuard, name: str) -> None:
    """A run is past its start-up: every role is ready and step 0 is out (the vehicle's line)."""
    if name == "run":
        wait_for(lambda: STEP0 in procs.stderr(name), START_S, what="the run's first step")


def _ctrl_c(procs: ProcessGuard, name: str) -> int:
    """Ctrl-C at the terminal: SIGINT to the process group (the command, its roles, its view)."""
    os.killpg(procs.procs[name].pid, signal.SIGINT)
    return procs.wait(name, 60)


@pytest.mark.timeout(300)
@pytest.mark.parametrize("how", ["view", "run --view"])
def test_ctrl_c_ends_the_view_with_130_and_leaves_nothing(how: str, procs: ProcessGuard, tmp_path: Path) -> None:
    """Ctrl-C while a browser reads the stream: exit 130 as ``run``, no traceback (once: ``RuntimeError: gRPC
    connection severed`` and exit 1), the browser's stream ends, nothing left in the temporary directory (once:
    ``/tmp/netsetest-view-*``) and no process (the ``procs`` fixture)."""
    tmp = tmp_path / "tmp"
    name, log = _start(procs, how, tmp, [])
    url, _ = _view_url(procs, name, log)
    reader = Reader(url + STREAM)
    reader.start()
    _stepping(procs, name)
    wait_for(lambda: len(reader.data) > 0 or not reader.is_alive(), 60, what="the stream's first bytes")
    assert _ctrl_c(procs, name) == EXIT_INTERRUPTED, procs.logs()
    err = procs.stderr(name)
    assert "Traceback" not in err and "Error" not in err, err
    assert list(tmp.iterdir()) == []
    reader.join(30)
    assert not reader.is_alive() and reader.error is None and reader.data.startswith(b"RRF2"), reader.error


@pytest.mark.timeout(300)
def test_the_view_serves_on_the_one_port_given_and_a_taken_port_is_one_line(procs: ProcessGuard, tmp_path: Path) -> None:
    """``--port N``: the page and the stream on N, and no other port (once: a second, random one for Rerun's
    gRPC proxy, so remote watching needed two tunnels); N taken: ``view`` and ``run --view --view-port N``
    exit 2 with one line naming the option, the address and why, before a role starts."""
    (port,) = free_ports(1)
    name, log = _start(procs, "view", tmp_path / "tmp", ["--port", str(port)])
    url, got_port = _view_url(procs, name, log)
    assert got_port == port and url.startswith(f"http://127.0.0.1:{port}/")
    assert _listening_ports(_tree(procs.procs[name].pid)) == {port}
    with urllib.request.urlopen(url, timeout=30) as r:  # the page, by way of the redirect to its stream's address
        assert r.status == 200 and b"re_viewer.js" in r.read()
    for argv, option in (
        (cli("view", "--run-id", new_run_id("taken"), "--port", str(port), "--duration", "30"), "--port"),
        (cli("run", PAPER6, "--steps", "5", "--view", "--view-port", str(port), "--quiet"), "--view-port"),
    ):
        p = subprocess.run(argv, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
        lines = p.stderr.strip().splitlines()
        assert p.returncode == EXIT_BAD_INPUT and len(lines) == 1, p.stderr
        assert f"{option} {port}: 127.0.0.1:{port} is taken" in lines[0], lines
    assert _ctrl_c(procs, name) == EXIT_INTERRUPTED


# ------------------------------------------------------------------------------ another account

PROBE = r"""
import json, os, socket, sys, time
ports, pids, forged = json.loads(sys.argv[1]), json.loads(sys.argv[2]), sys.argv[3]
out = {"uid": os.getuid(), "http": [], "grpc": [], "fds": {}, "proc": ""}


def ask(port, method, path):
    # [status or None, the body's first bytes, its length]: at most 3 s and 64 KiB of an answer (a stream never ends)
    body = forged.encode() if method != "GET" else b""
    end, got = time.monotonic() + 3, b""
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=3) as s:
            s.sendall(f"{method} {path} HTTP/1.0\r\nHost: 127.0.0.1:{port}\r\nContent-Length: {len(body)}\r\n\r\n".encode() + body)
            while len(got) < 1 << 16 and (left := end - time.monotonic()) > 0:
                s.settimeout(left)
                chunk = s.recv(4096)
                if not chunk:
                    break
                got += chunk
    except OSError as e:
        if not got:
            return [None, type(e).__name__, 0]
    head, _, rest = got.partition(b"\r\n\r\n")
    parts = head.split(b" ", 2)
    status = int(parts[1]) if len(parts) > 1 and parts[0].startswith(b"HTTP/") and parts[1].isdigit() else None
    return [status, rest[:4].decode(errors="replace"), len(rest)]


for port in ports:
    for method in ("GET", "POST"):
        for path in ("/", "/recording.rrd", "/proxy", "/x/recording.rrd"):
            print("http", port, method, path, file=sys.stderr, flush=True)
            out["http"].append([port, method, path, *ask(port, method, path)])
def forge(port, res):
    rec = rr.RecordingStream("netsetest")
    rec.connect_grpc(f"rerun+http://127.0.0.1:{port}/proxy")
    for k in range(50):
        rec.set_time("step", sequence=k)
        rec.log("verdict", rr.TextDocument(forged + ": PASS"))
    try:
        rec.flush(timeout_sec=5)
        res.append("flushed")
    except Exception as e:
        res.append(type(e).__name__)


try:
    import threading
    import rerun as rr
    for port in ports:  # what the issue's forger did: Rerun's SDK, logging into the view's recording
        print("grpc", port, file=sys.stderr, flush=True)
        res = []
        t = threading.Thread(target=forge, args=(port, res), daemon=True)  # Rerun's SDK may hang on a port that is no gRPC server
        t.start()
        t.join(20)
        out["grpc"].append([port, res[0] if res else "no answer"])
except Exception as e:
    out["grpc"].append([None, repr(e)])
texts = []
for d in filter(str.isdigit, os.listdir("/proc")):  # where a token could be seen by another account
    for what in ("cmdline", "environ"):
        try:
            with open(f"/proc/{d}/{what}", "rb") as f:
                texts.append(f.read().decode(errors="replace"))
        except OSError:
            pass
out["proc"] = "\n".join(texts)
for pid in pids:  # the view's standard output, where it prints its address
    for fd in (0, 1, 2):
        try:
            open(f"/proc/{pid}/fd/{fd}", "rb").close()
            out["fds"][f"{pid}/{fd}"] = "opened"
        except OSError as e:
            out["fds"][f"{pid}/{fd}"] = e.errno
print(json.dumps(out), flush=True)
os._exit(0)  # not waiting for a recording stream Rerun could not close
"""


def _as(uid: int, gid: int, argv: list[str], timeout: float, pythonpath: str | None = None) -> subprocess.CompletedProcess:
    """``argv`` as user ``uid`` (no supplementary groups, a home it cannot write, in /); a test failure, with
    what it said, if it takes longer than ``timeout``."""
    try:
        return _run_as(uid, gid, argv, timeout, pythonpath)
    except subprocess.TimeoutExpired as exc:
        said = exc.stderr.decode(errors="replace") if isinstance(exc.stderr, bytes) else exc.stderr
        pytest.fail(f"{argv[0]} as uid {uid} did not finish within {timeout:g} s; its last words: {(said or '')[-500:]}")


def _run_as(uid: int, gid: int, argv: list[str], timeout: float, pythonpath: str | None) -> subprocess.CompletedProcess:
    return subprocess.run(
        argv,
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd="/",
        env={"PATH": os.environ["PATH"], "HOME": "/nonexistent", "LANG": "C.UTF-8", **({"PYTHONPATH": pythonpath} if pythonpath else {})},
        preexec_fn=lambda: (os.setgroups([]), os.setgid(gid), os.setuid(uid)),  # type: ignore[func-returns-value]  # called for its effect
    )


def _python_for(uid: int, gid: int) -> tuple[str, str | None]:
    """A Python that ``uid`` may run with Rerun's SDK (to forge as the issue's forger did), and its PYTHONPATH:
    this one, else the system's of the same version with this environment's packages (this interpreter may
    live in root's home, which nobody may enter)."""
    purelib = sysconfig.get_paths()["purelib"]
    check = "import sys, rerun; print(tuple(sys.version_info[:2]))"
    for exe, path in ((sys.executable, None), *((exe, purelib) for exe in SYSTEM_PYTHONS)):
        try:
            ok = _as(uid, gid, [exe, "-c", check], timeout=60, pythonpath=path)
        except PermissionError:  # not nobody's to run
            continue
        if ok.returncode == 0 and ok.stdout.strip() == str(tuple(sys.version_info[:2])):
            return exe, path
    pytest.skip("no Python with Rerun's SDK that user nobody may run (this one is not readable by nobody)")


def _as_nobody() -> tuple[int, int]:
    if os.geteuid() != 0:
        pytest.skip("a second account's view needs root to switch to it (user nobody)")
    try:
        pw = pwd.getpwnam("nobody")
    except KeyError:
        pytest.skip("no user nobody on this machine")
    return pw.pw_uid, pw.pw_gid


@pytest.mark.timeout(400)
def test_another_account_can_neither_read_nor_write_the_view(procs: ProcessGuard, tmp_path: Path) -> None:
    """``run --view`` (secured, its view an observer with ``--credentials``) as root; user nobody, knowing every
    port the view listens on and its pid, asks every port for the page, the stream and Rerun's paths, posts to
    it, logs a forged verdict into it with Rerun's SDK (once the issue's forger's 400 panels reached every
    browser), and looks for the address in every process's command line and environment and in the view's
    standard output: it gets nothing but 404 and refusals, and the stream the user reads to its end holds
    the truth and no forged line."""
    uid, gid = _as_nobody()
    name, log = _start(procs, "run --view", tmp_path / "tmp", [])
    url, port = _view_url(procs, name, log)
    token = url.rstrip("/").rsplit("/", 1)[-1]
    reader = Reader(url + STREAM)  # the user's browser, reading from the start to the view's end
    reader.start()
    _stepping(procs, name)
    view_pids = [p for p in _tree(procs.procs[name].pid) if "view" in _argv(p)]
    assert view_pids, procs.logs()
    pids = [q for p in view_pids for q in _tree(p)]
    ports = sorted(_listening_ports(pids))
    assert port in ports
    python, pythonpath = _python_for(uid, gid)
    probe = _as(uid, gid, [python, "-c", PROBE, json.dumps(ports), json.dumps(pids), FORGED], timeout=PROBE_S, pythonpath=pythonpath)
    assert probe.returncode == 0, probe.stderr[-3000:]
    seen = json.loads(probe.stdout)
    assert seen["uid"] == uid
    assert [g[0] for g in seen["grpc"]] == ports, seen["grpc"]  # the forger tried every port
    answered = [h for h in seen["http"] if h[3] is not None]
    assert answered, seen["http"]  # the server was there to ask
    assert all(h[3] in (404, 501) and h[5] == 0 for h in answered), [h for h in answered if h[3] not in (404, 501) or h[5]]
    assert token not in seen["proc"]
    assert all(v != "opened" for v in seen["fds"].values()), seen["fds"]
    assert _ctrl_c(procs, name) == EXIT_INTERRUPTED, procs.logs()
    reader.join(30)
    assert not reader.is_alive() and reader.error is None, reader.error
    entities = _decode(bytes(reader.data), tmp_path)
    assert entities.get("/sets/truth"), sorted(entities)  # the user reads the truth
    assert not any(FORGED in str(t) for t in entities.get("/verdict", [])), "a forged verdict reached the user's view"


# ------------------------------------------------------------------------------ processes and their ports


def _argv(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _tree(root: int) -> list[int]:
    """``root`` and its live descendants."""
    parent = {}
    for d in filter(str.isdigit, os.listdir("/proc")):
        try:
            parent[int(d)] = int(Path(f"/proc/{d}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            pass
    out, todo = [], [root]
    while todo:
        p = todo.pop()
        out.append(p)
        todo += [c for c, pp in parent.items() if pp == p]
    return out


def _listening_ports(pids: list[int]) -> set[int]:
    """The TCP ports (IPv4 and IPv6) on which any of ``pids`` listens (/proc/net/tcp: state 0A, by socket inode)."""
    inodes = set()
    for pid in pids:
        try:
            for fd in os.listdir(f"/proc/{pid}/fd"):
                link = os.readlink(f"/proc/{pid}/fd/{fd}")
                if link.startswith("socket:["):
                    inodes.add(link[8:-1])
        except OSError:
            pass
    ports = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            f = line.split()
            if f[3] == "0A" and f[9] in inodes:
                ports.add(int(f[1].rsplit(":", 1)[1], 16))
    return ports


FOOTER = b"RRF2FOOT\x01\x00\x00\x00"  # the end of each piece: Rerun's footer (its manifest before it)


def _decode(rrd: bytes, tmp_path: Path) -> dict[str, list[object]]:
    """Entity → its timed values, from a whole stream of the view: its pieces one by one (each a complete RRD
    with a footer of its own, which Rerun's streaming decoder, the browser's, reads one after another, while
    its file reader trusts the last footer only)."""
    from rerun.chunk import RrdReader

    pieces = [p + FOOTER for p in rrd.split(FOOTER) if p]
    assert pieces and rrd.endswith(FOOTER), "the stream did not end with a whole piece"
    out: dict[str, list[object]] = {}
    path = tmp_path / "piece.rrd"
    for piece in pieces:
        path.write_bytes(piece)
        for chunk in RrdReader(path).stream():
            batch = chunk.to_record_batch().to_pydict()
            if "step" in batch:
                out.setdefault(str(chunk.entity_path), []).extend(v for c, vs in batch.items() if ":" in c for v in vs)
    return out
