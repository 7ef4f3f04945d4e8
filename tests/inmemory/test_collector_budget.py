"""Issue 33, real time: a collector past its memory budget closes the oldest steps unjudged as
``collector overloaded``, counted under that name; no node that published is reported missing or
rejoined, and the verdict says how many steps and why (roles/collector.py, runtime/report.py)."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

from netsetest.bus.base import MAX_PER_KEY, MemoryBus
from netsetest.config.schema import load_topology
from netsetest.messages import Message, NodeState, Truth
from netsetest.records.summary import RunSummary
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
    assert behind.admission.peak_open_node_steps <= BUDGET_STEPS * per_step + per_step  # the budget holds, give or take the step arriving
    s = behind.finish(run_meta(sc, "inmemory", "realtime", "paper", "scheduled", 0, "mem"))
    total = (STEPS + 1) * len(sc.ids)
    assert s.steps_overloaded > STEPS - 2 * BUDGET_STEPS, s.steps_overloaded  # most steps closed past the budget
    assert s.node_steps_overloaded == s.steps_overloaded * len(sc.ids)  # every node published each of them
    assert s.node_steps_evaluated + s.node_steps_overloaded == total  # the rest judged at the end, none lost
    assert s.nodes_missing == [] and s.nodes_rejoined == [] and all(r.missing_from is None for r in s.nodes)
    # the step judged after one closed unjudged is outside the guarantee for the collector's loss, not the truth's
    assert s.node_steps_not_covered.get("collector overloaded", 0) >= len(sc.ids), s.node_steps_not_covered
    assert "truth unknown" not in s.node_steps_not_covered, s.node_steps_not_covered
    assert s.collector_budget == BUDGET_STEPS * per_step and s.collector_peak == behind.admission.peak_open_node_steps
    assert outcome(s) == ("PASS (partial coverage)", EXIT_OK)
    assert f"collector overloaded on {s.steps_overloaded} step(s) (past its budget of {s.collector_budget}" in format_table(s).splitlines()[-1]


def test_what_the_collectors_full_inbox_dropped_is_not_a_node_missing() -> None:
    """A collector that did not pump while a whole run arrived: its inbox kept MAX_PER_KEY steps per key
    and dropped the rest.  Before, every node was then "missing" (or "rejoined") though all published."""
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


# ---------------------------------------------------------------- every node-step in exactly one count

AUDIT_STEPS = 20
K = 8  # the step the cases below take apart


def _partition_holds(s: RunSummary) -> None:
    """Every node-step of the closed steps in exactly one count: judged or not judged (truth unknown,
    contested) among the reported ones, rejected, the collector's overload, or missing (docs/summary.md)."""
    per_node = [r.steps_reported + r.steps_rejected + r.missing_steps for r in s.nodes]
    assert sum(per_node) + s.node_steps_overloaded == (s.steps_completed + 1) * len(s.nodes), (per_node, s.node_steps_overloaded)
    assert s.node_steps_reported == sum(r.steps_reported for r in s.nodes) >= s.node_steps_evaluated + s.node_steps_contested
    assert s.steps_overloaded <= s.node_steps_overloaded, "a step called overloaded with no node-step lost to it"


@functools.cache
def _sent() -> tuple[tuple[str, Message], ...]:
    """The truths and states of an in-memory paper6 run, in the order they were published."""
    sc = load_topology(ROOT / "topologies" / "paper6.toml", None, AUDIT_STEPS)
    recorded = MemoryBus()
    sent: list[tuple[str, Message]] = []
    recorded.subscribe("netsetest/**", lambda key, msg: sent.append((key, msg)) if isinstance(msg, Truth | NodeState) else None)
    run_inmemory(sc, bus=recorded)
    return tuple(sent)


def _replay(collector: Collector, bus: MemoryBus, keep: Callable[[str, Message], bool], before: Callable[[int], None] = lambda k: None) -> RunSummary:
    """The run's messages into ``collector`` step by step (what ``keep`` lets through; ``before(k)`` ahead of step k's)."""
    steps = sorted({m.step for _, m in _sent()})
    for k in steps:
        before(k)
        for key, msg in _sent():
            if msg.step == k and keep(key, msg):
                bus.publish(key, msg)
        while bus.pump():
            collector.close_ready()
    return collector.finish(run_meta(collector.sc, "inmemory", "realtime", "paper", "scheduled", 0, "mem"))


def test_a_step_closed_past_the_budget_without_its_truth_counts_every_node_step_once() -> None:
    """Step K's truth never came and node 4 was silent at K: the collector, past its budget, closes K
    unjudged.  All six node-steps are the collector's overload (it closed K before it could tell who
    published), none a node's: before, node 4's landed in no count at all."""
    sc = load_topology(ROOT / "topologies" / "paper6.toml", None, AUDIT_STEPS)
    bus = MemoryBus()
    per_step = len(sc.ids) + 1
    collector = Collector(sc, bus, "mem", None, realtime=True, budget=4 * per_step)
    s = _replay(collector, bus, lambda key, msg: msg.step != K or not (isinstance(msg, Truth) or msg.node == 4))
    assert s.steps_completed == AUDIT_STEPS and s.steps_overloaded == 1, s
    assert s.node_steps_overloaded == len(sc.ids)
    assert s.nodes_missing == [] and s.nodes_rejoined == [] and all(r.missing_steps == 0 and r.missing_from is None for r in s.nodes)
    _partition_holds(s)
    assert outcome(s) == ("PASS (partial coverage)", EXIT_OK)
    assert f"collector overloaded on 1 step(s) (past its budget of {4 * per_step} open node-steps): 6 node-step(s) not judged" in format_table(s)


def _fill(bus: MemoryBus, key: str, msg: Message) -> None:
    """``key``'s inbox queue full of copies of an earlier, closed step's ``msg``: the next message on it is dropped."""
    for _ in range(MAX_PER_KEY):
        bus.publish(key, msg)


def test_a_step_whose_truth_the_collectors_inbox_dropped_is_its_overload_not_truth_unknown() -> None:
    """Step K's truth reached a full inbox (the truth key flooded with copies of step K − 1's) and was
    dropped; every state of K arrived.  The step is the collector's loss, whole: not judged (collector
    overloaded), never ``truth unknown`` (which reads as the vehicle's doing), no node blamed."""
    sc = load_topology(ROOT / "topologies" / "paper6.toml", None, AUDIT_STEPS)
    bus = MemoryBus()
    collector = Collector(sc, bus, "mem", None, realtime=True)
    truths = {m.step: (key, m) for key, m in _sent() if isinstance(m, Truth)}
    s = _replay(collector, bus, lambda key, msg: True, before=lambda k: _fill(bus, *truths[k - 1]) if k == K else None)
    assert bus.dropped["inbox-full"] == 1
    assert s.steps_completed == AUDIT_STEPS and s.steps_overloaded == 1 and s.node_steps_overloaded == len(sc.ids), s
    assert s.node_steps_reported == s.node_steps_evaluated == AUDIT_STEPS * len(sc.ids), "K's states judged on an unknown truth"
    assert s.nodes_missing == [] and s.nodes_rejoined == [] and all(r.missing_steps == 0 for r in s.nodes)
    _partition_holds(s)
    last = format_table(s).splitlines()[-1]
    assert "collector overloaded on 1 step(s) (its inbox full): 6 node-step(s) not judged" in last, last
    assert "not judged (truth unknown" not in last, last  # (step K + 1 rests on K's states, which no truth judged: not covered)


def test_an_insider_flooding_its_own_state_key_cannot_pass_a_silent_node_off_as_the_collectors_loss() -> None:
    """Node 3 is silent at step K.  Node 2's certificate floods node 2's own state key (the access control
    allows it) until the collector's inbox drops a state there that names node 3, step K.  That is not
    node 3's state on node 3's key: node 3 stays missing at K (and back at K + 1), counted once; only
    what the inbox dropped on its sender's own key is the collector's loss."""
    sc = load_topology(ROOT / "topologies" / "paper6.toml", None, AUDIT_STEPS)
    bus = MemoryBus()
    collector = Collector(sc, bus, "mem", None, realtime=True)
    state = {(m.node, m.step): (key, m) for key, m in _sent() if isinstance(m, NodeState)}
    truth_k = next(m for _, m in _sent() if isinstance(m, Truth) and m.step == K)
    key2 = state[(2, K - 1)][0]

    def flood(k: int) -> None:
        if k == K:
            _fill(bus, *state[(2, K - 1)])
            bus.publish(key2, state[(3, K)][1])  # node 3's state of K, on node 2's key: dropped, inbox full
            bus.publish(key2, truth_k)  # and a truth on it
            while bus.pump():  # the flood handled (duplicates, a state on a foreign key) before step K's messages
                collector.close_ready()

    s = _replay(collector, bus, lambda key, msg: not (isinstance(msg, NodeState) and (msg.node, msg.step) == (3, K)), before=flood)
    assert bus.dropped["inbox-full"] == 2
    assert s.steps_overloaded == 0 and s.node_steps_overloaded == 0, s
    assert s.node(3).missing_steps == 1 and s.node(3).missing_from == K and s.node(3).rejoined_at == K + 1
    assert all(r.missing_steps == 0 for r in s.nodes if r.id != 3) and s.nodes_missing == []
    _partition_holds(s)


LONG_PAUSE_STEPS = 2 * MAX_PER_KEY  # a real-time collector stopped this many steps (12.8 s at τs = 0.1 s)


def test_a_realtime_collector_stopped_longer_than_its_inbox_catches_up_and_blames_no_node() -> None:
    """Real time: the collector stopped for LONG_PAUSE_STEPS steps.  Its inbox kept MAX_PER_KEY steps per
    key and dropped the rest; when it came back, the next truth was more than WINDOW steps past the newest
    it had.  Before, it dropped that truth and every later one as 'ahead' (and the states with them): it
    judged nothing more, and reported every node missing from there.  Now what it lost is its overload,
    and it judges the steps after the pause again."""
    from netsetest.roles.collector import WINDOW

    steps = 40 + LONG_PAUSE_STEPS + 2 * WINDOW
    sc = load_topology(ROOT / "topologies" / "paper6.toml", None, steps)
    recorded = MemoryBus()
    sent: list[tuple[str, Message]] = []
    recorded.subscribe("netsetest/**", lambda key, msg: sent.append((key, msg)) if isinstance(msg, Truth | NodeState) else None)
    run_inmemory(sc, bus=recorded)
    bus = MemoryBus()
    collector = Collector(sc, bus, "mem", None, realtime=True)
    paused = range(40, 40 + LONG_PAUSE_STEPS)
    for k in range(steps + 1):
        for key, msg in sent:
            if msg.step == k:
                bus.publish(key, msg)
        if k not in paused:
            while bus.pump():
                collector.close_ready()
    assert bus.dropped["inbox-full"] > 0
    s = collector.finish(run_meta(sc, "inmemory", "realtime", "paper", "scheduled", 0, "mem"))
    assert s.nodes_missing == [] and s.nodes_rejoined == [] and all(r.missing_steps == 0 for r in s.nodes), [(r.id, r.missing_steps) for r in s.nodes]
    assert s.steps_completed == steps and 0 < s.steps_overloaded <= LONG_PAUSE_STEPS - MAX_PER_KEY + 1, s.steps_overloaded
    assert s.node_steps_evaluated >= (steps + 1 - LONG_PAUSE_STEPS) * len(sc.ids), "the steps after the pause not judged"
    _partition_holds(s)
