"""Malformed messages from the network are dropped and counted, never used (docs/design.md §6, wire format).

(a) two ``ZenohBus`` peers in this process; (b) a whole run launched role by role with an injector
session that publishes bad payloads on the run's keys while the run goes.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter

import msgpack
import numpy as np
import pytest
from zenoh_helpers import (
    read_record,
    PAPER6,
    ROOT,
    free_ports,
    launch_peer_mesh,
    new_run_id,
    read_json,
    wait_roles,
)

from netsetest.bus import keys
from netsetest.bus.zenoh_bus import ZenohBus
from netsetest.messages import SCHEMA_VERSION, NodeInput, NodeState, encode
from message_helpers import make_state, raw_message

pytestmark = pytest.mark.zenoh


def _state(node: int = 2, step: int = 0, **changes: object) -> NodeState:
    return make_state(
        step=step,
        node=node,
        xhat=[0.0, 0.0, 0.0],
        P=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
        rho=1.0,
        gamma=1.0,
        innov=0.0,
        status="ok",
        **changes,
    )


def _raw(msg: NodeState | NodeInput, **fields: object) -> bytes:
    """The msgpack map of ``msg`` with some fields replaced (bypassing validation)."""
    return msgpack.packb(raw_message(msg, **fields), use_bin_type=True)


GARBAGE = b"\x00\xffthis is not msgpack\xc1"
A_LIST = msgpack.packb([1, 2, 3])
BAD_STATES = {  # payload → the reason Bus.pump counts it under
    "garbage": (GARBAGE, "undecodable"),
    "list": (A_LIST, "not-a-map"),
    "version": (_raw(_state(), v=SCHEMA_VERSION + 1), "schema-version"),
    "old-version": (_raw(_state(), v=1), "schema-version"),  # a node of before the ProvenSets
    "nan": (_raw(_state(), xhat=[0.0, math.nan, 0.0]), "invalid"),
    "not-spd": (_raw(_state(), P=[1.0, 2.0, 0, 2.0, 1.0, 0, 0, 0, 1.0]), "invalid"),
}


@pytest.fixture
def bus_pair():
    (port,) = free_ports(1)
    ep = f"tcp/127.0.0.1:{port}"
    opened: list[ZenohBus] = []
    try:
        rx = ZenohBus("peer", listen=[ep])
        opened.append(rx)
        tx = ZenohBus("peer", connect=[ep])
        opened.append(tx)
        yield rx, tx
    finally:
        for b in opened:
            b.close()


@pytest.mark.timeout(60)
def test_zenoh_bus_drops_and_counts_malformed(bus_pair) -> None:
    rx, tx = bus_pair
    seen: list[tuple[str, object]] = []
    rx.subscribe("netsetest/t/node/*/state", lambda key, msg: seen.append((key, msg)))
    key = keys.node_state("t", 2)

    # the first puts race the subscription: repeat a valid state until one is through
    deadline = time.monotonic() + 20
    while not seen:
        assert time.monotonic() < deadline, "no valid message arrived between the two sessions"
        tx.publish(key, _state(step=0))
        rx.pump(timeout=0.1)
    rx.pump(timeout=0.3)  # late copies of the warm-up state
    assert not rx.dropped
    before = len(seen)

    for payload, _ in BAD_STATES.values():
        tx.send_raw(key, payload)
    tx.publish(key, _state(step=99))  # sentinel: same key, same publisher, so it arrives last

    deadline = time.monotonic() + 10
    while not any(m.step == 99 for _, m in seen):
        assert time.monotonic() < deadline, f"sentinel never arrived; dropped so far {dict(rx.dropped)}"
        rx.pump(timeout=0.1)

    assert all(isinstance(m, NodeState) for _, m in seen)
    assert [m.step for _, m in seen[before:]] == [99], "a malformed payload reached the handler"
    assert all(k == key for k, _ in seen)
    assert rx.dropped == Counter(reason for _, reason in BAD_STATES.values())
    assert rx.dropped == {"undecodable": 1, "not-a-map": 1, "schema-version": 2, "invalid": 2}
    assert rx.received == len(seen) + 6


class Injector:
    """A separate Zenoh session (listening; every role also connects to it) that keeps publishing bad
    payloads on a run's keys from before the run starts until it is over."""

    def __init__(self, run_id: str) -> None:
        self.run = run_id
        (port,) = free_ports(1)
        self.endpoint = f"tcp/127.0.0.1:{port}"
        self.bus = ZenohBus("peer", listen=[self.endpoint])
        self.heard: set[tuple[str, int | None]] = set()  # Ready of the roles: they are connected to us
        self.bus.subscribe(keys.ready_of(run_id, "*"), lambda key, m: self.heard.add((m.role, m.node)))
        self.stop = threading.Event()
        self.sent = 0
        self.thread = threading.Thread(target=self._loop, daemon=True)

    def payloads(self) -> list[tuple[str, bytes]]:
        r = self.run
        st2, in1 = keys.node_state(r, 2), keys.node_input(r, 1)
        inp = NodeInput(step=100000, node=1, y=0.0, gamma=1.0)
        return [
            (st2, GARBAGE),
            (st2, A_LIST),
            (st2, _raw(_state(node=2), v=7)),  # wrong schema version
            (st2, _raw(_state(node=2), xhat=[math.nan, 0.0, 0.0])),  # NaN
            (st2, _raw(_state(node=2), P=[1.0, 2.0, 0, 2.0, 1.0, 0, 0, 0, 1.0])),  # not positive definite
            (st2, encode(_state(node=5))),  # valid, but node 5's state on node 2's key
            (st2, encode(_state(node=9))),  # valid, but node 9 is not in the topology
            (keys.node_state(r, 9), encode(_state(node=9))),  # an unknown node on its own key
            (in1, GARBAGE),
            (in1, _raw(inp, v=0)),
            (in1, _raw(inp, y=math.inf)),
            (in1, _raw(inp, gamma=0.0)),
            (in1, encode(inp.model_copy(update={"node": 2}))),  # node 2's input on node 1's key
        ]

    def _loop(self) -> None:
        batch = self.payloads()
        while not self.stop.is_set():
            self.bus.pump(timeout=0.0)
            for key, payload in batch:
                self.bus.send_raw(key, payload)
                self.sent += 1
            self.stop.wait(0.1)

    def __enter__(self) -> Injector:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join(5)
        self.bus.close()


@pytest.mark.timeout(150)
def test_zenoh_run_ignores_injected_garbage(procs, tmp_path) -> None:
    steps, seed = 40, 1
    run_id = new_run_id()
    summary_path, record_path = tmp_path / "summary.json", tmp_path / "record.json"
    with Injector(run_id) as inj:
        launch_peer_mesh(procs, PAPER6, run_id, steps, summary_path, seed=seed, record=record_path, also_connect=[inj.endpoint])
        codes = wait_roles(procs, 120)
        heard = set(inj.heard)
        assert inj.sent > 0
    logs = procs.logs()
    assert codes == {n: 0 for n in codes}, f"exit codes {codes}\n{logs}"

    s = read_json(summary_path)
    assert s["violations_total"] == 0 and s["steps_completed"] == steps and s["nodes_missing"] == []
    for row in s["nodes"]:
        assert row["steps_reported"] == steps + 1 and row["violations"] == 0, row

    # the collector (subscribed to node/*/state) dropped every kind of bad state
    dropped = s["dropped_messages"]
    for reason in ("undecodable", "not-a-map", "schema-version", "invalid", "unknown-node"):
        assert dropped.get(reason, 0) > 0, f"collector dropped {dropped}: nothing under {reason!r} (injector heard {heard})"
    # nodes 1 and 3 subscribe to node 2's key (node 1 also gets the bad inputs); the others never see them
    per_node = {r["id"]: r["dropped_messages"] for r in s["nodes"]}
    assert per_node[1] > 0 and per_node[3] > 0, per_node
    assert per_node[4] == per_node[5] == per_node[6] == 0, per_node

    # never used: the numbers are exactly those of an undisturbed in-memory run
    from netsetest.config.schema import load_topology
    from netsetest.runtime.inmemory import run_inmemory

    mem = run_inmemory(load_topology(ROOT / PAPER6, None, steps), "paper", "scheduled", seed=seed).parts
    rec = read_record(record_path)
    assert rec["truth"] == mem["truth"]
    for i, entries in rec["nodes"].items():
        assert [e["step"] for e in entries] == [e["step"] for e in mem["nodes"][i]] == list(range(steps + 1))
        for ze, me in zip(entries, mem["nodes"][i]):
            where = f"node {i} step {ze['step']}"
            np.testing.assert_allclose(ze["published"]["xhat"], me["published"]["xhat"], rtol=0, atol=1e-9, err_msg=where)
            np.testing.assert_allclose(ze["published"]["P"], me["published"]["P"], rtol=0, atol=1e-9, err_msg=where)
            assert ze["used"] == me["used"] and ze["missing"] == [], where


@pytest.mark.timeout(60)
def test_zenoh_node_drops_far_future_input_before_start(bus_pair) -> None:
    """A NodeInput after the run's last step that reaches a node still waiting for step 0 is dropped."""
    from netsetest.bus.base import Bus
    from netsetest.config.schema import load_topology
    from netsetest.roles.node import Node

    rx, tx = bus_pair
    sc = load_topology(ROOT / PAPER6, None, 12)
    node = Node(sc, 1, rx, "t")
    states: list[NodeState] = []
    rx.subscribe(keys.node_state("t", 1), lambda key, msg: states.append(msg))  # what node 1 publishes
    key = keys.node_input("t", 1)
    deadline = time.monotonic() + 20
    while not node.drop_report().get("step-beyond-run"):  # the first puts race the subscription (its bus screens them out, undecoded)
        assert time.monotonic() < deadline, "no input arrived"
        tx.publish(key, NodeInput(step=100000, node=1, y=0.0, gamma=1.0))
        rx.pump(timeout=0.1)
    tx.publish(key, NodeInput(step=0, node=1, y=0.01, gamma=1.0))
    deadline = time.monotonic() + 10
    while 0 not in node.inputs:
        assert time.monotonic() < deadline, "the step-0 input did not arrive"
        rx.pump(timeout=0.1)
    assert node.try_step()
    rx.pump(timeout=0.5)
    assert node.k == 0 and [s.step for s in states] == [0] and states[0].status == "init"
    # beyond the run: no evidence that the run started without us
    assert isinstance(rx, Bus) and node.drop_report()["step-beyond-run"] >= 1 and node.late_start_evidence == 0


@pytest.mark.timeout(60)
def test_zenoh_vehicle_ignores_state_on_a_foreign_key(bus_pair) -> None:
    from netsetest.config.schema import load_topology
    from netsetest.roles.vehicle import Vehicle

    rx, tx = bus_pair
    sc = load_topology(ROOT / PAPER6, None, 12)
    vehicle = Vehicle(sc, rx, "t", "paper", 0)
    vehicle.advance()  # step 0 published
    spoof, key = _state(node=5, step=0), keys.node_state("t", 2)
    deadline = time.monotonic() + 20
    while not rx.received:  # the first puts race the subscription
        assert time.monotonic() < deadline, "nothing arrived"
        tx.publish(key, spoof)
        rx.pump(timeout=0.1)
    rx.pump(timeout=0.3)
    assert 5 not in vehicle.heard.get(0, set()), "the vehicle took node 5's state from node 2's key"
    assert vehicle.drops["state-on-foreign-key"] >= 1
