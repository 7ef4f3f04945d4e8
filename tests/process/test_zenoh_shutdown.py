"""Stopping a Zenoh run: Ctrl-C / SIGTERM to the parent stops every child (exit 130) — the vehicle and the
nodes first, then the collector, which writes its summary and record of the steps it had checked — SIGKILL of the parent
takes the children with it (PR_SET_PDEATHSIG), and a failing vehicle stops the run (exit 1)."""

from __future__ import annotations

import json
import os
import signal
import time

import pytest
from zenoh_helpers import (
    EXIT_INTERRUPTED,
    EXIT_VIOLATION,
    PAPER6,
    alive,
    describe,
    find_role,
    parent_run_id,
    pids_with_arg,
    progress_steps,
    start_parent,
    wait_for,
    wait_gone,
)

pytestmark = pytest.mark.zenoh

LONG = [PAPER6, "--steps", "400"]
ROLES = {"collector": 1, "vehicle": 1, "node": 6}


def _children(run_id: str) -> dict[str, list[int]]:
    return {role: find_role(run_id, role) for role in ROLES}


def _wait_running(guard, proc, min_step: int | None) -> None:
    """Wait until every role is up and (``min_step``) the parent's progress shows a step > ``min_step``."""

    def ready() -> bool:
        if proc.poll() is not None:
            pytest.fail(f"the run ended early with exit {proc.returncode}\n{guard.logs()}")
        err = guard.stderr("run")
        if "all 6 nodes and the collector are ready" not in err:
            return False
        return min_step is None or any(k > min_step for k in progress_steps(err))

    wait_for(ready, 90, 0.1, "the run to start" + (f" and pass step {min_step}" if min_step is not None else ""))
    kids = _children(parent_run_id(proc))
    assert {r: len(p) for r, p in kids.items()} == ROLES, f"unexpected children: {kids}"


@pytest.mark.timeout(120)
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_zenoh_signal_to_parent_stops_every_child(procs, sig, tmp_path) -> None:
    summary = tmp_path / "summary.json"
    proc = start_parent(procs, "run", [*LONG, "--summary-json", str(summary)])
    run_id = parent_run_id(proc)
    _wait_running(procs, proc, min_step=2)
    t0 = time.monotonic()
    os.kill(proc.pid, sig)  # the parent only, not its group
    code = procs.wait("run", 15)
    took = time.monotonic() - t0
    assert code == EXIT_INTERRUPTED, f"exit {code} after {sig.name}\n{procs.logs()}"
    assert took < 10, f"{sig.name}: the parent took {took:.1f} s to stop"
    left = pids_with_arg(run_id)
    assert not left, f"left after {sig.name}: {describe(left)}"
    err = procs.stderr("run")
    assert "interrupted: stopping the vehicle and the nodes, then letting the collector write" in err
    # the collector was stopped last and wrote the steps it had checked
    assert "[collector] stopped by SIGTERM; writing what was checked" in err, err
    s = json.loads(summary.read_text())
    assert 2 < s["steps_completed"] < 400 and s["security"] == "mtls+acl"


@pytest.mark.timeout(120)
def test_zenoh_sigkill_parent_kills_children(procs) -> None:
    proc = start_parent(procs, "run", LONG)
    run_id = parent_run_id(proc)
    _wait_running(procs, proc, min_step=None)
    kids = [p for ps in _children(run_id).values() for p in ps]
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=5)
    left = wait_gone([run_id], 5.0)
    assert not left, f"children survived the parent's SIGKILL: {describe(left)}"
    assert not [p for p in kids if alive(p)]


@pytest.mark.timeout(120)
def test_zenoh_failing_vehicle_stops_the_run(procs) -> None:
    proc = start_parent(procs, "run", LONG)
    run_id = parent_run_id(proc)
    _wait_running(procs, proc, min_step=None)
    (vehicle,) = find_role(run_id, "vehicle")
    os.kill(vehicle, signal.SIGKILL)
    code = procs.wait("run", 20)
    err = procs.stderr("run")
    assert code == EXIT_VIOLATION, f"exit {code}\n{procs.logs()}"
    assert "the vehicle process failed" in err
    left = wait_gone([run_id], 3.0)
    assert not left, f"left after the vehicle failed: {describe(left)}"
