"""Issue 33: a collector that falls behind loses nothing.  The deterministic trigger: SIGSTOP the collector
of an unpaced lockstep run for a while, then SIGCONT.  Before the vehicle waited for the collector's
acknowledgment (roles/vehicle.py, roles/flow.py ACK_WINDOW), its inbox bound dropped the run's own truths and states:
a 3 s pause ended with exit 1 at "steps 0–319" and two nodes falsely reported missing.  Each run also
writes a slow record (gzip, MCAP), the other way a collector fell behind."""

from __future__ import annotations

import contextlib
import os
import signal
import time
from pathlib import Path

import pytest
from zenoh_helpers import find_role, parent_run_id, read_json, start_parent, wait_for

from netsetest.records.record import load_record

STEPS = 300  # unpaced: the pause falls mid-run with most of the run after it (1000 until 2026-12-07: 300 still fails
# both lockstep cases without the acknowledgment window, NETSETEST_ACK_WINDOW=unbounded, at a third of the CPU)
NODES = 6
UNDER_WAY_BYTES = 100_000  # the record has grown this much: the run is under way (about 20–60 steps)


def _run_with_collector_paused(procs, args: list[str], record: Path, pause_s: float, outlasts: bool) -> None:
    """``netsetest run ARGS`` whose collector is stopped (SIGSTOP) for ``pause_s`` once the record has grown
    (the run under way), then continued; with ``outlasts`` the run must still be going when it is (lockstep waits)."""
    proc = start_parent(procs, "run", args)
    wait_for(lambda: find_role(parent_run_id(proc), "collector"), 60, what="the collector")
    collector = find_role(parent_run_id(proc), "collector")[0]
    wait_for(lambda: record.exists() and record.stat().st_size > UNDER_WAY_BYTES, 120, interval=0.05, what="the run under way")
    os.kill(collector, signal.SIGSTOP)
    try:
        time.sleep(pause_s)
        assert not outlasts or proc.poll() is None, "the run ended while its collector was stopped"
    finally:
        with contextlib.suppress(ProcessLookupError):  # (a run that gave up on it may have ended it already)
            os.kill(collector, signal.SIGCONT)


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.parametrize(("pause_s", "suffix"), [(3.0, "jsonl.gz"), (10.0, "mcap")])
def test_a_paused_collector_loses_no_step(procs, tmp_path: Path, pause_s: float, suffix: str) -> None:
    record, summary = tmp_path / f"r.{suffix}", tmp_path / "s.json"
    _run_with_collector_paused(
        procs, ["paper6", "--steps", str(STEPS), "--record", str(record), "--summary-json", str(summary), "--quiet"], record, pause_s, outlasts=True
    )
    assert procs.wait("run", 240) == 0, procs.logs()
    s = read_json(summary)
    assert s["steps_completed"] == STEPS
    assert s["node_steps_evaluated"] == s["node_steps_covered"] == (STEPS + 1) * NODES, "a node-step was not judged"
    assert s["nodes_missing"] == [] and s["nodes_rejoined"] == []
    assert s["steps_overloaded"] == 0 and s["stopped"] is None
    assert not s["drops"].get("collector"), s["drops"]  # no inbox-full, no End counted early


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.parametrize(("pause_s", "steps"), [(10.0, 300), (20.0, 500)])  # steps of τs = 0.1 s: the pause falls mid-run
def test_a_paused_realtime_collector_blames_no_node(procs, tmp_path: Path, pause_s: float, steps: int) -> None:
    """Real time cannot wait for the collector: what it could not take in (its inbox full when it came back)
    is its own overload, in the verdict under that name; before, all six nodes were reported "rejoined".
    Paused 20 s, longer than its inbox and WINDOW hold, it catches up and judges on; before, it judged nothing
    after the pause: 'FAIL (vehicle gone)', four nodes 'lost for good', two 'rejoined'."""
    record, summary = tmp_path / "r.jsonl", tmp_path / "s.json"
    args = ["paper6", "--clock", "realtime", "--steps", str(steps), "--record", str(record), "--summary-json", str(summary), "--quiet"]
    _run_with_collector_paused(procs, args, record, pause_s, outlasts=False)
    assert procs.wait("run", 240) == 0, procs.logs()
    s = read_json(summary)
    assert s["steps_completed"] == steps and s["stopped"] is None
    counted = sum(n["steps_reported"] + n["steps_rejected"] + n["missing_steps"] for n in s["nodes"]) + s["node_steps_overloaded"]
    assert counted == (steps + 1) * len(s["nodes"]), "a node-step in no count, or in two"
    assert s["nodes_missing"] == [] and s["nodes_rejoined"] == [] and all(r["missing_steps"] == 0 for r in s["nodes"])
    lost_here = s["drops"].get("collector", {}).get("inbox-full", 0)
    assert (s["steps_overloaded"] > 0) == (lost_here > 0), s  # what the inbox dropped is counted as the collector's overload
    last = (procs.logdir / "run.out").read_text().splitlines()[-1]
    assert last.startswith("PASS") and ("collector overloaded" in last) == (s["steps_overloaded"] > 0), last


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_collector_stopped_past_zenohs_old_lease_rides_through(procs, tmp_path: Path) -> None:
    """Issue 41, item 6: the collector stopped 70 s mid-run.  The sessions' lease was 60 s: the router closed the
    collector's session, what was in flight to it was lost, the vehicle waited for it with no bound, and the run
    ended 'FAIL (vehicle gone)' at steps 0–51 (3 of 3 times; at 300 s also a node 'lost for good').  Now every
    session's lease is the run's stall limit (600 s by default): the run completes, nothing lost.  (A long pause
    but an idle one: the run's processes wait, they do not compute.)"""
    record, summary = tmp_path / "r.jsonl", tmp_path / "s.json"
    args = ["paper6", "--steps", "300", "--record", str(record), "--summary-json", str(summary), "--quiet"]
    _run_with_collector_paused(procs, args, record, 70.0, outlasts=True)
    assert procs.wait("run", 120) == 0, procs.logs()
    s = read_json(summary)
    assert s["steps_completed"] == 300 and s["stopped"] is None
    assert s["node_steps_evaluated"] == s["node_steps_covered"] == 301 * NODES
    assert s["nodes_missing"] == [] and s["nodes_rejoined"] == [] and s["collector_stall_s"] >= 70.0


@pytest.mark.timeout(180)
def test_a_collector_stopped_past_the_stall_limit_ends_the_run_naming_its_stall(procs, tmp_path: Path) -> None:
    """Issue 41, item 6, past the limit: a collector stopped longer than ``--stall-limit`` (3 s here, for the
    default 600) loses its session.  The vehicle waits for it at most that long, then ends the run; the launcher
    continues the collector, which writes the steps it had checked and a verdict naming its own stall, no node
    blamed (before: 'FAIL (vehicle gone)' after another 60 s, nodes 'lost for good' or all six 'rejoined')."""
    record, summary = tmp_path / "r.jsonl", tmp_path / "s.json"
    args = ["paper6", "--steps", "300", "--record", str(record), "--summary-json", str(summary), "--stall-limit", "3", "--quiet"]
    t0 = time.monotonic()
    _run_with_collector_paused(procs, args, record, 8.0, outlasts=False)
    assert procs.wait("run", 60) == 1, procs.logs()
    assert time.monotonic() - t0 < 45, "the run waited out an idle timeout"  # (3 s limit, 5 s grace for the roles)
    s = read_json(summary)
    assert s["stopped"] == "collector stalled" and s["collector_stall_s"] >= 3.0, s
    assert s["nodes_missing"] == [] and s["nodes_rejoined"] == [] and all(n["missing_steps"] == 0 for n in s["nodes"])
    assert s["node_steps_evaluated"] == s["node_steps_covered"] == (s["steps_completed"] + 1) * NODES  # what it checked, all of it
    last = (procs.logdir / "run.out").read_text().splitlines()[-1]
    assert last.startswith("FAIL (collector stalled): ") and "no node blamed" in last and "lost for good" not in last, last
    rec = load_record(record)
    assert rec.summary is not None and [t["step"] for t in rec.truth] == list(range(s["steps_completed"] + 1))
