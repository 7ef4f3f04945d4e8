"""bench/bus_floor.py (Zenoh's floor of ``netsetest bench --only node``): the bare bus process subscribes as a
real-time node of the plain ring does, and sends and receives the payloads that node and its in-neighbours
published, step by step."""

from __future__ import annotations

from pathlib import Path

from netsetest_bench.bus_floor import PAYLOAD_RUN, median_node, ring_payloads, subscribe_as_node
from netsetest_bench.topologies import ring_topology
from netsetest.bus import keys
from netsetest.bus.base import Handler, MemoryBus, Screen
from netsetest.config.schema import load_topology
from netsetest.messages import Message, NodeInput, NodeState, decode
from netsetest.roles.node import Node


class _Subscriptions(MemoryBus):
    """Which keys are subscribed (and whether lazily) and declared for publishing."""

    def __init__(self) -> None:
        super().__init__()
        self.subscribed: set[tuple[str, bool]] = set()
        self.declared: set[str] = set()

    def subscribe(self, key_expr: str, handler: Handler, lazy: bool = False, screen: Screen | None = None) -> None:
        self.subscribed.add((key_expr, lazy))

    def declare_publisher(self, key: str) -> None:
        self.declared.add(key)


def test_the_bare_process_subscribes_as_a_real_time_node(tmp_path: Path) -> None:
    sc = load_topology(str(ring_topology(tmp_path, 9, 4)))
    for i in sc.ids:
        node_bus, bare_bus = _Subscriptions(), _Subscriptions()
        Node(sc, i, node_bus, "r", lazy=True)
        others = tuple(j for j in sc.node(i).in_weights if j != i)

        def nothing(key: str, msg: Message) -> None: ...

        own = subscribe_as_node(bare_bus, "r", i, others, nothing)
        assert bare_bus.subscribed == node_bus.subscribed and bare_bus.declared == node_bus.declared == {own}


def test_the_payloads_are_the_ring_nodes_step_by_step(tmp_path: Path) -> None:
    sc = load_topology(str(ring_topology(tmp_path, 9, 4)))
    node = median_node(sc)
    counts = sorted(len(n.in_weights) - 1 for n in sc.nodes)
    assert len(sc.node(node).in_weights) - 1 == counts[len(counts) // 2]
    p = ring_payloads(sc, node)
    assert set(p.others) == set(sc.node(node).in_weights) - {node} and p.steps == sc.steps
    for k in range(sc.steps + 1):
        sent = decode(p.sent(k))
        assert isinstance(sent, NodeState) and (sent.node, sent.step) == (node, k)
        inp = decode(p.by_key[keys.node_input(PAYLOAD_RUN, node).removeprefix(f"{keys.ROOT}/{PAYLOAD_RUN}/")][k])
        assert isinstance(inp, NodeInput) and (inp.node, inp.step) == (node, k)
        for j in p.others:
            st = decode(p.by_key[f"node/{j}/state"][k])
            assert isinstance(st, NodeState) and (st.node, st.step) == (j, k)
