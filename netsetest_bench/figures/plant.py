"""The car part's figures (bench/plant.json: ``netsetest bench --only plant``) as typed data."""

from __future__ import annotations

import statistics
from dataclasses import dataclass, field

from netsetest_bench.render import typed

CASES = ("nsnim", "saim")


@dataclass(frozen=True)
class Drive:
    """One judged run of a drive (a seed, a signal family, a case): node-steps and what e_k did."""

    case: str
    steps: int
    evaluated: int
    covered: int
    contained: int
    violations: int
    misses_attributed: int
    ay_peak: float  # [m/s²] the largest |a_y| the tyres carried
    e_max_in_bound_norm: float = 0.0  # the largest e_k over the bound
    e_outside_steps: int = 0
    fault_width: float = 0.0
    fault_ratio_exact: float | None = None


def by_case(rows: list[Drive]) -> list[tuple[str, list[Drive]]]:
    """A drive's runs per case, the cases measured only."""
    return [(case, rs) for case in CASES if (rs := [r for r in rows if r.case == case])]


def mean_ratio(rs: list[Drive]) -> float | None:
    """The mean fault width over the exact limit's, over the runs that have one."""
    ratios = [r.fault_ratio_exact for r in rs if r.fault_ratio_exact is not None]
    return statistics.mean(ratios) if ratios else None


@dataclass(frozen=True)
class HeldOut:
    bound: str  # the topology's declaration, its last line the bound
    declared: dict[str, list[Drive]]  # drive → runs, with the declared bound
    moderate: dict[str, list[Drive]]  # the same with the moderate drives' box


@dataclass(frozen=True)
class Box:
    drives: list[str]
    box: list[float]


@dataclass(frozen=True)
class Training:
    seeds: list[int]
    envelope: Box
    moderate: Box
    declared_covers_envelope: bool
    causes: dict[str, dict[str, list[float]]]  # plant → training drive → (largest |e_β|, |e_r|)
    ay_peak: dict[str, float]


@dataclass(frozen=True)
class EstimatorCost:
    fault_width: float | None
    fault_ratio_exact: float | None
    violations: int
    width_vs_ts_twin: float | None = None


@dataclass(frozen=True)
class Cost:
    car: dict[str, EstimatorCost]
    ts_twin: dict[str, EstimatorCost]


@dataclass(frozen=True)
class VehicleCpu:
    ms_median: float
    ms_p95: float


@dataclass(frozen=True)
class Coverage:
    covered: int
    evaluated: int


@dataclass(frozen=True)
class Halved:
    """The declared bound scaled down on the double lane change."""

    scale: float
    misses: int
    misses_attributed: int
    violations: int
    drives: list[Coverage]


@dataclass(frozen=True)
class EnvelopeDrive:
    case: str
    steps: int
    evaluated: int
    covered: int
    violations: int
    misses: int
    misses_attributed: int
    ay_peak: float
    envelope_left: int
    e_max_ratio: float
    verdict_says: bool | None = None
    kmh: float | None = None  # the speed it was held at


@dataclass(frozen=True)
class EnvelopeCar:
    vehicle: int
    box: list[float]
    drives: dict[str, list[EnvelopeDrive]]


@dataclass(frozen=True)
class Envelopes:
    ay_max: float
    speed_kmh: list[float]
    seeds: list[int]
    held_out_seeds: list[int]
    cars: list[EnvelopeCar]


@dataclass(frozen=True)
class Config:
    plant_seeds: list[int]


@dataclass(frozen=True)
class Plant:
    config: Config
    held_out: HeldOut
    training: Training
    cost: Cost
    vehicle_cpu: dict[str, VehicleCpu]
    halved: dict[str, Halved] = field(default_factory=dict)
    envelopes: Envelopes | None = None


def load(doc: dict, what: str = "the car figures") -> Plant:
    return typed(Plant, doc, what)
