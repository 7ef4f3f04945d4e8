"""The scenario part's figures (bench/scenario.json: ``netsetest bench --only scenario``) as typed data."""

from __future__ import annotations

from dataclasses import dataclass

from netsetest_bench.render import typed


@dataclass(frozen=True)
class Coordinates:
    f: float
    r: float
    beta: float


@dataclass(frozen=True)
class ScenarioNode:
    """One node of the paper run: its ellipsoid's size, widths, what the exact limit says, the sector, detection."""

    max_E: float
    fault_width: float  # mean from step 10
    fault_width_step0: float
    ratio_exact: Coordinates  # mean published width over the exact limit's
    steps_evaluated: int
    steps_contained: int
    steps_covered: int
    violations: int
    false_detections: int
    sector_breaks: int  # steps on which the paper's fixed sector would be false
    first_sector_break: int | None = None
    detection_delay: int | None = None  # steps from the fault's onset to its guaranteed detection (None: no fault)


@dataclass(frozen=True)
class ScenarioRun:
    case: str
    signals: str
    seed: int
    objective: str
    steps: int
    nodes: dict[int, ScenarioNode]


@dataclass(frozen=True)
class CompareRow:
    """One estimator of ``netsetest compare`` over the runs of a case."""

    estimator: str
    violations: int
    covered: int
    node_steps: int
    fault_width_mean: float | None
    beta_width_mean: float | None
    r_width_mean: float | None
    ratio_exact: float | None
    ratio_exact_state: list[float | None]  # β, r
    rms_radius_rel: float | None
    ms_median: float | None
    ms_p95: float | None


@dataclass(frozen=True)
class Compare:
    case: str
    estimators: list[str]
    runs: list[str]
    steps: int
    rows: list[CompareRow]


@dataclass(frozen=True)
class Scenario:
    runs: list[ScenarioRun]
    compare: list[Compare]
    compare_seeds: list[int]

    def run(self, case: str, signals: str) -> ScenarioRun:
        return next(r for r in self.runs if r.case == case and r.signals == signals)


def load(doc: dict, what: str = "the scenario figures") -> Scenario:
    return typed(Scenario, doc, what)
