"""A fork server for the role processes of a run: import once, fork each role (like multiprocessing's forkserver).

Starting a role as a fresh ``python -m netsetest.cli.main ROLE`` costs ≈0.4 s of CPU importing numpy,
clarabel, zenoh, the messages and the estimator; the eight processes of the paper run on two cores
spent ≈1.5 s doing that before step 0.  The launcher instead starts one server process first (in the
role environment, ``ROLE_ENV``), which imports what every role needs and then, per request, forks a
child that runs the role's command line (the same argv as an exec'd role).  Each child opens its own
Zenoh session: the server opens none and starts no thread before it forks (``zenoh`` starts its
runtimes with the first session; ``OPENBLAS_NUM_THREADS=1`` keeps numpy's BLAS single-threaded).

Lifetimes: the server gets SIGKILL when the launcher dies (PR_SET_PDEATHSIG, set by the launcher) and
each child gets SIGKILL when the server dies (set in the child, relative to the server), so killing
the launcher takes everything with it.  Each child runs in its own session (Ctrl-C at the terminal
reaches the launcher only) under the process name ``ns-<name>`` (e.g. ``ns-node3``; its command
line is the server's, which carries the run id).  When the launcher closes the control socket the
server SIGKILLs what is left of its children, reaps them and exits.

Protocol (a SOCK_SEQPACKET socket pair, one JSON object per packet): the launcher sends
``{"name", "argv", "pipes"}`` (``pipes``: descriptor numbers in the child, e.g. 1 for its stdout or 3 for
the collector's channel to the launcher; the write end of a pipe for each rides along as SCM_RIGHTS, in
that order); the server answers ``{"started": name, "pid"}`` and later, when the child has
ended, ``{"exited": pid, "code", "cpu_s", "peak_rss_mb"}`` (``code`` as :attr:`subprocess.Popen.returncode`: −N
for signal N; the child's user + system CPU seconds and peak RSS, from its rusage: the benchmark's figures).
"""

from __future__ import annotations

import ctypes
import importlib
import json
import os
import selectors
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from typing import IO, NoReturn

PR_SET_PDEATHSIG, PR_SET_NAME = 1, 15  # prctl(2)
NAME_PREFIX = "ns-"  # process name of a forked role: ns-vehicle, ns-collector, ns-node3
SERVER_GRACE_S = 5.0  # how long the server may take to kill and reap what is left when told to end
HIGHEST_PIPE_FD = 9  # a child's pipes go to descriptors up to this one (stdout 1, the collector's channel 3)
MAX_PACKET = 1 << 20  # a request's argv: a 128-node peer mesh is ≈5 kB per role
# What every role imports beyond the command line itself; imported once, by the server.
ROLE_MODULES = ("numpy", "clarabel", "zenoh", "netsetest.bus.zenoh_bus", "netsetest.runtime.processes", "netsetest.runtime.security")


class ForkServerError(RuntimeError):
    """The fork server is gone or answered nonsense."""


def _prctl(option: int, arg: int | bytes) -> None:
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(option, arg, 0, 0, 0)
    except OSError:
        pass


def die_with_parent() -> None:
    """Get SIGKILL when the parent dies, however it dies (Linux; in a child, before anything else)."""
    _prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


def _send(sock: socket.socket, obj: object, fds: Sequence[int] = ()) -> None:
    data = json.dumps(obj).encode()
    if fds:
        socket.send_fds(sock, [data], list(fds))
    else:
        sock.send(data)


def _recv(sock: socket.socket) -> tuple[dict | None, list[int]]:
    """One packet: (message, received fds); (None, []) at end of file."""
    data, fds, _, _ = socket.recv_fds(sock, MAX_PACKET, 1)
    return (json.loads(data) if data else None), fds


# ---------------------------------------------------------------- the server


def serve(control_fd: int, run: Callable[[list[str]], int]) -> int:
    """The server's loop: fork a child running ``run(argv)`` per request, report children's ends."""
    placeholders = _hold_low_fds()
    for name in ROLE_MODULES:
        importlib.import_module(name)
    sock = socket.socket(fileno=control_fd)
    sel = selectors.DefaultSelector()
    sel.register(sock, selectors.EVENT_READ)
    children: dict[int, int] = {}  # pidfd → pid
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    while True:
        for key, _ in sel.select():
            if key.fileobj is sock:
                req, fds = _recv(sock)
                if req is None:  # the launcher is done (or gone): nothing may outlive it
                    _kill_all(children)
                    return 0
                pid = _fork(req["name"], req["argv"], dict(zip(req.get("pipes", []), fds)), run, [sock.fileno(), *children, sel.fileno(), *placeholders])
                for fd in fds:
                    os.close(fd)
                pidfd = os.pidfd_open(pid)
                children[pidfd] = pid
                sel.register(pidfd, selectors.EVENT_READ)
                _send(sock, {"started": req["name"], "pid": pid})
            else:
                pidfd = int(key.fd)
                pid = children.pop(pidfd)
                sel.unregister(pidfd)
                os.close(pidfd)
                _, status, usage = os.wait4(pid, 0)
                _send(
                    sock,
                    {
                        "exited": pid,
                        "code": os.waitstatus_to_exitcode(status),
                        "cpu_s": usage.ru_utime + usage.ru_stime,
                        "peak_rss_mb": usage.ru_maxrss / 1024.0,
                    },
                )


def _hold_low_fds() -> list[int]:
    """Open /dev/null on every free descriptor up to :data:`HIGHEST_PIPE_FD`, so that nothing the imports
    open lands where a child's pipe goes (a child closes these first)."""
    held = []
    while (fd := os.open(os.devnull, os.O_RDONLY)) <= HIGHEST_PIPE_FD:
        held.append(fd)
    os.close(fd)
    return held


def _kill_all(children: Mapping[int, int]) -> None:
    for pid in children.values():
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    for pid in children.values():
        os.waitpid(pid, 0)


def _fork(name: str, argv: list[str], pipes: dict[int, int], run: Callable[[list[str]], int], close: list[int]) -> int:
    """Fork a child that runs ``run(argv)`` and exits with its code; the child's pid."""
    server = os.getpid()
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
        _child(server, name, argv, pipes, run, close)
    return pid


def _child(server: int, name: str, argv: list[str], pipes: dict[int, int], run: Callable[[list[str]], int], close: list[int]) -> NoReturn:
    """``pipes``: descriptor number in the child → the received write end to put there."""
    code = 1
    try:
        os.setsid()  # like start_new_session: the terminal's Ctrl-C goes to the launcher alone
        die_with_parent()
        if os.getppid() != server:  # the server died before the line above
            os._exit(1)
        for fd in close:
            os.close(fd)
        devnull = os.open(os.devnull, os.O_RDWR)
        os.dup2(devnull, 0)
        os.dup2(devnull, 1)
        os.close(devnull)
        for target, fd in pipes.items():  # received above HIGHEST_PIPE_FD (the low ones are held): no clash
            os.dup2(fd, target)
            os.close(fd)
        for sig in (signal.SIGTERM, signal.SIGCHLD):
            signal.signal(sig, signal.SIG_DFL)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        _prctl(PR_SET_NAME, (NAME_PREFIX + name).encode()[:15])
        code = run(argv)
    except SystemExit as exc:  # argparse's exit 2, sys.exit(n)
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except BaseException:  # as an exec'd role would: the traceback on stderr, exit 1
        import traceback

        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


# ---------------------------------------------------------------- the launcher's side


class ForkedProcess:
    """A role forked by the server, with the part of :class:`subprocess.Popen` the launcher uses."""

    def __init__(self, server: ForkServer, name: str, pid: int, pipes: dict[int, IO[bytes]]) -> None:
        """``pipes``: the read ends of the child's pipes, by their descriptor number in the child."""
        self.server, self.name, self.pid, self.pipes = server, name, pid, pipes
        self.returncode: int | None = None
        self.cpu_s: float | None = None  # at its exit: user + system CPU seconds (None: killed with the server)
        self.peak_rss_mb: float | None = None  # at its exit: peak resident memory (ru_maxrss)
        try:  # signals go through a pidfd: never to another process that got the pid after this one was reaped
            self.pidfd: int | None = os.pidfd_open(pid)
        except ProcessLookupError:  # already ended and reaped: its exit is on the way
            self.pidfd = None

    def ended(self, code: int, cpu_s: float | None = None, peak_rss_mb: float | None = None) -> None:
        self.returncode, self.cpu_s, self.peak_rss_mb = code, cpu_s, peak_rss_mb
        if self.pidfd is not None:
            os.close(self.pidfd)
            self.pidfd = None

    def poll(self) -> int | None:
        if self.returncode is None:
            self.server.pump(0.0)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.returncode is None:
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                raise subprocess.TimeoutExpired(self.name, timeout or 0.0)
            self.server.pump(left)
        return self.returncode

    def send_signal(self, sig: int) -> None:
        if self.poll() is None and self.pidfd is not None:
            try:
                signal.pidfd_send_signal(self.pidfd, sig)
            except ProcessLookupError:
                pass

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


class ForkServer:
    """The launcher's handle on its fork server: start it early (it imports while the launcher goes on)."""

    def __init__(self, argv: list[str], env: Mapping[str, str]) -> None:
        """``argv``: the server's command; ``--control-fd N`` is appended."""
        self.sock, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.proc = subprocess.Popen(
            [*argv, "--control-fd", str(theirs.fileno())],
            pass_fds=[theirs.fileno()],
            start_new_session=True,
            preexec_fn=die_with_parent,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            env=dict(env),
        )
        theirs.close()
        self.children: dict[int, ForkedProcess] = {}
        self.started: list[tuple[str, int]] = []  # (name, pid) answers not yet claimed by spawn()

    def spawn(self, name: str, argv: list[str], pipes: Sequence[int] = ()) -> ForkedProcess:
        """Fork ``argv`` (a role's command line) as ``name``; each descriptor in ``pipes`` (1: its stdout) is
        the write end of a pipe whose read end comes back in :attr:`ForkedProcess.pipes` (binary)."""
        if any(not 0 < fd <= HIGHEST_PIPE_FD for fd in pipes):
            raise ValueError(f"pipes {list(pipes)}: descriptors 1 to {HIGHEST_PIPE_FD}")
        ends = {fd: os.pipe() for fd in pipes}
        try:
            _send(self.sock, {"name": name, "argv": argv, "pipes": list(ends)}, [w for _, w in ends.values()])
        except OSError as exc:
            for r, _ in ends.values():
                os.close(r)
            raise ForkServerError(f"the fork server is gone ({exc})") from None
        finally:
            for _, w in ends.values():
                os.close(w)
        while not any(n == name for n, _ in self.started):
            if not self.pump(None):
                raise ForkServerError(f"the fork server ended (exit {self.proc.wait()}) before starting {name}")
        pid = next(p for n, p in self.started if n == name)
        self.started.remove((name, pid))
        child = ForkedProcess(self, name, pid, {fd: os.fdopen(r, "rb") for fd, (r, _) in ends.items()})
        self.children[pid] = child
        return child

    def pump(self, timeout: float | None) -> bool:
        """Read the server's messages (waiting at most ``timeout`` s for the first); False once it is gone."""
        if self.sock.fileno() < 0:  # closed by us
            return False
        try:
            self.sock.settimeout(timeout)
            while True:
                msg, _ = _recv(self.sock)
                if msg is None:
                    self._gone()
                    return False
                if "started" in msg:
                    self.started.append((msg["started"], msg["pid"]))
                elif msg["exited"] in self.children:
                    self.children[msg["exited"]].ended(msg["code"], msg.get("cpu_s"), msg.get("peak_rss_mb"))
                self.sock.settimeout(0.0)  # then take what is there without waiting
        except (BlockingIOError, TimeoutError):
            return True
        except OSError:
            self._gone()
            return False

    def _gone(self) -> None:
        """The server died: its children got SIGKILL with it (PR_SET_PDEATHSIG)."""
        for child in self.children.values():
            if child.returncode is None:
                child.ended(-signal.SIGKILL)

    def close(self) -> None:
        """Tell the server to end (it SIGKILLs any child still alive) and wait for it."""
        self.sock.close()
        try:
            self.proc.wait(timeout=SERVER_GRACE_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._gone()
