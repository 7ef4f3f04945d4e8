"""The network part's figures (bench/network.json: ``netsetest bench --only network``) as typed data."""

from __future__ import annotations

from dataclasses import dataclass

from netsetest_bench.render import typed


@dataclass(frozen=True)
class NodeFigures:
    """One node of one run: widths over each other and the exact limits (None: no ratio, e.g. a reference's
    declared zero fault, a point), detection delays in steps after the fault's onset (None: never)."""

    fault: float | None = None  # its exact limit from its own data over the central one (own fault)
    r: float | None = None  # the same for the yaw rate
    sdp_network_over_exact: float | None = None
    sdp_r_over_exact: float | None = None
    sdp_beta_over_exact: float | None = None
    sdp_alone_over_network: float | None = None
    delay_network: int | None = None
    delay_alone: int | None = None
    false_detections: int = 0
    false_detections_covered: int = 0

    def ceiling(self) -> float | None:
        """The node alone over the exact central limit: alone / network times network / exact (None: no exact width)."""
        over, gain = self.sdp_network_over_exact, self.sdp_alone_over_network
        return None if over is None or gain is None else gain * over


@dataclass(frozen=True)
class NetworkRun:
    topology: str
    case: str
    signals: str
    seed: int
    nodes: dict[int, NodeFigures]
    exact: bool = True  # False: no exact limit under this health assumption


@dataclass(frozen=True)
class SweepRow:
    """Containment and detection over the sweep's seeds, node-steps summed."""

    topology: str
    declared: str
    case: str
    signals: str
    violations: int
    covered: int
    evaluated: int
    contained: int
    misses_broken: int
    uncovered_health: int
    false_detections: int
    false_detections_covered: int


@dataclass(frozen=True)
class Sweep:
    seeds: list[int]
    rows: list[SweepRow]


@dataclass(frozen=True)
class ReadingsCost:
    """Lockstep ms per step over Zenoh with the same step's readings and without them."""

    readings: float
    no_readings: float


@dataclass(frozen=True)
class ExchangeCost:
    ms_per_step: dict[str, ReadingsCost]
    reps: int
    steps: list[int]


@dataclass(frozen=True)
class Network:
    steps: int
    seeds: list[int]
    runs: list[NetworkRun]
    sweep: Sweep | None = None
    exchange_cost: ExchangeCost | None = None

    def groups(self, signals: str | None = None) -> dict[tuple[str, str, str], list[NetworkRun]]:
        """The runs by (topology, case, signals), in the order measured; ``signals``: that family only."""
        out: dict[tuple[str, str, str], list[NetworkRun]] = {}
        for r in self.runs:
            if signals is None or r.signals == signals:
                out.setdefault((r.topology, r.case, r.signals), []).append(r)
        return out


def load(doc: dict, what: str = "the network figures") -> Network:
    return typed(Network, doc, what)
