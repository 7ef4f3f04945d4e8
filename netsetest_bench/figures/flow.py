"""The flow part's figures (bench/flow.json: ``netsetest bench --only flow``) as typed data."""

from __future__ import annotations

from dataclasses import dataclass, field

from netsetest_bench.render import typed


@dataclass(frozen=True)
class FlowRun:
    """An unpaced lockstep run as users start it, the collector perhaps stopped mid-run."""

    topology: str
    record: str
    steps: int
    pause_s: float
    exit_code: int | None
    node_steps_lost: int
    nodes_missing: list[int]
    nodes_rejoined: list[int]
    collector_drops: dict[str, int]
    wall_s: float | None
    paused_at_s: float | None = None  # None: the run ended before the pause
    load_before: float | None = None

    def clean(self) -> bool:
        """Exit 0, every node-step judged, no node reported missing or rejoined: what the issue's targets ask."""
        return self.exit_code == 0 and self.node_steps_lost == 0 and not self.nodes_missing and not self.nodes_rejoined


@dataclass(frozen=True)
class Ratio:
    """The lockstep run over Zenoh with the window and without, against in memory, interleaved."""

    steps: int
    reps: int
    load_before: list[float | None]
    inmemory_s: list[float]
    zenoh_window_s: list[float | None]
    zenoh_unbounded_s: list[float | None]
    ratio_window: float | None
    ratio_unbounded: float | None
    window_cost: float | None


@dataclass(frozen=True)
class Flow:
    ack_window: int
    ack_stride: int
    paused: list[FlowRun]
    ratio: Ratio
    records: list[FlowRun] = field(default_factory=list)
    soak: list[FlowRun] = field(default_factory=list)


def load(doc: dict, what: str = "the flow figures") -> Flow:
    return typed(Flow, doc, what)
