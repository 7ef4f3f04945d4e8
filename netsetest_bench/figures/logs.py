"""The logs part's figures (bench/logs.json: ``netsetest bench --only logs``) as typed data."""

from __future__ import annotations

from dataclasses import dataclass

from netsetest_bench.render import typed

BAG = "rosbag-mcap"  # the import row the targets are read from


@dataclass(frozen=True)
class ImportRow:
    """One log format read as the vehicle role reads it, in a process of its own."""

    format: str
    size_mb: float
    import_s: float
    import_cpu_s: float
    stream_s: float
    peak_mb: float
    rss_mb: list[float]  # after the import, …, after the last step
    load: str
    rosbags_cpu_s: float | None = None  # the bag's: rosbags' own reading of its mapped messages, nothing decoded


@dataclass(frozen=True)
class Import:
    minutes: float
    hz: float
    channels: int
    samples: int
    rows: list[ImportRow]

    def bag(self) -> ImportRow:
        return next(r for r in self.rows if r.format == BAG)


@dataclass(frozen=True)
class Replay:
    steps: int
    drive_s: float
    reps: int
    log_wall_s: float
    log_cpu_s: float
    model_wall_s: float
    model_cpu_s: float
    realtime_wall: float
    realtime_cpu: float
    same_verdict: bool
    load: str
    estimator_s: float | None = None  # of log_wall_s: the nodes' estimator steps (None: measured before it was)


@dataclass(frozen=True)
class Transitions:
    """Held-out transitions by where e_k lies against the box: inside, possibly outside, certainly outside."""

    inside: int
    overlap: int
    disjoint: int

    def total(self) -> int:
        return self.inside + self.overlap + self.disjoint


@dataclass(frozen=True)
class HeldOut:
    inside: Transitions  # transitions inside the envelope
    outside: Transitions


@dataclass(frozen=True)
class CalibrationRun:
    """The held-out drive declared with the calibration, one reference accuracy."""

    accuracy: list[float]  # [rad, rad/s] of the reference's β, r (0: exact)
    held_out: HeldOut
    evaluated: int
    contained: int
    missed: int
    undecided: int
    covered: int
    not_covered: dict[str, int]


@dataclass(frozen=True)
class Envelope:
    ay_max: float
    speed_kmh: list[float]


@dataclass(frozen=True)
class Calibration:
    train_seeds: list[int]
    train_s: float
    held_s: float
    held_seed: int
    held_steer: float
    transitions: int
    box: list[float]
    envelope: Envelope
    runs: dict[str, CalibrationRun]  # exact, ins


@dataclass(frozen=True)
class Logs:
    import_: Import
    replay: Replay
    calibration: Calibration
    load: str = "?"


def load(doc: dict, what: str = "the logs figures") -> Logs:
    """``doc`` as :class:`Logs` (its ``import`` is the field ``import_``: a keyword in Python)."""
    if isinstance(doc, dict) and "import" in doc:
        doc = {("import_" if k == "import" else k): v for k, v in doc.items()}
    return typed(Logs, doc, what)
