"""What `netsetest exact` prints: a record's published widths against its exact limit, as typed tables.

:func:`exact_table` builds the main table from the exact limit and the record's ratios (analysis/exact.py),
:func:`local_table` the ``--local`` one (each node's own-data limit over the central one), :func:`network_table` the
``--network`` one (each node's network limit against the record and against the central limit).  Each table's
``lines()`` is its text; the CLI only prints it (docs/exact.md shows the output).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from netsetest.analysis.exact import (
    COORDINATES,
    FROM_STEP,
    Coordinate,
    CoordinateRatio,
    ExactBounds,
    ExactComparison,
    LocalLimit,
    health_line,
    limit_ratios,
)
from netsetest.config.schema import Scenario

COLUMN_NAMES = {"f": "fault", "r": "yaw rate", "beta": "sideslip"}
CELL = 22  # characters of a coordinate's column in the main table


@dataclass(frozen=True)
class WidthCell:
    """One coordinate of one row: the published width over the exact one, mean over steps ≥ FROM_STEP and over every
    step, and the relative-RMS radius; where the exact interval is a point (no ratio), the published width minus the
    exact one, absolute (``absolute``)."""

    width: float
    width_all: float
    rms: float = math.nan
    absolute: bool = False

    @classmethod
    def of(cls, x: CoordinateRatio) -> WidthCell:
        if x.width_excess is None or x.width_excess_all is None:
            return cls(x.width_ratio, x.width_ratio_all, x.rms_radius_rel)
        return cls(x.width_excess, x.width_excess_all, absolute=True)

    def text(self) -> str:
        if self.absolute:
            return f"{self.width:+.1e} |{self.width_all:+.1e} abs".rjust(CELL)
        return f"{self.width:6.3f} |{self.width_all:6.3f}  {self.rms:6.3f}"


@dataclass(frozen=True)
class WidthRow:
    label: str  # a node id, or "mean"
    cells: tuple[WidthCell, ...]  # per coordinate, in COORDINATES' order


@dataclass(frozen=True)
class ExactTable:
    """The main table of `netsetest exact`: the heading (the record, its case and steps, the fault bounds applied and on
    which nodes, the seconds taken), notes on what was applied or found, a row per node and the mean row, the overall
    ratios, and how many node-step intervals were left out (the exact one unbounded or empty) and were narrower than the
    exact one (``narrower_why``: the likely reason, "" where none is)."""

    record: str
    case: str
    steps: int
    fault_bounds: str
    bounded: tuple[int, ...]
    seconds: float
    notes: tuple[str, ...]
    rows: tuple[WidthRow, ...]
    overall_width_ratio: float
    overall_rms_radius_rel: float
    left_out: int
    narrower: int
    intervals: int
    narrower_why: str

    def lines(self) -> list[str]:
        bounded = ", ".join(map(str, self.bounded)) or "none"
        out = [
            f"exact bounds for {self.record}: case {self.case}, {self.steps} steps, fault bounds '{self.fault_bounds}' "
            f"(applied on nodes: {bounded}), {self.seconds:.1f} s",
            *(f"  {n}" for n in self.notes),
            f"published width / exact width: mean over steps ≥ {FROM_STEP} | all steps; relative-RMS radius (Althoff & Rath (9), exact = 1)",
            f"{'node':>4}  " + "  ".join(f"{COLUMN_NAMES[c]:>{CELL}}" for c in COORDINATES),
            *(f"{row.label:>4}  " + "  ".join(c.text() for c in row.cells) for row in self.rows),
            f"overall: width ratio {self.overall_width_ratio:.3f}, relative-RMS radius {self.overall_rms_radius_rel:.3f}",
        ]
        if self.left_out:
            out.append(f"  {self.left_out} node-step intervals left out: the exact interval is unbounded there (inf) or empty")
        why = f" ({self.narrower_why})" if self.narrower and self.narrower_why else ""
        out.append(f"published interval narrower than exact on {self.narrower} of {self.intervals} node-step intervals{why}")
        return out


def _notes(exact: ExactBounds) -> tuple[str, ...]:
    """What the heading's notes say: steps without a trajectory, the k-of-N search, the assumptions left out."""
    notes = []
    if exact.infeasible_steps:
        notes.append(f"no trajectory meets the assumptions at steps {list(exact.infeasible_steps)} (an assumption was broken)")
    if exact.no_reading:
        nodes = sorted({i for i, _ in exact.no_reading})
        notes.append(
            f"{len(exact.no_reading)} node-step(s) without a reading (gaps in the log; nodes {', '.join(map(str, nodes))}): "
            "no measurement there, the declared fault bounds still hold"
        )
    if exact.health is not None:
        notes.append(health_line(exact.health))
    if exact.omitted:
        notes.append(
            f"not applied: {', '.join(exact.omitted)} (--no-health): these bounds are an outer bound of the "
            "exact limit, and a node that uses the assumption may be narrower (docs/exact.md)"
        )
    return tuple(notes)


def _narrower_why(exact: ExactBounds) -> str:
    """Why a published interval can be narrower than the exact one: what the limit left out, or relaxed, or else."""
    if exact.omitted:
        return f"the nodes used {', '.join(exact.omitted)}, which these bounds leave out"
    if exact.health is not None and exact.health.relaxed:
        return "some ends are relaxed: an outer bound there"
    return "the estimator relied on more than these assumptions there, or one of the two is wrong"


def _intervals(comparison: ExactComparison) -> int:
    """The node-step intervals compared: every step of every node's track, per coordinate (left out or not)."""
    return sum(x.steps + x.left_out for n in comparison.nodes for x in n.ratios.values())


def exact_table(label: str, case: str, exact: ExactBounds, comparison: ExactComparison, seconds: float) -> ExactTable:
    """The main table of a record (``label``: its path as the user gave it) against ``exact`` (``comparison``: the
    record's ratios against it, :func:`~netsetest.analysis.exact.compare_record`); ``seconds``: the time it took."""
    c = comparison
    rows = [WidthRow(str(n.node), tuple(WidthCell.of(n.ratios[k]) for k in COORDINATES)) for n in c.nodes]
    rows.append(WidthRow("mean", tuple(WidthCell(c.mean_width_ratio[k], c.mean_width_ratio_all[k], c.mean_rms_radius_rel[k]) for k in COORDINATES)))
    return ExactTable(
        record=label,
        case=case,
        steps=len(exact.steps),
        fault_bounds=exact.fault_bounds,
        bounded=exact.bounded_nodes,
        seconds=seconds,
        notes=_notes(exact),
        rows=tuple(rows),
        overall_width_ratio=c.overall_width_ratio,
        overall_rms_radius_rel=c.overall_rms_radius_rel,
        left_out=sum(x.left_out for n in c.nodes for x in n.ratios.values()),
        narrower=sum(x.narrower for n in c.nodes for x in n.ratios.values()),
        intervals=_intervals(c),
        narrower_why=_narrower_why(exact),
    )


@dataclass(frozen=True)
class LocalTable:
    """``exact --local``: per node, its exact limit from its own data over the whole network's (LocalLimit; NaN: the
    central width is a point, a reference sensor's declared zero fault)."""

    limits: tuple[LocalLimit, ...]

    def lines(self) -> list[str]:
        out = [
            "the exchange's value at best: exact limit from the node's own data / from every node's data "
            f"(mean width from step {FROM_STEP}; 1.000: the network cannot help this node)",
            f"{'node':>4}  {'own fault':>10}  {'yaw rate':>10}  {'sideslip':>10}",
        ]
        for lim in self.limits:
            cells = ("  declared 0" if math.isnan(v) else f"{v:10.3f}" for v in (lim.fault_ratio, lim.r_ratio, lim.beta_ratio))
            out.append(f"{lim.node:>4}  " + "  ".join(cells))
        return out


def local_table(limits: Sequence[LocalLimit]) -> LocalTable:
    return LocalTable(tuple(limits))


@dataclass(frozen=True)
class NetworkCell:
    """One coordinate of a node's row: the record's width over its network limit's, and that limit's over the central
    limit's (NaN or inf: no ratio, shown as a dash)."""

    published: float
    over_central: float


@dataclass(frozen=True)
class NetworkRow:
    node: int
    furthest: int  # the most steps a node's data take to it
    cells: tuple[NetworkCell, ...]  # fault, yaw rate, sideslip


NETWORK_COLUMNS: tuple[tuple[Coordinate, str], ...] = (("f", "fault"), ("r", "yaw rate"), ("beta", "sideslip"))


def _ratio_text(v: float, width: int) -> str:
    return f"{'–' if not math.isfinite(v) else format(v, '.3f'):>{width}}"


@dataclass(frozen=True)
class NetworkTable:
    """``exact --network``: per node, how far its furthest datum is and, per coordinate, the record over its network
    limit and that limit over the central one; the k-of-N search's line, and how many node-step intervals were narrower
    than the network limit."""

    health: str | None
    rows: tuple[NetworkRow, ...]
    narrower: int
    intervals: int

    def lines(self) -> list[str]:
        out = ["the network limit (docs/exact.md): node j's data reach node i d(j→i) steps late, one hop a step along the states, a reading's in its step"]
        if self.health is not None:
            out.append(f"  {self.health}")
        out.append(
            f"{'node':>4}  {'furthest':>8}  " + "  ".join(f"{name + ': published / network':>24}  {'network / central':>17}" for _, name in NETWORK_COLUMNS)
        )
        for row in self.rows:
            cells = (f"{_ratio_text(c.published, 24)}  {_ratio_text(c.over_central, 17)}" for c in row.cells)
            out.append(f"{row.node:>4}  {row.furthest:>8}  " + "  ".join(cells))
        out.append(f"published interval narrower than the network limit on {self.narrower} of {self.intervals} node-step intervals")
        return out


def network_table(scenario: Scenario, network: ExactBounds, comparison: ExactComparison, central: ExactBounds) -> NetworkTable:
    """The ``--network`` table of a record (``comparison``: its ratios against ``network``, each node's network limit)."""
    over = {lim.node: lim for lim in limit_ratios(network, central, sorted(network.fault))}
    mine = {n.node: n.ratios for n in comparison.nodes}
    rows = []
    for i in scenario.ids:
        limit = (over[i].fault_ratio, over[i].r_ratio, over[i].beta_ratio)
        published = [mine[i][c].width_ratio if i in mine else math.nan for c, _ in NETWORK_COLUMNS]
        rows.append(NetworkRow(i, max(scenario.delays(i).values()), tuple(NetworkCell(p, q) for p, q in zip(published, limit))))
    return NetworkTable(
        health=None if network.health is None else health_line(network.health),
        rows=tuple(rows),
        narrower=sum(x.narrower for n in comparison.nodes for x in n.ratios.values()),
        intervals=_intervals(comparison),
    )
