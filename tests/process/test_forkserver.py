"""The fork server that starts a run's role processes (runtime/forkserver.py): it forks with one thread,
its children run the command line with their own stdout and exit code, and nothing outlives it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from zenoh_helpers import describe, free_ports, new_run_id, pids_with_arg, wait_for, wait_gone

from netsetest.runtime.forkserver import NAME_PREFIX, ForkServer, ForkServerError
from netsetest.runtime.launcher import ROLE_MODULE
from netsetest.runtime.processes import role_env

pytestmark = pytest.mark.zenoh
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture()
def server() -> Iterator[tuple[ForkServer, str]]:
    run_id = new_run_id()
    fs = ForkServer([sys.executable, "-m", ROLE_MODULE, "forkserver", "--run-id", run_id], role_env())
    try:
        yield fs, run_id
    finally:
        fs.close()
        left = wait_gone([run_id], 5.0)
        for pid in left:
            os.kill(pid, signal.SIGKILL)
        assert not left, f"left behind: {describe(left)}"


def _router(fs: ForkServer, run_id: str):
    """A child that runs until stopped: an open Zenoh router on a free port."""
    return fs.spawn("router", ["router", "--listen", f"tcp/127.0.0.1:{free_ports(1)[0]}", "--run-id", run_id])


def _comm(pid: int) -> str:
    return Path(f"/proc/{pid}/comm").read_text().strip()


def _threads(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/task"))


def test_a_child_runs_the_command_line_with_its_own_stdout_and_exit_code(server: tuple[ForkServer, str]) -> None:
    fs, _ = server
    child = fs.spawn("compose", ["compose", "paper6"], pipes=[1])
    out = child.pipes[1].read().decode()
    assert child.wait(30) == 0 and "services:" in out and "  node6:" in out, out[:300]
    assert fs.spawn("bad", ["compose", "no-such-topology"]).wait(30) == 2  # bad input, as exec'd
    assert fs.spawn("usage", ["node", "paper6"]).wait(30) == 2  # argparse: --id is required
    # the server forks with a single thread: no Zenoh runtime, no BLAS pool before fork
    assert _threads(fs.proc.pid) == 1


def test_signals_reach_the_child_and_its_name_says_its_role(server: tuple[ForkServer, str]) -> None:
    fs, run_id = server
    child = _router(fs, run_id)
    wait_for(lambda: _comm(child.pid) == f"{NAME_PREFIX}router", 10, what="the child's process name")  # set right after fork
    assert child.pid in pids_with_arg(run_id)  # the server's command line, with the run id
    with pytest.raises(subprocess.TimeoutExpired):
        child.wait(0.3)
    child.send_signal(signal.SIGTERM)
    assert child.wait(10) == 0  # the router's SIGTERM handler: a clean stop
    child.send_signal(signal.SIGTERM)  # reaped: a no-op, never another process's pid


def test_children_die_with_the_server(server: tuple[ForkServer, str]) -> None:
    fs, run_id = server
    kids = [_router(fs, run_id) for _ in range(2)]
    wait_for(lambda: all(_comm(k.pid) == f"{NAME_PREFIX}router" for k in kids), 10, what="the routers")
    os.kill(fs.proc.pid, signal.SIGKILL)
    fs.proc.wait(5)
    left = wait_gone([run_id], 5.0)
    assert not left, f"children survived their fork server: {describe(left)}"
    assert [k.wait(5) for k in kids] == [-signal.SIGKILL] * 2  # the launcher learns it from the closed socket


def test_closing_the_server_kills_what_is_left(server: tuple[ForkServer, str]) -> None:
    fs, run_id = server
    child = _router(fs, run_id)
    time.sleep(0.2)
    fs.close()
    assert fs.proc.returncode == 0
    assert not wait_gone([run_id], 5.0)
    assert child.poll() == -signal.SIGKILL


def test_a_server_that_is_gone_is_an_error_not_a_hang() -> None:
    fs = ForkServer([sys.executable, "-c", "pass"], role_env())  # ends at once, without serving
    try:
        with pytest.raises(ForkServerError, match="ended"):
            fs.spawn("vehicle", ["vehicle", "paper6"])
    finally:
        fs.close()
