"""The same-step exchange at one node (docs/network.md): a reference publishes its reading as soon as it
has its input; another node waits for it, checks it in context and drops what cannot be a reading of
the run, never repairs it."""

from __future__ import annotations

import dataclasses

from pathlib import Path

import pytest

from netsetest.bus import keys
from netsetest.bus.base import MemoryBus
from netsetest.config.schema import Scenario, load_topology
from netsetest.messages import NodeInput, Reading
from netsetest.roles.node import Node
from netsetest.runtime.security import grants

REFERENCE = Path(__file__).resolve().parents[2] / "topologies" / "paper6_reference.toml"


def _alone(sc: Scenario) -> Scenario:
    """The topology without its bounded readings and neighbours' sets (tests/unit/test_node_bounded.py): the exchange under test alone."""
    return dataclasses.replace(sc, bounded_readings=False, neighbour_sets=False)


def _input(sc, node: int, step: int) -> NodeInput:
    if step == 0:
        return NodeInput(step=0, node=node, y=0.03, gamma=1.0)
    return NodeInput(step=step, node=node, y=0.03, gamma=1.0, u_prev=(sc.steer_low + sc.steer_high) / 2, vx_prev=sc.vx(step - 1))


def _node_after_step_0(steps: int) -> tuple[object, MemoryBus, Node]:
    """Node 2 of paper6_reference on its own bus, its step 0 taken."""
    sc = _alone(load_topology(REFERENCE, None, steps))
    bus = MemoryBus()
    node = Node(sc, 2, bus, "t")
    bus.publish(keys.node_input("t", 2), _input(sc, 2, 0))
    bus.pump()
    assert node.try_step() and node.k == 0
    return sc, bus, node


def test_a_reference_publishes_its_reading_with_its_input_and_no_other_node_does() -> None:
    sc = _alone(load_topology(REFERENCE, None, 5))
    bus = MemoryBus()
    nodes = {i: Node(sc, i, bus, "t") for i in (2, 3)}
    seen: list[tuple[str, Reading]] = []
    bus.subscribe(keys.reading("t", "*"), lambda key, msg: seen.append((key, msg)))
    for i in (2, 3):
        bus.publish(keys.node_input("t", i), _input(sc, i, 0))
    bus.pump()
    bus.pump()
    assert seen == []  # step 0 uses no reading: none is sent
    for i in (2, 3):
        nodes[i].try_step()
        bus.publish(keys.node_input("t", i), _input(sc, i, 1))
    bus.pump()
    bus.pump()
    assert [(k, m.node, m.step, m.y) for k, m in seen] == [(keys.reading("t", 3), 3, 1, 0.03)]


def test_a_node_waits_for_the_reading_and_then_uses_it() -> None:
    sc, bus, node = _node_after_step_0(5)
    bus.publish(keys.node_input("t", 2), _input(sc, 2, 1))
    bus.pump()
    assert node.missing() == [3] and node.awaiting_readings() and not node.try_step(now=1.0)  # the reading of step 1
    bus.publish(keys.reading("t", 3), Reading(step=1, node=3, y=0.0388, gamma=1.0))
    bus.pump()
    assert node.missing() == [] and not node.awaiting_readings()
    states = []
    bus.subscribe(keys.node_state("t", 2), lambda key, msg: states.append(msg))
    assert node.try_step()
    bus.pump()
    assert states[0].readings == [(3, 0.0388, 1.0)]


@pytest.mark.parametrize(
    "key, reading, reason",
    [
        (keys.reading("t", 4), Reading(step=1, node=4, y=0.0, gamma=1.0), "not-a-reference"),  # node 4 is no reference
        (keys.reading("t", 4), Reading(step=1, node=3, y=0.0, gamma=1.0), "not-a-reference"),  # not on its own key
        (keys.reading("t", 3), Reading(step=0, node=3, y=0.0, gamma=1.0), "stale"),  # our step 0 is done
        (keys.reading("t", 3), Reading(step=1, node=3, y=0.0, gamma=0.5), "reading-gamma"),  # NSNIM: γ = 1
        (keys.reading("t", 3), Reading(step=60, node=3, y=0.0, gamma=1.0), "implausible-step"),
    ],
)
def test_a_reading_that_cannot_be_one_of_the_run_is_dropped(key: str, reading: Reading, reason: str) -> None:
    _, _, node = _node_after_step_0(80)
    node.on_message(key, reading)
    assert node.drops[reason] == 1 and not node.readings


def test_a_second_copy_of_a_reading_is_dropped_and_the_first_counts() -> None:
    sc = _alone(load_topology(REFERENCE, None, 5))
    node = Node(sc, 2, MemoryBus(), "t")
    node.on_message(keys.reading("t", 3), Reading(step=1, node=3, y=0.01, gamma=1.0))
    node.on_message(keys.reading("t", 3), Reading(step=1, node=3, y=0.02, gamma=1.0))
    assert node.drops["duplicate-reading"] == 1 and node.readings == {1: {3: (0.01, 1.0)}}


def test_the_access_control_lets_the_reference_publish_and_every_other_node_receive_its_readings() -> None:
    sc = _alone(load_topology(REFERENCE))
    g = grants(sc, "r1")
    assert keys.reading("r1", 3) in g["node-3"].publish
    for i in sc.ids:
        assert (keys.reading("r1", 3) in g[f"node-{i}"].receive) == (i != 3)
        assert all(keys.reading("r1", j) not in g[f"node-{i}"].publish for j in sc.ids if j != 3)
    paper6 = _alone(load_topology(REFERENCE.with_name("paper6.toml")))
    assert not any("reading" in k for gr in grants(paper6, "r1").values() for k in (*gr.publish, *gr.receive) if "node/" in k)


def test_a_silent_reference_costs_one_wait_not_one_per_step() -> None:
    """A reference whose reading did not come before the node gave up is not waited for again until one of
    its readings arrives (a dead reference would otherwise cost every later step the neighbour timeout)."""
    sc, bus, node = _node_after_step_0(10)
    bus.publish(keys.node_input("t", 2), _input(sc, 2, 1))
    bus.pump()
    assert node.missing() == [3]
    node.give_up = True  # the runtime's deadline for step 1 passed
    assert node.try_step() and node.k == 1 and node.silent == {3}
    bus.publish(keys.node_input("t", 2), _input(sc, 2, 2))
    bus.pump()
    assert node.missing() == [] and not node.awaiting_readings() and node.try_step() and node.k == 2  # no wait
    bus.publish(keys.reading("t", 3), Reading(step=3, node=3, y=0.0388, gamma=1.0))  # it speaks again
    bus.publish(keys.node_input("t", 2), _input(sc, 2, 4))
    bus.pump()
    assert node.silent == set()
    bus.publish(keys.node_input("t", 2), _input(sc, 2, 3))
    bus.pump()
    assert node.try_step() and node.k == 3  # its reading of step 3 is here
    assert node.missing() == [3]  # and for step 4 the node waits for it again
