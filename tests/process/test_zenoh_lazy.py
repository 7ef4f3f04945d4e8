"""Lazy subscriptions of the Zenoh bus (netsetest/bus/base.py, bus/zenoh_bus.py): their messages do not
wake a blocking pump, the next pump delivers them, a flood on one is bounded by its ring and delays no
other key; and a real-time run over Zenoh, whose nodes hear their neighbours lazily, uses them."""

from __future__ import annotations

import json
import subprocess
import threading
import time
from pathlib import Path

import msgspec
import pytest

from netsetest.bus.base import MAX_PER_KEY, MAX_ROUNDS
from netsetest.bus.zenoh_bus import ZenohBus
from netsetest.messages import End, Message
from netsetest.records.record import Record, load_record
from zenoh_helpers import PAPER6, ROOT, cli, free_ports
from message_helpers import make_state

LAZY, WAKE = "lazytest/a/lazy", "lazytest/a/wake"


@pytest.fixture
def pair():
    """Two peers on loopback: ``rx`` subscribes (lazily on LAZY), ``tx`` publishes."""
    p_rx, p_tx = free_ports(2)
    rx = ZenohBus("peer", listen=[f"tcp/127.0.0.1:{p_rx}"], connect=[f"tcp/127.0.0.1:{p_tx}"])
    tx = ZenohBus("peer", listen=[f"tcp/127.0.0.1:{p_tx}"], connect=[f"tcp/127.0.0.1:{p_rx}"])
    got: list[tuple[str, int]] = []

    def handler(key: str, msg: Message) -> None:
        assert isinstance(msg, End)
        got.append((key, msg.steps))

    rx.subscribe(LAZY, handler, lazy=True)
    rx.subscribe(WAKE, handler)
    time.sleep(0.5)  # the peers connect and learn each other's subscriptions
    try:
        yield rx, tx, got
    finally:
        rx.close()
        tx.close()


def _pump_until(rx: ZenohBus, got: list, n: int, timeout: float = 5.0) -> None:
    t0 = time.monotonic()
    while len(got) < n and time.monotonic() - t0 < timeout:
        rx.pump(timeout=0.05)


def test_lazy_message_does_not_wake_but_the_next_pump_delivers_it(pair) -> None:
    rx, tx, got = pair
    tx.publish(LAZY, End(steps=1))
    time.sleep(0.2)  # it is in rx's ring now
    t0 = time.monotonic()
    rx.pump(timeout=0.3)  # collected before the wait: delivered at once, no waiting
    assert got == [(LAZY, 1)] and time.monotonic() - t0 < 0.2
    tx.publish(LAZY, End(steps=2))
    time.sleep(0.05)
    got.clear()
    t0 = time.monotonic()
    rx.pump(timeout=0.4)  # already in the ring when the pump starts: delivered without waiting
    assert got == [(LAZY, 2)] and time.monotonic() - t0 < 0.3
    got.clear()
    t0 = time.monotonic()
    rx.pump(timeout=0.3)  # nothing in: the full timeout
    assert got == [] and time.monotonic() - t0 >= 0.29


def test_lazy_arrival_does_not_end_a_blocking_pump_a_normal_one_does(pair) -> None:
    rx, tx, got = pair

    def publish_later(key: str, steps: int) -> threading.Timer:
        timer = threading.Timer(0.1, lambda: tx.publish(key, End(steps=steps)))
        timer.start()
        return timer

    timer = publish_later(LAZY, 3)
    t0 = time.monotonic()
    rx.pump(timeout=0.6)  # the lazy message arrives after 0.1 s and does not wake us
    waited = time.monotonic() - t0
    timer.join()
    assert waited >= 0.59 and got == [(LAZY, 3)]  # …but is delivered once the wait ends
    got.clear()
    timer = publish_later(WAKE, 4)
    t0 = time.monotonic()
    rx.pump(timeout=3.0)
    elapsed = time.monotonic() - t0
    # the put may still be returning in the timer's thread after rx has the sample: the fixture's close
    # must not undeclare the publisher under it (zenoh-python raises "Already borrowed")
    timer.join()
    assert got == [(WAKE, 4)] and elapsed < 1.5


def test_flood_on_a_lazy_key_is_bounded_and_delays_no_other_key(pair) -> None:
    rx, tx, got = pair
    flood = 10 * MAX_PER_KEY
    for k in range(flood):
        tx.publish(LAZY, End(steps=k))
    tx.publish(WAKE, End(steps=999_999))
    time.sleep(0.5)
    rx.pump(timeout=1.0)
    first = [s for key, s in got if key == LAZY]
    assert (WAKE, 999_999) in got  # the other key in the same pump
    assert 0 < len(first) <= MAX_ROUNDS  # the flooded key: at most MAX_ROUNDS decodes in one pump
    _pump_until(rx, got, flood + 1, timeout=1.0)
    lazy = [s for key, s in got if key == LAZY]
    assert len(lazy) <= 2 * MAX_PER_KEY  # the ring (oldest dropped) and the inbox hold at most this
    assert lazy == sorted(lazy) and lazy[-1] == flood - 1  # in order, the newest kept


def test_a_flood_of_far_steps_loses_the_awaited_state_from_a_ring_not_from_the_inbox() -> None:
    """Why a lockstep node hears its neighbours through the inbox (runtime/processes.py, run_node): an
    insider flooding its own state key with far steps pushes its genuine state out of a lazy ring (the
    oldest goes), and its neighbours waited out their timeout every step; the inbox keeps an earlier
    step over the flood's."""
    p_rx, p_tx = free_ports(2)
    rx = ZenohBus("peer", listen=[f"tcp/127.0.0.1:{p_rx}"], connect=[f"tcp/127.0.0.1:{p_tx}"])
    tx = ZenohBus("peer", listen=[f"tcp/127.0.0.1:{p_tx}"], connect=[f"tcp/127.0.0.1:{p_rx}"])
    got: dict[str, list[int]] = {LAZY: [], WAKE: []}
    try:
        rx.subscribe(LAZY, lambda key, msg: got[key].append(msg.step), lazy=True)
        rx.subscribe(WAKE, lambda key, msg: got[key].append(msg.step))
        time.sleep(0.5)
        far = make_state(step=10_000, node=2, xhat=[0.0] * 3, P=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], rho=1.0, gamma=1.0, innov=0.0, status="ok")
        for key in (LAZY, WAKE):
            for _ in range(4 * MAX_PER_KEY):
                tx.publish(key, far)
            tx.publish(key, msgspec.structs.replace(far, step=7))  # the state a neighbour waits for, amid the flood
            for _ in range(4 * MAX_PER_KEY):
                tx.publish(key, far)
        time.sleep(1.0)  # everything has arrived before the role looks
        t0 = time.monotonic()
        while time.monotonic() - t0 < 2.0:
            rx.pump(timeout=0.05)
    finally:
        rx.close()
        tx.close()
    assert 7 in got[WAKE]  # the inbox: the far steps were turned away, step 7 kept
    assert 7 not in got[LAZY] and len(got[LAZY]) <= MAX_PER_KEY  # the ring kept the newest copies only


def test_lazy_subscription_needs_an_exact_key(pair) -> None:
    rx, _, _ = pair
    with pytest.raises(ValueError, match="exact key"):
        rx.subscribe("lazytest/*/state", lambda k, m: None, lazy=True)


def _realtime_run(topology: Path, steps: int, tmp_path: Path, *extra: str) -> Record:
    """``netsetest run TOPOLOGY --mode zenoh --clock realtime`` (secured), whose summary must say no violation and no
    node missing: its record."""
    summary, record = tmp_path / "s.json", tmp_path / "r.jsonl"
    argv = cli(
        "run",
        topology,
        "--mode",
        "zenoh",
        "--clock",
        "realtime",
        "--steps",
        str(steps),
        "--quiet",
        "--summary-json",
        str(summary),
        "--record",
        str(record),
        *extra,
    )
    out = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=170)
    assert out.returncode == 0, out.stderr[-2000:]
    s = json.loads(summary.read_text())
    assert s["violations_total"] == 0 and not s.get("nodes_missing")
    return load_record(record)


@pytest.mark.timeout(180)
def test_realtime_run_over_zenoh_uses_its_neighbours(tmp_path: Path) -> None:
    """A real-time secured paper run: every node publishes every step, the truth is contained, and the
    nodes, which hear their neighbours lazily, use them (a broken lazy path would leave ``used`` empty)
    and wake about once per step (``run --profile``: blocking waits per step; ≈3 if every neighbour
    state woke the node).  The innovations alone (``bounded_readings = false``): a node waiting for the step's
    readings polls for them (test_realtime_run_over_zenoh_waits_for_the_readings)."""
    steps = 30
    prof = tmp_path / "profile"
    prof.mkdir()
    topology = tmp_path / "paper6_innovations.toml"
    text = Path(PAPER6).read_text().replace('node_dir = "../nodes"', f"node_dir = {str(ROOT / 'nodes')!r}")
    topology.write_text(text + "\n[network]\nbounded_readings = false\n")
    rec = _realtime_run(topology, steps, tmp_path, "--profile", str(prof))
    used_all = total = 0
    for rows in rec.raw_nodes.values():
        assert [e["step"] for e in rows] == list(range(steps + 1))
        for e in rows[1:]:
            total += 1
            used_all += not e["missing"] and len(e["used"]) == 2  # paper6: two in-neighbours each
    assert used_all >= total // 2, f"only {used_all} of {total} node-steps used both neighbours"
    # the vehicle hears the states from a ring per node (roles/vehicle.py): every node alive at every step,
    # past its 20-step window too (states it never collected would have declared the nodes dead by then)
    assert [t["alive"] for t in rec.truth[1:]] == [[1, 2, 3, 4, 5, 6]] * steps
    reports = {p.name: json.loads(p.read_text()) for p in prof.glob("node-*.json")}
    assert sorted(reports) == [f"node-{i}.json" for i in range(1, 7)]
    for name, r in reports.items():
        ph = r["phases"]
        assert r["steps"] == steps - 1 and ph["solve"]["calls_per_step"] == 1.0, (name, r)  # steps 2..30
        assert ph["decode"]["calls_per_step"] >= 2.0 and r["process_ms_per_step"] >= r["thread_ms_per_step"] > 0, (name, r)
        assert ph["wait"]["calls_per_step"] <= 1.5, (name, ph["wait"])  # one wake-up per step: the input


@pytest.mark.timeout(180)
def test_realtime_run_over_zenoh_waits_for_the_readings(tmp_path: Path) -> None:
    """A real-time secured paper6_reference run: sensor 3's reading of each step reaches the other nodes
    within their budget (a quarter period) and they use it nearly every step (docs/network.md)."""
    steps = 20
    rec = _realtime_run(ROOT / "topologies" / "paper6_reference.toml", steps, tmp_path)
    rows = [e for i, es in rec.raw_nodes.items() if i != "3" for e in es[1:]]
    assert len(rows) == 5 * steps
    with_reading = sum(3 in e["readings"] for e in rows)  # the reference's (beside the others' bounded readings)
    assert with_reading >= 0.8 * len(rows), f"only {with_reading} of {len(rows)} node-steps used the reading"


def test_a_screen_drops_passed_steps_undecoded_on_lazy_and_waking_keys() -> None:
    """A subscription's screen (bus/base.py) sees the step a payload names before it is decoded: a payload
    it turns away is counted under the screen's reason, never decoded (one decode() would refuse is counted
    as the screen's, not as ``invalid``) and never handed over; the others are decoded and delivered."""
    p_rx, p_tx = free_ports(2)
    rx = ZenohBus("peer", listen=[f"tcp/127.0.0.1:{p_rx}"], connect=[f"tcp/127.0.0.1:{p_tx}"])
    tx = ZenohBus("peer", listen=[f"tcp/127.0.0.1:{p_tx}"], connect=[f"tcp/127.0.0.1:{p_rx}"])
    got: dict[str, list[int]] = {LAZY: [], WAKE: []}
    first = 5  # the first step the subscriber can still use
    try:
        for key, lazy in ((LAZY, True), (WAKE, False)):
            rx.subscribe(key, lambda k, msg: got[k].append(msg.step), lazy=lazy, screen=lambda step: "stale" if step < first else None)
        time.sleep(0.5)
        good = make_state(step=0, node=2, xhat=[0.0] * 3, P=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], rho=1.0, gamma=1.0, innov=0.0, status="ok")
        not_spd = msgspec.msgpack.encode({**msgspec.to_builtins(good), "type": "state", "step": 3, "P": [-1.0] * 9})
        invalid_kept = msgspec.msgpack.encode({**msgspec.to_builtins(good), "type": "state", "step": 8, "P": [-1.0] * 9})
        for key in (LAZY, WAKE):
            for step in (1, 4, 5, 9):
                tx.publish(key, msgspec.structs.replace(good, step=step))
            tx.send_raw(key, not_spd)  # a passed step: dropped undecoded, as stale
            tx.send_raw(key, invalid_kept)  # a step still to come: decoded, and refused as invalid
        time.sleep(0.5)
        t0 = time.monotonic()
        while len(got[LAZY]) + len(got[WAKE]) < 4 and time.monotonic() - t0 < 5.0:
            rx.pump(timeout=0.05)
    finally:
        rx.close()
        tx.close()
    assert got == {LAZY: [5, 9], WAKE: [5, 9]}
    assert rx.dropped == {"stale": 6, "invalid": 2} and rx.received == 12
