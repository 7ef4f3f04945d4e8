"""What a role process costs besides its work: its environment, its imports, its idle wake-ups."""

from __future__ import annotations

import subprocess
import sys

import pytest

from netsetest.bus.base import MemoryBus
from netsetest.config.schema import load_topology
from netsetest.roles.node import Node
from netsetest.bus import keys
from netsetest.messages import Ready
from netsetest.runtime.processes import (
    IDLE_WAIT_S,
    READY_PERIOD_S,
    ROLE_ENV,
    Barrier,
    _all_roles,
    _node_wait,
    node_peers,
    role_env,
)


def test_role_env_adds_defaults_and_keeps_the_users():
    env = role_env({"PATH": "/bin", "MALLOC_ARENA_MAX": "8"})
    assert env["PATH"] == "/bin" and env["MALLOC_ARENA_MAX"] == "8"  # the user's value wins
    assert env["OPENBLAS_NUM_THREADS"] == ROLE_ENV["OPENBLAS_NUM_THREADS"] == "1"
    assert env["ZENOH_RUNTIME"] == ROLE_ENV["ZENOH_RUNTIME"]


def test_zenoh_accepts_the_runtime_setting():
    """A malformed ZENOH_RUNTIME makes zenoh panic at its first session: open one with ours."""
    code = "import zenoh; c = zenoh.Config(); c.insert_json5('scouting/multicast/enabled', 'false'); zenoh.open(c).close(); print('ok')"
    out = subprocess.run([sys.executable, "-c", code], env=role_env(), capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-500:]


def test_node_process_imports_no_dead_weight():
    """A node reads its credentials but never writes any: cryptography, scipy and cvxpy stay unimported."""
    code = (
        "import sys, netsetest.cli.main, netsetest.cli.processes, netsetest.runtime.security, netsetest.runtime.processes, "
        "netsetest.bus.zenoh_bus, netsetest.roles.node; "
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'cryptography', 'scipy', 'cvxpy', 'matplotlib'}))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "[]", (out.stdout, out.stderr[-500:])


def test_node_blocks_until_something_is_due():
    sc = load_topology("topologies/paper6.toml", steps=3)
    node = Node(sc, 1, MemoryBus(), "t")
    # not started: until its next Ready is due
    assert _node_wait(node, ready_due=10.0 + READY_PERIOD_S, neighbour_timeout=5.0, reading_wait=None, now=10.03) == pytest.approx(READY_PERIOD_S - 0.03)
    assert _node_wait(node, ready_due=10.0 + READY_PERIOD_S, neighbour_timeout=5.0, reading_wait=None, now=10.5) == 0.0
    assert _node_wait(node, ready_due=None, neighbour_timeout=5.0, reading_wait=None, now=10.5) == IDLE_WAIT_S  # quiet: input 0 wakes it
    node.k = 2
    assert _node_wait(node, 0.0, 5.0, None, now=100.0) == IDLE_WAIT_S  # started, nothing due: sleep on the queue
    node.waiting_since = 98.0  # lockstep, waiting for neighbours: their states wake it, never past the deadline
    assert _node_wait(node, 0.0, 5.0, None, now=100.0) == pytest.approx(3.0)
    assert _node_wait(node, 0.0, 5.0, None, now=102.9995) == pytest.approx(0.0005)
    assert _node_wait(node, 0.0, 5.0, None, now=104.0) == 0.0
    # real time waits only for the readings, within its budget, looking for them (lazy) every poll period
    assert _node_wait(node, 0.0, 5.0, (2.5, 0.2), now=100.0) == pytest.approx(0.2)
    assert _node_wait(node, 0.0, 5.0, (2.5, 0.2), now=100.4) == pytest.approx(0.1)
    assert _node_wait(node, 0.0, 5.0, (2.5, 0.2), now=101.0) == 0.0


def test_a_node_listens_to_its_peers_ready_only():
    """Paper ring: node 1 exchanges states with 2 and 6 only; Ready of nodes 3–5 never reaches it, so
    the start-up barrier costs O(N·degree) messages, not O(N²)."""
    sc = load_topology("topologies/paper6.toml", steps=3)
    assert node_peers(sc, 1) == {("vehicle", None), ("collector", None), ("node", 2), ("node", 6)}
    bus = MemoryBus()
    node = Barrier(bus, "t", Ready(role="node", node=1), node_peers(sc, 1))
    vehicle = Barrier(bus, "t", Ready(role="vehicle"), _all_roles(sc) - {("vehicle", None)})
    for i in sc.ids:
        bus.publish(keys.ready_of("t", keys.role_name("node", i)), Ready(role="node", node=i, seen_all=True))
    bus.publish(keys.ready_of("t", "collector"), Ready(role="collector"))
    bus.pump()
    assert node.heard == {("collector", None), ("node", 2), ("node", 6)}  # and its own Ready is not for itself
    assert vehicle.heard == _all_roles(sc) - {("vehicle", None)}  # the vehicle still hears everyone
    assert ("node", 4) in vehicle.complete


def test_a_barrier_goes_quiet_once_everyone_heard_it():
    """A node repeats its Ready until its seen_all went out and every peer reported seen_all (each heard
    it); then it stops (its start-up traffic would otherwise load step 0), and answers a newcomer still."""
    sc = load_topology("topologies/paper6.toml", steps=3)
    bus = MemoryBus()
    sent: list[Ready] = []
    bus.subscribe(keys.ready_of("t", keys.role_name("node", 1)), lambda key, msg: sent.append(msg))
    node = Barrier(bus, "t", Ready(role="node", node=1), node_peers(sc, 1))
    node.tick(1.0)
    bus.pump()
    assert [m.seen_all for m in sent] == [False] and not node.quiet and node.next_due() == 1.0 + READY_PERIOD_S
    for role, i in sorted(node_peers(sc, 1), key=str):
        bus.publish(keys.ready_of("t", keys.role_name(role, i)), Ready(role=role, node=i, seen_all=False))
    bus.pump()
    node.tick(1.01)  # prompt: newcomers heard; our seen_all goes out, but the peers have not reported theirs
    bus.pump()
    assert sent[-1].seen_all and not node.quiet
    for role, i in sorted(node_peers(sc, 1), key=str):
        bus.publish(keys.ready_of("t", keys.role_name(role, i)), Ready(role=role, node=i, seen_all=True))
    bus.pump()
    n = len(sent)
    node.tick(5.0)
    bus.pump()
    assert node.quiet and node.next_due() is None and len(sent) == n  # nothing repeated
    node.prompt = True  # a role heard for the first time (a restarted peer) is still answered
    node.tick(6.0)
    bus.pump()
    assert len(sent) == n + 1


def test_run_gives_large_networks_longer_to_start():
    from netsetest.runtime.launcher import START_S_PER_ROLE, run_start_timeout
    from netsetest.runtime.timeouts import START_TIMEOUT_S

    assert run_start_timeout(8) == START_TIMEOUT_S  # the paper run keeps the vehicle's default
    assert run_start_timeout(130) == 130 * START_S_PER_ROLE > START_TIMEOUT_S  # 128 nodes + vehicle + collector


def test_roles_declare_their_publishers_before_the_run():
    """The vehicle's inputs, truth and End and a node's state are declared at construction, so that the
    transport announces them during start-up rather than in step 0's burst."""
    from netsetest.roles.vehicle import Vehicle

    class Recording(MemoryBus):
        def __init__(self) -> None:
            super().__init__()
            self.declared: list[str] = []

        def declare_publisher(self, key: str) -> None:
            self.declared.append(key)

    sc = load_topology("topologies/paper6.toml")
    bus = Recording()
    Vehicle(sc, bus, "t", "paper", 0)
    assert set(bus.declared) == {keys.truth("t"), keys.end("t"), *(keys.node_input("t", i) for i in sc.ids)}
    bus.declared.clear()
    Node(sc, 3, bus, "t")
    # paper6's sensors declare fault bounds, so every node reads the others' readings with them ([network] bounded_readings)
    assert bus.declared == [keys.node_state("t", 3), keys.reading("t", 3)]
