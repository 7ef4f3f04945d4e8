"""Issue 41, items 6–8 at the unit level: the collector's own stall (runtime/processes.py ``StallWatch``), the
signals it acts on only between two turns of its loop (``StopRequests``), and the verdict lines of a run it
ended because of them (runtime/report.py).  The processes themselves: tests/process/test_collector_behind.py
(a collector stopped past the stall limit) and tests/process/test_record_partial.py (Ctrl-C at random moments)."""

from __future__ import annotations

import signal

import pytest

from netsetest.records.summary import RunSummary
from netsetest.runtime.processes import LEASE_RISK, STALL_S, StallWatch
from netsetest.runtime.stops import StopRequests
from netsetest.runtime.report import EXIT_INTERRUPTED, EXIT_VIOLATION, format_table, outcome, verdict

LEASE = 60.0


def test_a_turn_on_time_is_no_stall_and_a_late_one_is_measured() -> None:
    w = StallWatch(LEASE, now=100.0)
    assert w.turn(100.05, step=3) == 0.0 and w.turn(100.05 + STALL_S * 0.9, step=3) == 0.0
    assert w.turn(200.0, step=51) == pytest.approx(200.0 - 100.05 - STALL_S * 0.9)
    assert (w.longest, w.step) == (pytest.approx(99.05, abs=0.1), 51)
    w.turn(205.0, step=60)  # a shorter stall later: the longest stays
    assert w.step == 51


def test_the_session_is_at_risk_after_a_stall_near_the_lease_until_a_message_comes() -> None:
    """Zenoh sends a keep-alive only every quarter of the lease when nothing else goes out: a stall of three
    quarters of it may have cost the session; a message afterwards proves it did not."""
    w = StallWatch(LEASE, now=0.0)
    w.turn(LEASE_RISK * LEASE * 0.99, step=5)
    assert not w.session_at_risk
    w.turn(LEASE_RISK * LEASE * 0.99 + LEASE_RISK * LEASE, step=5)
    assert w.session_at_risk
    w.heard()
    assert not w.session_at_risk


def test_a_signal_is_noted_not_raised_and_the_handlers_come_back() -> None:
    """The collector's loop must not be cut in the middle of writing a step (item 7): the signal is noted, the
    loop reads it between two turns."""
    before = signal.getsignal(signal.SIGINT)
    with StopRequests() as stop:
        assert stop.signal is None
        signal.raise_signal(signal.SIGINT)  # no KeyboardInterrupt here
        assert stop.signal == "SIGINT"
    assert signal.getsignal(signal.SIGINT) is before


def _summary(**kw: object) -> RunSummary:
    base = {"mode": "zenoh", "case": "nsnim", "signals": "paper", "variant": "scheduled", "seed": 0, "steps": 300, "steps_completed": 51}
    counts = {"node_steps_evaluated": 312, "node_steps_contained": 312, "node_steps_covered": 312, "nodes": [{"id": i} for i in range(1, 7)]}
    return RunSummary.from_dict({**base, **counts, **kw})


def test_a_stalled_collectors_verdict_names_its_stall_and_blames_no_node() -> None:
    s = _summary(stopped="collector stalled", collector_stall_s=70.4, collector_stall_step=51)
    assert outcome(s) == ("FAIL (collector stalled)", EXIT_VIOLATION)
    text = verdict(s)
    assert "the collector stalled 70 s after step 51" in text and "run --stall-limit" in text and "no node blamed" in text
    assert "lost for good" not in text and "vehicle" not in text
    assert format_table(s).splitlines()[-1].startswith("FAIL (collector stalled): zenoh run")


def test_an_interrupted_runs_verdict_gives_the_counts_so_far() -> None:
    """Item 8: INTERRUPTED, with the counts of the steps checked before the signal."""
    s = _summary(stopped="interrupted")
    assert outcome(s) == ("INTERRUPTED", EXIT_INTERRUPTED)
    last = format_table(s).splitlines()[-1]
    assert last.startswith("INTERRUPTED: zenoh run") and "steps 0–51: contained on 312 of 312 node-steps" in last
    assert "interrupted (Ctrl-C or SIGTERM): the counts are of steps 0–51 of the run's 300" in last
