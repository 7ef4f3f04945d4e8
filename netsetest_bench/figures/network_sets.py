"""Issue 44's figures, what a node takes from its network (bench/widths.json's ``sets``: netsetest_bench/network_sets.py),
as typed data."""

from __future__ import annotations

from dataclasses import dataclass, field

from netsetest_bench.render import typed

WITH = {"json": "with"}  # the JSON's key of a field named with_ (``with`` is a keyword in Python): load reads it, run.py writes it
Ratios = dict[int, list[float | None]]  # node → published width over the limit: β, r, f, and how many intervals were narrower


@dataclass(frozen=True)
class Judged:
    """A run's verdict: violations, coverage, the misses and how many were attributed to a broken assumption."""

    violations: int
    covered: int
    evaluated: int
    misses: int
    misses_attributed: int


@dataclass(frozen=True)
class AtBoundsRun(Judged):
    seed: int = 0
    ratios: Ratios | None = None  # per node over the central limit
    worst: float = 0.0  # the worst coordinate of the worst node
    narrower: int = 0


@dataclass(frozen=True)
class AtBounds:
    """Faults at their declared bounds on one topology, over the seeds."""

    topology: str
    from_step: int
    target: float
    runs: list[AtBoundsRun]
    case: str = "saim"
    signals: str = "worst"


@dataclass(frozen=True)
class Ring(Judged):
    """A directed 12-node ring: each node's widths over its network limit and over the central one."""

    variant: str = ""
    nodes: int = 0
    steps: int = 0
    seed: int = 0
    from_step: int = 0
    target: float = 0.0
    worst: float = 0.0
    furthest: dict[int, int] | None = None  # node → steps the furthest node's data take to reach it
    network: Ratios | None = None
    central: Ratios | None = None
    central_cpu_s: float | None = None
    network_cpu_s: float | None = None
    relaxed: dict[str, int | None] | None = None  # limit → ends relaxed


@dataclass(frozen=True)
class Declared(Judged):
    """Declared bounds drawn at random, true or false."""

    seed: int = 0
    declared: str = ""  # "true" or "false"
    false_nodes: list[int] | None = None


@dataclass(frozen=True)
class Traffic:
    """Per node-step: messages published, their bytes and the deliveries they make."""

    messages: float
    bytes: float
    deliveries: float


@dataclass(frozen=True)
class Wire:
    state: Traffic
    reading: Traffic


@dataclass(frozen=True)
class Sides:
    """The same topology with the exchange (``with``) and without it."""

    with_: Wire = field(metadata=WITH)
    without: Wire


@dataclass(frozen=True)
class Step:
    """The estimator's step replayed on the same inputs, with the exchange and without [ms CPU]."""

    with_: float = field(metadata=WITH)
    without: float
    with_median: float
    without_median: float
    over_ms: float
    over_median_ms: float
    met: bool
    with_ms: list[float] = field(default_factory=list)  # every round's mean
    without_ms: list[float] = field(default_factory=list)


@dataclass(frozen=True)
class Cost:
    label: str
    case: str
    rounds: int
    wire: Sides
    step: Step
    steps: int = 0


@dataclass(frozen=True)
class Sets:
    at_bounds: list[AtBounds]
    rings: list[Ring]
    declared: list[Declared]
    cost: list[Cost]
    step_target_ms: int | float  # printed as written


def load(doc: dict, what: str = "the network sets' figures") -> Sets:
    """``doc`` as :class:`Sets` (``with``, a keyword in Python, is the field ``with_``)."""
    if isinstance(doc, dict) and isinstance(doc.get("cost"), list):
        doc = doc | {"cost": [{k: _with(v) if k in ("step", "wire") else v for k, v in c.items()} if isinstance(c, dict) else c for c in doc["cost"]]}
    return typed(Sets, doc, what)


def _with(d: object) -> object:
    return {("with_" if k == "with" else k): v for k, v in d.items()} if isinstance(d, dict) else d
