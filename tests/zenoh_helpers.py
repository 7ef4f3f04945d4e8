"""Shared helpers of the Zenoh-runtime tests (``tests/test_zenoh_*.py``).

Everything runs on loopback (or inside network namespaces the test creates) with explicit endpoints on
free ports; the bus configuration already turns multicast scouting off.  Every process a test starts is
registered with a :class:`ProcessGuard`; its finalizer SIGKILLs whatever is left (by pid, and processes
whose command line carries one of the test's run ids) and the ``procs`` fixture then asserts that
nothing is left.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import IO

import pytest

from netsetest.runtime.report import EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_NODE_LOST, EXIT_OK, EXIT_VIOLATION  # noqa: F401  # the tests import them from here: one source of truth

ROOT = Path(__file__).resolve().parents[1]
PAPER6 = "topologies/paper6.toml"
PAPER6_LOSSY = "topologies/paper6_lossy.toml"
NODE_IDS = [1, 2, 3, 4, 5, 6]
RING = {1: [2, 6], 2: [1, 3], 3: [2, 4], 4: [3, 5], 5: [4, 6], 6: [1, 5]}  # in-neighbours j ≠ i (paper6)


# ------------------------------------------------------------------------------ small utilities


def cli(*args: str) -> list[str]:
    """Command line of ``netsetest ARGS`` with this interpreter (same as the run parent uses)."""
    return [sys.executable, "-m", "netsetest.cli.main", *args]


def free_ports(n: int, host: str = "127.0.0.1") -> list[int]:
    """``n`` distinct ports that are free right now (all bound at once, so they differ)."""
    socks, ports = [], []
    try:
        for _ in range(n):
            s = socket.socket()
            s.bind((host, 0))
            socks.append(s)
            ports.append(s.getsockname()[1])
    finally:
        for s in socks:
            s.close()
    return ports


def new_run_id(prefix: str = "zt") -> str:
    return f"{prefix}{uuid.uuid4().hex[:10]}"


def wait_for(pred: Callable[[], object], timeout: float, interval: float = 0.1, what: str = "condition") -> object:
    """Poll ``pred`` until it returns something truthy; fail the test after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        v = pred()
        if v:
            return v
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(interval)


def wait_port(host: str, port: int, timeout: float) -> None:
    def up() -> bool:
        try:
            with socket.create_connection((host, port), timeout=0.5):
                return True
        except OSError:
            return False

    wait_for(up, timeout, 0.1, f"{host}:{port} to accept connections")


def read_json(path: str | Path) -> dict:
    return json.loads(Path(path).read_text())


def read_record(path: str | Path) -> dict:
    """A run record as one dict: meta, truth, nodes {i: entries}, summary, partial; its truth entries as the file holds
    them (node ids as strings), as an in-memory run's parts hold them."""
    from netsetest.records.record import load_record
    from netsetest.records.truth import truth_json

    rec = load_record(path)
    summary = rec.summary.to_dict() if rec.summary is not None else None
    return {"meta": rec.meta, "truth": [truth_json(t) for t in rec.truth], "nodes": rec.raw_nodes, "summary": summary, "partial": rec.partial}


# ------------------------------------------------------------------------------ processes via /proc


def _cmdline(pid: int) -> list[str] | None:
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    state = stat.rsplit(")", 1)[-1].split()[0]
    if state in ("Z", "X") or not raw:  # a zombie has no command line and is already dead
        return None
    return raw.rstrip(b"\0").decode(errors="replace").split("\0")


def pids_with_arg(marker: str) -> list[int]:
    """Live processes (not zombies) one of whose argv entries is exactly ``marker`` (a run id)."""
    me = os.getpid()
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == me:
            continue
        argv = _cmdline(int(entry))
        if argv and marker in argv:
            out.append(int(entry))
    return sorted(out)


def _comm(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return ""


def find_role(run_id: str, role: str) -> list[int]:
    """Pids of the run's ROLE processes: exec'd as ``netsetest.cli.main ROLE ... --run-id RUN_ID`` (like
    ``pgrep -f``), or forked by the run's fork server (its command line, with the run id; process name
    ``ns-ROLE`` or ``ns-nodeN``, runtime/forkserver.py)."""
    out = []
    for pid in pids_with_arg(run_id):
        argv = _cmdline(pid) or []
        if "netsetest.cli.main" in argv:
            i = argv.index("netsetest.cli.main")
            name = _comm(pid)
            if (i + 1 < len(argv) and argv[i + 1] == role) or name.removeprefix("ns-").rstrip("0123456789") == role != name:
                out.append(pid)
    return out


def child_pids() -> set[int]:
    """The pids of this process's live children (from /proc: a child that exits meanwhile is skipped)."""
    me = str(os.getpid())
    out = set()
    for d in os.listdir("/proc"):
        try:
            if d.isdigit() and Path(f"/proc/{d}/stat").read_text().rsplit(")", 1)[1].split()[1] == me:
                out.add(int(d))
        except OSError:
            pass
    return out


def alive(pid: int) -> bool:
    return _cmdline(pid) is not None


def wait_gone(markers: Iterable[str], timeout: float) -> list[int]:
    """Wait until no process carries one of ``markers``; return the pids still there at the end."""
    markers = list(markers)
    deadline = time.monotonic() + timeout
    while True:
        left = sorted({p for m in markers for p in pids_with_arg(m)})
        if not left or time.monotonic() > deadline:
            return left
        time.sleep(0.1)


def describe(pids: Iterable[int]) -> str:
    return "; ".join(f"{p}: {' '.join(_cmdline(p) or ['?'])}" for p in pids)


# ------------------------------------------------------------------------------ the guard


class ProcessGuard:
    """Starts processes in their own session, remembers them, and kills whatever is left at the end."""

    def __init__(self, logdir: Path) -> None:
        self.logdir = Path(logdir)
        self.logdir.mkdir(parents=True, exist_ok=True)
        self.procs: dict[str, subprocess.Popen] = {}
        self.markers: set[str] = set()  # run ids: any process carrying one is ours
        self._files: list[IO] = []
        self.finalizers: list[Callable[[], None]] = []  # run after the processes are gone (netns cleanup)

    def start(self, name: str, argv: Sequence[str], stdout: bool = False, **kw: object) -> subprocess.Popen:
        """Start ``argv`` with stderr (and stdout unless ``stdout``: a pipe) into ``logdir/name.*``."""
        err = open(self.logdir / f"{name}.err", "wb")
        self._files.append(err)
        if stdout:
            out: object = subprocess.PIPE
        else:
            out = open(self.logdir / f"{name}.out", "wb")
            self._files.append(out)
        kw.setdefault("cwd", str(ROOT))
        proc = subprocess.Popen(list(argv), stdin=subprocess.DEVNULL, stdout=out, stderr=err, start_new_session=True, **kw)
        self.procs[name] = proc
        return proc

    def stderr(self, name: str) -> str:
        p = self.logdir / f"{name}.err"
        return p.read_text(errors="replace") if p.exists() else ""

    def logs(self) -> str:
        parts = []
        for f in sorted(self.logdir.glob("*.err")):
            text = f.read_text(errors="replace").strip()
            if text:
                parts.append(f"--- {f.name}\n{text[-3000:]}")
        return "\n".join(parts)

    def wait(self, name: str, timeout: float) -> int:
        try:
            return self.procs[name].wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            pytest.fail(f"{name} did not exit within {timeout:g} s\n{self.logs()}")

    def cleanup(self) -> list[str]:
        """SIGKILL every process we started (and its process group) and every process carrying one of
        our run ids; return descriptions of processes that survive."""
        for proc in self.procs.values():
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGKILL)  # its own session/group: only our processes
                except (ProcessLookupError, PermissionError):
                    pass
                try:
                    proc.kill()
                except ProcessLookupError:
                    pass
        for marker in self.markers:
            for pid in pids_with_arg(marker):
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        for proc in self.procs.values():
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                pass
            if proc.stdout:
                proc.stdout.close()
        for f in self._files:
            f.close()
        left = [f"{n} (pid {p.pid})" for n, p in self.procs.items() if p.poll() is None]
        stray = wait_gone(self.markers, 5.0)
        left += [describe(stray)] if stray else []
        for fin in self.finalizers:
            fin()
        return left


@pytest.fixture
def procs(tmp_path: Path):
    """A :class:`ProcessGuard`; at teardown every leftover is SIGKILLed, then none may remain."""
    guard = ProcessGuard(tmp_path / "logs")
    yield guard
    left = guard.cleanup()
    assert not left, f"processes left behind: {left}"


# ------------------------------------------------------------------------------ the parent `netsetest run`


def parent_run_id(proc: subprocess.Popen) -> str:
    """The run id start_parent gave ``netsetest run`` (every child carries it on its command line)."""
    return proc.netsetest_run_id


_PARENTS = iter(range(1_000_000))


def start_parent(guard: ProcessGuard, name: str, args: Sequence[str]) -> subprocess.Popen:
    """``netsetest run ARGS`` with a run id of the test's (the default is random) and, unless ARGS give one,
    seed 0 (the default is a fresh random seed; the tests compare with in-memory runs of seed 0)."""
    run_id = f"t{os.getpid()}n{next(_PARENTS)}"
    extra = ["--run-id", run_id, *([] if "--seed" in args else ["--seed", "0"])]
    guard.markers.add(run_id)
    proc = guard.start(name, cli("run", *args, *extra))
    proc.netsetest_run_id = run_id
    return proc


def progress_steps(stderr: str) -> list[int]:
    """Steps of the parent's progress lines ``zenoh (...): step K/N (...)``."""
    return [int(m) for m in re.findall(r"step (\d+)/\d+", stderr)]


def run_parent(guard: ProcessGuard, name: str, args: Sequence[str], timeout: float) -> int:
    proc = start_parent(guard, name, args)
    code = guard.wait(name, timeout)
    # the parent waits for its children before it exits: none may carry the run id any more
    left = wait_gone([parent_run_id(proc)], 3.0)
    assert not left, f"{name}: children left after the parent exited: {describe(left)}"
    return code


def run_to_success(log_dir: Path, args: Sequence[str], timeout: float) -> str:
    """``netsetest run ARGS`` with its own guard: it must exit 0 and leave no process; its logs."""
    guard = ProcessGuard(log_dir)
    try:
        code = run_parent(guard, "run", args, timeout)
        logs = guard.logs()
    finally:
        left = guard.cleanup()
    assert not left, f"processes left behind: {left}"
    assert code == 0, f"netsetest run {' '.join(map(str, args))}: exit {code}\n{logs}"
    return logs


# ------------------------------------------------------------------------------ roles launched by hand


def role_argv(
    role: str,
    topology: str,
    run_id: str,
    mode: str,
    listen: Sequence[str],
    connect: Sequence[str],
    steps: int | None = None,
    extra: Sequence[str] = (),
) -> list[str]:
    argv = [role, topology, "--run-id", run_id, "--zenoh-mode", mode]
    if steps:
        argv += ["--steps", str(steps)]
    argv += list(extra)
    for e in listen:
        argv += ["--listen", e]
    for e in connect:
        argv += ["--connect", e]
    return argv


def role_names(ids: Sequence[int] = NODE_IDS) -> list[str]:
    return ["collector", "vehicle", *(f"node{i}" for i in ids)]


def role_extra(name: str, summary: Path, seed: int = 0, signals: str = "paper", record: Path | None = None) -> list[str]:
    if name == "collector":
        rec = ["--record", str(record)] if record else []
        return ["--signals", signals, "--seed", str(seed), "--summary-json", str(summary), "--idle-timeout", "30", *rec]
    if name == "vehicle":
        return ["--signals", signals, "--seed", str(seed), "--start-timeout", "90"]
    return ["--id", name.removeprefix("node")]


def launch_peer_mesh(
    guard: ProcessGuard,
    topology: str,
    run_id: str,
    steps: int,
    summary: Path,
    seed: int = 0,
    signals: str = "paper",
    record: Path | None = None,
    also_connect: Sequence[str] = (),
    endpoints: dict[str, str] | None = None,
) -> dict[str, str]:
    """Collector, nodes and vehicle as peers: each listens on a free port (or its given one in ``endpoints``)
    and connects to all the others (the same layout ``netsetest run --mode zenoh`` builds) and to
    ``also_connect``.  Returns name → listen endpoint."""
    names = role_names()
    endpoints = {**{n: f"tcp/127.0.0.1:{p}" for n, p in zip(names, free_ports(len(names)))}, **(endpoints or {})}
    guard.markers.add(run_id)
    for name in names:
        role = "node" if name.startswith("node") else name
        others = [endpoints[o] for o in names if o != name] + list(also_connect)
        argv = role_argv(role, topology, run_id, "peer", [endpoints[name]], others, steps, role_extra(name, summary, seed, signals, record))
        guard.start(name, cli(*argv))
    return endpoints


def launch_clients(
    guard: ProcessGuard,
    topology: str,
    run_id: str,
    steps: int,
    summary: Path,
    router: str | dict[str, str],
    prefix: dict[str, list[str]] | None = None,
    record: Path | None = None,
    extra: Sequence[str] = (),
) -> None:
    """Collector, nodes and vehicle in client mode.  ``router``: one endpoint, or role name → endpoint;
    ``prefix``: role name → argv prefix (e.g. ``ip netns exec NS``); ``extra``: options for every role
    (e.g. ``--credentials DIR``)."""
    guard.markers.add(run_id)
    for name in role_names():
        role = "node" if name.startswith("node") else name
        ep = router if isinstance(router, str) else router[name]
        argv = role_argv(role, topology, run_id, "client", [], [ep], steps, [*role_extra(name, summary, record=record), *extra])
        guard.start(name, [*(prefix or {}).get(name, []), *cli(*argv)])


def wait_roles(guard: ProcessGuard, timeout: float, names: Sequence[str] | None = None) -> dict[str, int]:
    """Wait for the role processes to end; fail at once when one of them fails (exit ≠ 0)."""
    names = list(names or role_names())
    deadline = time.monotonic() + timeout
    while True:
        codes = {n: guard.procs[n].poll() for n in names}
        failed = {n: c for n, c in codes.items() if c not in (None, 0)}
        if failed:
            pytest.fail(f"role process(es) failed: {failed}\n{guard.logs()}")
        if all(c is not None for c in codes.values()):
            return codes
        if time.monotonic() > deadline:
            pytest.fail(f"roles still running after {timeout:g} s: {[n for n, c in codes.items() if c is None]}\n{guard.logs()}")
        time.sleep(0.1)
