"""A node's warm-up (netsetest.roles.node.Node.warm_up) leaves no trace: a network whose nodes all warmed
up before the run publishes exactly the states of one whose nodes did not."""

from __future__ import annotations

from pathlib import Path

import pytest

from netsetest.config.schema import load_topology
from netsetest.roles import node as node_module
from netsetest.runtime.inmemory import run_inmemory

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    ("topology", "case", "variant", "signals"),
    [
        ("paper6", "nsnim", "scheduled", "paper"),
        ("paper6", "saim", "scheduled", "paper"),
        ("paper6", "saim", "scheduled", "worst"),
        ("paper6", "nsnim", "per-rule", "paper"),
        ("paper6_reference", "nsnim", "scheduled", "paper"),
        ("paper6_reference", "saim", "scheduled", "paper"),  # the readings' solvers
    ],
)
def test_warm_up_changes_no_published_state(topology: str, case: str, variant: str, signals: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The warm-up runs through the node's own estimator (its layouts and Clarabel solvers are built then)."""
    sc = load_topology(ROOT / "topologies" / f"{topology}.toml", case, 30)
    plain = run_inmemory(sc, signals, variant).parts["nodes"]
    warmed: list[int] = []
    original = node_module.Node.__init__

    def init_and_warm(self, *args, **kwargs) -> None:
        original(self, *args, **kwargs)
        self.warm_up()
        warmed.append(self.id)

    monkeypatch.setattr(node_module.Node, "__init__", init_and_warm)
    after = run_inmemory(sc, signals, variant).parts["nodes"]
    assert sorted(warmed) == sorted(sc.ids)
    assert _without_times(after) == _without_times(plain)  # every published entry, bit for bit


def _without_times(nodes: dict[str, list[dict]]) -> dict[str, list[dict]]:
    return {i: [{k: v for k, v in e.items() if k != "solve_ms"} for e in rows] for i, rows in nodes.items()}
