"""Issue 33, real time: a collector past its memory budget closes the oldest steps unjudged as
``collector overloaded``, counted under that name; no node that published is reported missing or
rejoined, and the verdict says how many steps and why (roles/collector.py, runtime/report.py)."""

from __future__ import annotations

from pathlib import Path

from netsetest.bus.base import MemoryBus
from netsetest.config.schema import load_topology
from netsetest.roles.collector import Collector
from netsetest.runtime.inmemory import run_inmemory, run_meta
from netsetest.runtime.report import EXIT_OK, format_table, outcome

ROOT = Path(__file__).resolve().parents[2]
STEPS = 30
BUDGET_STEPS = 5  # steps of paper6 (six states and a truth each) the lagging collector may hold


def test_a_collector_past_its_budget_blames_no_node() -> None:
    sc = load_topology(ROOT / "topologies" / "paper6.toml", None, STEPS)
    bus = MemoryBus()
    per_step = len(sc.ids) + 1
    behind = Collector(sc, bus, "mem", None, realtime=True, budget=BUDGET_STEPS * per_step)
    steps_seen = []

    def overloaded_now(k: int) -> None:  # the collector never gets the time to judge: only its budget closes steps
        behind.close_ready(most=0)
        steps_seen.append(k)

    run_inmemory(sc, bus=bus, on_step=overloaded_now)
    assert behind.peak_open_node_steps <= BUDGET_STEPS * per_step + per_step  # the budget holds, give or take the step arriving
    s = behind.finish(run_meta(sc, "inmemory", "realtime", "paper", "scheduled", 0, "mem"))
    total = (STEPS + 1) * len(sc.ids)
    assert s.steps_overloaded > STEPS - 2 * BUDGET_STEPS, s.steps_overloaded  # most steps closed past the budget
    assert s.node_steps_overloaded == s.steps_overloaded * len(sc.ids)  # every node published each of them
    assert s.node_steps_evaluated + s.node_steps_overloaded == total  # the rest judged at the end, none lost
    assert s.nodes_missing == [] and s.nodes_rejoined == [] and all(r.missing_from is None for r in s.nodes)
    assert s.collector_budget == BUDGET_STEPS * per_step and s.collector_peak == behind.peak_open_node_steps
    assert outcome(s) == ("PASS (partial coverage)", EXIT_OK)
    assert f"collector overloaded on {s.steps_overloaded} step(s) (past its budget of {s.collector_budget}" in format_table(s).splitlines()[-1]


def test_what_the_collectors_full_inbox_dropped_is_not_a_node_missing() -> None:
    """A collector that did not pump while a whole run arrived: its inbox kept MAX_PER_KEY steps per key
    and dropped the rest.  Before, every node was then "missing" (or "rejoined") though all published."""
    from netsetest.bus.base import MAX_PER_KEY
    from netsetest.messages import NodeState, Truth

    sc = load_topology(ROOT / "topologies" / "paper6.toml", None, MAX_PER_KEY + 16)
    recorded = MemoryBus()
    sent: list = []
    recorded.subscribe("netsetest/**", lambda key, msg: sent.append((key, msg)) if isinstance(msg, Truth | NodeState) else None)
    run_inmemory(sc, bus=recorded)
    bus = MemoryBus()
    behind = Collector(sc, bus, "mem", None, realtime=True)
    for key, msg in sent:  # all of it before the collector pumps once
        bus.publish(key, msg)
    assert bus.dropped["inbox-full"] > 0
    while bus.pump():
        behind.close_ready()
    s = behind.finish(run_meta(sc, "inmemory", "realtime", "paper", "scheduled", 0, "mem"))
    lost_steps = sc.steps + 1 - MAX_PER_KEY
    assert s.steps_completed == sc.steps and s.steps_overloaded == lost_steps
    assert s.node_steps_overloaded == lost_steps * len(sc.ids) and s.node_steps_evaluated == MAX_PER_KEY * len(sc.ids)
    assert s.nodes_missing == [] and s.nodes_rejoined == [] and all(r.missing_steps == 0 for r in s.nodes)
    assert outcome(s).code == EXIT_OK and "(its inbox full)" in format_table(s).splitlines()[-1]


def test_the_collector_acknowledges_every_stride_and_the_last_step() -> None:
    """The in-memory run goes through the same acknowledgments as the processes (its collector shares the bus)."""
    from netsetest.bus import keys
    from netsetest.messages import Ready
    from netsetest.roles.flow import ACK_STRIDE

    sc = load_topology(ROOT / "topologies" / "paper6.toml", None, 20)
    bus = MemoryBus()
    acks: list[int] = []
    bus.subscribe(keys.ready_of("mem", "collector"), lambda key, msg: acks.append(msg.acked) if isinstance(msg, Ready) else None)
    s = run_inmemory(sc, bus=bus).summary
    assert s.steps_completed == sc.steps and s.collector_budget is None and s.steps_overloaded == 0
    assert acks == sorted(acks) and acks[-1] == sc.steps and all(b - a >= ACK_STRIDE for a, b in zip(acks, acks[1:-1]))
