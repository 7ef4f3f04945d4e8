"""How a node takes its inputs before and around step 0 (the start-up race of a loaded machine)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from netsetest.bus import keys
from netsetest.bus.base import MemoryBus
from netsetest.config.schema import Scenario, load_topology
from netsetest.messages import NodeInput
from netsetest.roles.node import Node
from message_helpers import make_state

PAPER6 = Path(__file__).resolve().parents[2] / "topologies" / "paper6.toml"


def _alone(sc: Scenario) -> Scenario:
    """The topology without its bounded readings and neighbours' sets (tests/unit/test_node_bounded.py): the exchange under test alone."""
    return dataclasses.replace(sc, bounded_readings=False, neighbour_sets=False)


def _input(sc, step: int) -> NodeInput:
    if step == 0:
        return NodeInput(step=0, node=1, y=0.0, gamma=1.0)
    return NodeInput(step=step, node=1, y=0.0, gamma=1.0, u_prev=(sc.steer_low + sc.steer_high) / 2, vx_prev=sc.vx(step - 1))


def test_inputs_that_arrive_with_step_0_before_the_node_took_it_are_kept() -> None:
    """Real time under load: inputs 0 and 1 reach a node in one pump, before it took step 0.  Input 1 is
    then the next step, not evidence of a run we missed: dropping it left the node stuck at step 0 for the
    whole run (seen at 96 real-time nodes: three nodes lost)."""
    sc = _alone(load_topology(PAPER6, None, 5))
    bus = MemoryBus()
    node = Node(sc, 1, bus, "t")
    states: list[int] = []
    bus.subscribe(keys.node_state("t", 1), lambda key, msg: states.append(msg.step))
    for step in (0, 1):
        bus.publish(keys.node_input("t", 1), _input(sc, step))
    bus.pump(timeout=0.0)
    assert node.drops["before-start"] == 0 and sorted(node.inputs) == [0, 1]
    node.give_up = True  # step 1 goes on without the neighbours (none is expected here anyway)
    while node.try_step():
        bus.pump(timeout=0.0)
    assert node.k == 1 and states == [0, 1]


def test_a_later_input_without_step_0_is_still_dropped_before_start() -> None:
    """Without step 0 in hand, a later input still means a run we missed (or a forgery): dropped and
    counted as evidence for a rejoin, as before."""
    sc = _alone(load_topology(PAPER6, None, 5))
    bus = MemoryBus()
    node = Node(sc, 1, bus, "t")
    bus.publish(keys.node_input("t", 1), _input(sc, 2))
    bus.pump(timeout=0.0)
    assert node.drops["before-start"] == 1 and node.late_start_evidence == 1 and not node.inputs
    assert not node.try_step() and node.k == -1


def test_a_dropped_neighbour_state_answers_the_wait() -> None:
    """A neighbour whose state of our step we dropped as implausible has spoken: the node steps without
    it at once instead of waiting the neighbour timeout for it every step (over Zenoh a false-bound
    mixed run took 289 s against 6.7 s in memory)."""
    sc = _alone(load_topology(PAPER6, None, 5))
    bus = MemoryBus()
    node = Node(sc, 1, bus, "t")
    assert node.others, "node 1 needs an in-neighbour for this test"
    j = node.others[0]
    bus.publish(keys.node_input("t", 1), _input(sc, 0))
    bus.pump(timeout=0.0)
    assert node.try_step() and node.k == 0
    inp = NodeInput(step=1, node=1, y=0.0, gamma=1.0, u_prev=(sc.steer_low + sc.steer_high) / 2, vx_prev=sc.vx(0), expect_from=[j])
    bus.publish(keys.node_input("t", 1), inp)
    bus.pump(timeout=0.0)
    assert node.missing() == [j] and not node.try_step()  # waiting for j
    own = node.own
    assert own is not None
    nb = sc.node(j)
    forged = make_state(
        step=0,
        node=j,
        xhat=[float(a) for a in nb.x0_hat],
        P=[float(a) for a in (nb.P0 * 1e-6).reshape(9)],
        rho=nb.rho,
        gamma=1.0,
        innov=1e6,
        status="init",
        sector=None if not nb.sensor.saturated else (0.8, 0.3),
        sector_basis="none" if not nb.sensor.saturated else "measurement",
    )  # an innovation its own tiny set and noise bound cannot produce
    bus.publish(keys.node_state("t", j), forged)
    bus.pump(timeout=0.0)
    assert node.drops["neighbour-innovation"] == 1
    assert node.missing() == [] and node.try_step() and node.k == 1  # no wait for the dropped copy


def test_symmetric_shape_rounds_as_the_arrays() -> None:
    """A neighbour's P made symmetric in plain floats equals ½(P + Pᵀ) of the arrays exactly (so every step's
    data is what it was), at every scale, overflow included."""
    from netsetest.roles.node import _symmetric

    rng = np.random.default_rng(1)
    for _ in range(500):
        P = rng.normal(size=(3, 3)) * 10.0 ** float(rng.integers(-300, 308))
        with np.errstate(over="ignore"):
            assert np.array_equal(_symmetric(P.reshape(9).tolist()), 0.5 * (P + P.T))
