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
class NodeSummary:
    """The ring's node, each figure of node_budget.FIGURES over the runs (None: not in these figures)."""

    process_us: Range | None = None
    solve_us: Range | None = None
    outside_us: Range | None = None
    outside_ratio: Range | None = None
    wait_us: Range | None = None
    decode_us: Range | None = None
    handle_us: Range | None = None
    build_us: Range | None = None
    encode_us: Range | None = None
    put_us: Range | None = None
    other_us: Range | None = None
    threads_us: Range | None = None
    received: Range | None = None
    sent: Range | None = None
    per_received_us: Range | None = None
    per_sent_us: Range | None = None
    threads_per_message_us: Range | None = None
    outside_per_message_us: Range | None = None


@dataclass(frozen=True)
class FloorSummary:
    """The bare bus process (or the ring's node, the same figures), each figure of bus_floor.FIGURES over the runs."""

    process_us: Range | None = None
    thread_us: Range | None = None
    decode_us: Range | None = None
    wait_us: Range | None = None
    put_us: Range | None = None
    rest_us: Range | None = None
    threads_us: Range | None = None
    received: Range | None = None
    sent: Range | None = None
    per_message_us: Range | None = None


@dataclass(frozen=True)
class RingRun:
    load_before: str
    deadline_misses: int


@dataclass(frozen=True)
class Checkout:
    """One checkout's runs of the profiled ring, and each figure over them (node_budget.FIGURES' keys)."""

    runs: list[RingRun]
    summary: NodeSummary | None = None  # None: no node reported


@dataclass(frozen=True)
class FloorRun:
    load_before: str
    error: str | None = None


@dataclass(frozen=True)
class FloorMode:
    """The bare bus process's runs in one mode, and each figure over them (bus_floor.FIGURES' keys)."""

    runs: list[FloorRun]
    summary: FloorSummary | None = None  # None: no run reported


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
    """``doc`` as :class:`Node`; an empty summary (nothing reported) is None."""
    return typed(Node, _no_empty_summary(doc), what)


def _no_empty_summary(d: object) -> object:
    if isinstance(d, dict):
        return {k: None if k == "summary" and not v else _no_empty_summary(v) for k, v in d.items()}
    return d
