"""The profile's observer of a node (netsetest/profile.py, ``observe_node``), on a node of an in-memory run."""

from __future__ import annotations

from pathlib import Path

from netsetest.config.schema import load_topology
from netsetest.profile import PhaseProfile, observe_node
from netsetest.roles.node import Node
from netsetest.runtime.inmemory import run_inmemory

ROOT = Path(__file__).resolve().parents[2]


def test_an_observed_node_charges_its_solves_and_builds_from_its_first_solved_step() -> None:
    """A node stepped through a paper6 run in memory: the window starts at its first solved step, the solve and build
    phases are charged once a step from there, and the report covers those steps."""
    sc = load_topology(ROOT / "topologies" / "paper6.toml", "nsnim", 6)
    prof = PhaseProfile()
    nodes: list[Node] = []
    real = Node.__init__

    def observed_init(self: Node, *args: object, **kwargs: object) -> None:
        real(self, *args, **kwargs)  # type: ignore[arg-type]  # Node's own arguments, passed through
        if not nodes:
            nodes.append(self)
            observe_node(self, prof)

    Node.__init__ = observed_init  # type: ignore[method-assign]  # restored below
    try:
        run_inmemory(sc, "paper", "scheduled", 0)
    finally:
        Node.__init__ = real  # type: ignore[method-assign]  # the real one back
    report = prof.report(nodes[0].k - 1)
    assert prof.started and report["steps"] == 5
    assert prof.calls["solve"] == 5 and prof.calls["build"] == 5  # steps 2..6 after the window opened at step 1
