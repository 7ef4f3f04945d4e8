"""The exact part's figures (bench/exact.json: ``netsetest bench --only exact``) as typed data."""

from __future__ import annotations

from dataclasses import dataclass, field

from netsetest_bench.render import typed


@dataclass(frozen=True)
class ExactRun:
    """``netsetest exact`` on one record in a process of its own: CPU, memory, how its ends ended."""

    topology: str
    nodes: int
    case: str
    steps: int
    budget_s: float
    cpu_s: float
    wall_s: float
    peak_mb: float
    rss_mb: list[float]  # resident memory before each step
    ends: int
    exact_ends: int
    relaxed_ends: int
    solves: int
    seed: int = 0
    limit: str = ""  # the network part's: central, or each node's network limit

    def growth(self) -> float:
        """Resident memory after the last step over that before the middle step (MB)."""
        return self.rss_mb[-1] - self.rss_mb[len(self.rss_mb) // 2]


@dataclass(frozen=True)
class ExactCost:
    steps: int
    rows: list[ExactRun]
    network: list[ExactRun] = field(default_factory=list)  # issue 44: exact and exact --network on the ring
    load: str = "?"


def load(doc: dict, what: str = "the exact figures") -> ExactCost:
    return typed(ExactCost, doc, what)
