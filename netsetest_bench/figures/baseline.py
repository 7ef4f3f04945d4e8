"""The performance part beside a baseline checkout (``netsetest bench --only performance --baseline DIR``: the run's
``baseline`` figures, netsetest_bench/baseline.py) as typed data, for its table."""

from __future__ import annotations

from dataclasses import dataclass, field

from netsetest_bench.render import typed


@dataclass(frozen=True)
class SideFigure:
    """One figure of both checkouts: the fastest run's (the median run's beside it), their ratio, the issue's target."""

    this: int | float | None = None
    baseline: int | float | None = None
    this_median: float | None = None
    baseline_median: float | None = None
    ratio: float | None = None
    target: str = ""
    met: bool | None = None


@dataclass(frozen=True)
class Part:
    error: str | None = None  # the part was not measured, and why


@dataclass(frozen=True)
class RealtimeRun:
    nodes: int
    deadline_misses: int | None  # None: the run gave no summary (it failed; the bench's log says how)
    node_cpu_ms_per_step: float | None = None


@dataclass(frozen=True)
class Ladder:
    runs: list[RealtimeRun]


@dataclass(frozen=True)
class Realtime:
    this: Ladder
    baseline: Ladder


@dataclass(frozen=True)
class Commits:
    this: str | None = None
    baseline: str | None = None


@dataclass(frozen=True)
class Side:
    commits: Commits
    figures: dict[str, SideFigure] = field(default_factory=dict)
    step: Part = field(default_factory=Part)
    scaling: Part = field(default_factory=Part)
    realtime: Realtime | None = None


def load(doc: dict, what: str = "the baseline figures") -> Side:
    """``doc`` as :class:`Side` (a part not measured at all, None or empty, as one with no error)."""
    doc = {k: v for k, v in doc.items() if v or k == "commits"} if isinstance(doc, dict) else doc
    return typed(Side, doc, what)
