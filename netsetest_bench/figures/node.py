"""The node part's figures (bench/node.json: ``netsetest bench --only node``) as typed data."""

from __future__ import annotations

from dataclasses import dataclass, field

from netsetest_bench.render import typed


@dataclass(frozen=True)
class Range:
    """A figure over runs: the median of each run's, the least and the largest (NaN: no messages to divide by)."""

    median: float
    min: float
    max: float


@dataclass(frozen=True)
class RingRun:
    load_before: str
    deadline_misses: int


@dataclass(frozen=True)
class Checkout:
    """One checkout's runs of the profiled ring, and each figure over them (node_budget.FIGURES' keys)."""

    runs: list[RingRun]
    summary: dict[str, Range]


@dataclass(frozen=True)
class FloorRun:
    load_before: str
    error: str | None = None


@dataclass(frozen=True)
class FloorMode:
    """The bare bus process's runs in one mode, and each figure over them (bus_floor.FIGURES' keys)."""

    runs: list[FloorRun]
    summary: dict[str, Range] = field(default_factory=dict)


@dataclass(frozen=True)
class Floor:
    node: int
    in_neighbours: int
    secured: FloorMode
    insecure: FloorMode

    def mode(self, name: str) -> FloorMode:
        return self.secured if name == "secured" else self.insecure


@dataclass(frozen=True)
class Commits:
    this: str | None = None
    baseline: str | None = None


@dataclass(frozen=True)
class Node:
    nodes: int
    steps: int
    reps: int
    this: Checkout
    baseline: Checkout | None = None
    commits: Commits = field(default_factory=Commits)
    ratio: dict[str, float] = field(default_factory=dict)  # this / baseline, per figure
    floor: Floor | None = None


def load(doc: dict, what: str = "the node figures") -> Node:
    return typed(Node, doc, what)
