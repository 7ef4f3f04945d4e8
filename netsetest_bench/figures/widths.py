"""The widths part's figures (bench/widths.json: ``netsetest bench --only widths``) as typed data: every comparison's
rows (``netsetest compare``'s, analysis/compare.py), the region's cost, the step side by side with a baseline, and issue
44's tables (figures/network_sets.py)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from netsetest.analysis.compare import CompareRow
from netsetest.config.schema import Case
from netsetest.models.signals import SignalKind
from netsetest_bench.figures.network_sets import Sets
from netsetest_bench.figures.network_sets import load as load_sets
from netsetest_bench.render import typed


@dataclass(frozen=True)
class Row(CompareRow):
    """One estimator's row of a comparison, as ``netsetest compare --json`` writes it (with the truth's plant)."""

    plant: str = "ts"


@dataclass(frozen=True, kw_only=True)
class Run:
    """One comparison of the part: what it ran (netsetest_bench/widths.py's WidthRun), the runs and steps compare made,
    and every estimator's row."""

    label: str
    topology: str = ""
    case: Case | None = None  # None: the file's
    signals: SignalKind = "paper"
    seeds: list[int]
    target: float  # the SDP's, on its worst node
    steps: int
    without_region: bool = False  # every set estimator without its region too
    runs: list[str] = field(default_factory=list)  # case/signals/seed of each run
    rows: list[Row]

    def by_estimator(self) -> dict[str, Row]:
        return {r.estimator: r for r in self.rows}


@dataclass(frozen=True)
class RegionRun:
    """One run of the region's cost: medians over its node-steps [ms], and the region's share of the step time."""

    step_ms: float
    moved_ms: float
    cut_ms: float
    share: float


@dataclass(frozen=True)
class RegionCase(RegionRun):
    """A case's figures: the medians over its runs, and every run."""

    per_run: list[RegionRun] = field(default_factory=list)


@dataclass(frozen=True)
class RegionCost:
    steps: int
    runs: int
    nsnim: RegionCase
    saim: RegionCase

    def case(self, case: Case) -> RegionCase:
        return self.nsnim if case == "nsnim" else self.saim


@dataclass(frozen=True)
class StepFigure:
    """One figure of the step side by side [ms per node-step]: every run of each checkout, the fastest, the median,
    this checkout over the baseline, and whether the fastest runs meet the target."""

    this_ms: list[float]
    baseline_ms: list[float]
    this: float
    baseline: float
    this_median: float
    baseline_median: float
    over_ms: float
    over_median_ms: float
    met: bool


@dataclass(frozen=True)
class Commits:
    this: str | None  # None: not a git checkout
    baseline: str | None


@dataclass(frozen=True)
class SideCase:
    in_run: StepFigure
    replayed: StepFigure

    def figure(self, key: str) -> StepFigure:
        return self.in_run if key == "in_run" else self.replayed


@dataclass(frozen=True)
class SideBySide:
    """The step side by side with a baseline checkout, or why it was not measured (``error``)."""

    error: str | None = None
    steps: int = 0
    processes: int = 0
    runs: int = 0
    target_ms: float = 0.0
    commits: Commits | None = None
    nsnim: SideCase | None = None
    saim: SideCase | None = None

    def case(self, case: Case) -> SideCase:
        out = self.nsnim if case == "nsnim" else self.saim
        if out is None:
            raise ValueError(f"the step side by side has no {case} figures")
        return out


@dataclass(frozen=True)
class Widths:
    from_step: int
    runs: list[Run]
    cost: RegionCost | None = None  # None: figures measured before the nodes kept a region
    sets: Sets | None = None  # None: figures older than issue 44's part
    side_by_side: SideBySide | None = None  # None: measured without --baseline


def load(doc: dict, what: str = "the widths figures") -> Widths:
    """``doc`` (bench/widths.json's ``widths``, or a run's figures) as :class:`Widths`; its issue-44 part through
    figures/network_sets.py's ``load`` (which renames ``with``)."""
    sets = doc.get("sets") if isinstance(doc, dict) else None
    out = typed(Widths, (doc | {"sets": None}) if sets is not None else doc, what)
    return out if sets is None else replace(out, sets=load_sets(sets, what + ": sets"))
