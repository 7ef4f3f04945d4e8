"""A drive log's mapping file: which channel of a recorded drive is which signal of the run (docs/your-log.md).

A mapping TOML declares, per signal, where it is in the log (a column of a CSV or Parquet table, a channel
of an MDF4 file, a topic and message field of a ROS 2 bag), its unit, its sign convention and its time
offset, and which sensor it is: each node's yaw-rate reading, the speed, the road-wheel steering angle (or
the steering-wheel angle with its ratio), and optionally a reference for β and r with its declared accuracy.
Validated like a topology (msgspec, strictly): :func:`load_mapping` returns a :class:`LogMapping` (SI units,
one :class:`SignalMap` per signal) or raises ``ConfigError`` naming the file, the field and why on one line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from msgspec import Meta, Struct, field

from netsetest.models.vehicle import KMH
from netsetest.validation import Finite

# unit → factor to SI (rad, rad/s, m/s, s): what a mapping may name, per kind of signal
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
RATE_UNITS = {"rad/s": 1.0, "deg/s": math.pi / 180.0}
SPEED_UNITS = {"m/s": 1.0, "km/h": KMH}
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
FORMATS = ("csv", "parquet", "mdf4", "rosbag")
SUFFIX_FORMATS = {".csv": "csv", ".parquet": "parquet", ".mf4": "mdf4", ".mdf": "mdf4", ".mcap": "rosbag", ".db3": "rosbag"}
OFFSET_MAX_S = 3600.0  # a channel's time offset: an hour is a wrong clock, not a sensor's latency
TOLERANCE_MAX_S = 60.0
REORDER_S = 2.0  # how far out of time order a log may hold a sample by default: a logger's latency, not a sensor's gap
REORDER_MAX_S = 600.0  # the reader holds this much of the log: more is no stream
RATIO_RANGE = (1.0, 40.0)  # steering-wheel to road-wheel: a road car's lies in 10–20
MAX_NAME = 200
MAX_SIGNALS = 256  # yaw-rate sensors of one mapping (messages.MAX_NODES)


class _Strict(Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """A table of the mapping: unknown keys are errors (a typo must not silently map nothing)."""


Name = Annotated[str, Meta(min_length=1, max_length=MAX_NAME)]
Sign = Literal[1, -1]
Offset = Annotated[float, Meta(ge=-OFFSET_MAX_S, le=OFFSET_MAX_S)]
Stretch = tuple[Finite, Finite]


class SignalSpec(_Strict, frozen=True, kw_only=True):
    """Where one signal is: ``channel`` (a column, an MDF4 channel, or a bag's topic) and, in a bag, ``field``
    (the message's field path, e.g. ``angular_velocity.z``); its unit, sign (+1: the vehicle's convention,
    ISO 8855: z up, β and r positive to the left) and time offset (sample time = stamp + offset_s)."""

    channel: Name
    field: Annotated[str, Meta(max_length=MAX_NAME)] = ""
    unit: Name
    sign: Sign = 1
    offset_s: Offset = 0.0


class YawRateSpec(SignalSpec, frozen=True, kw_only=True):
    """Node ``node``'s yaw-rate reading; ``healthy``: the logged sensor has no fault (true: over the whole log;
    a list of [t0, t1] stretches in log seconds: there only; false: nowhere declared).  Where it is declared
    healthy the fault's truth is exactly the injected one, elsewhere the interval the reference leaves."""

    node: Annotated[int, Meta(ge=1)]
    healthy: bool | list[Stretch] = True


class SteeringSpec(SignalSpec, frozen=True, kw_only=True):
    """The front road-wheel angle δ_f, or the steering-wheel angle with ``ratio`` (δ_f = wheel / ratio)."""

    kind: Literal["road-wheel", "steering-wheel"] = "road-wheel"
    ratio: Annotated[float, Meta(ge=RATIO_RANGE[0], le=RATIO_RANGE[1])] | None = None


class AccuracySpec(_Strict, frozen=True, kw_only=True):
    """The reference's declared accuracy: the truth lies within ± these of the logged value, in the channel's unit."""

    beta: Annotated[float, Meta(ge=0, le=1e3)]
    r: Annotated[float, Meta(ge=0, le=1e3)]


class ReferenceSpec(_Strict, frozen=True, kw_only=True):
    """A reference of the state (an INS): β and r, each a signal, and its declared accuracy."""

    beta: SignalSpec
    r: SignalSpec
    accuracy: AccuracySpec


class LogSpec(_Strict, frozen=True, kw_only=True):
    """How the log keeps time: the time column (CSV, Parquet; a bag's and an MDF4's stamps are their own),
    its unit, the log time of step 0 (default: the latest first sample of the inputs and readings), the
    age beyond which a sample is no longer the value at a step (default: 0.5 τs), and how far out of time order
    the file may hold a sample (a bag's header stamps against its arrival order; the reader holds that much)."""

    format: Literal["csv", "parquet", "mdf4", "rosbag"] | None = None
    time: Name = "t"
    time_unit: Literal["s", "ms", "us", "ns"] = "s"
    start_s: Finite | None = None
    gap_tolerance_s: Annotated[float, Meta(gt=0, le=TOLERANCE_MAX_S)] | None = None
    reorder_s: Annotated[float, Meta(ge=0, le=REORDER_MAX_S)] = REORDER_S


class MappingFile(_Strict, frozen=True, kw_only=True):
    log: LogSpec = field(default_factory=LogSpec)
    speed: SignalSpec
    steering: SteeringSpec
    yaw_rate: Annotated[list[YawRateSpec], Meta(min_length=1, max_length=MAX_SIGNALS)]
    reference: ReferenceSpec | None = None

    def __post_init__(self) -> None:
        nodes = [s.node for s in self.yaw_rate]
        if len(set(nodes)) != len(nodes):
            raise ValueError(f"yaw_rate: node {next(n for n in nodes if nodes.count(n) > 1)} mapped twice")
        _unit(self.speed.unit, SPEED_UNITS, "speed")
        _unit(self.steering.unit, ANGLE_UNITS, "steering")
        if (self.steering.kind == "steering-wheel") != (self.steering.ratio is not None):
            raise ValueError("steering: a steering-wheel angle needs its ratio (and a road-wheel angle has none)")
        for k, s in enumerate(self.yaw_rate):
            _unit(s.unit, RATE_UNITS, f"yaw_rate[{k}]")
            if isinstance(s.healthy, list) and any(not a < b for a, b in s.healthy):
                raise ValueError(f"yaw_rate[{k}].healthy: each stretch [t0, t1] needs t0 < t1")
        if self.reference is not None:
            _unit(self.reference.beta.unit, ANGLE_UNITS, "reference.beta")
            _unit(self.reference.r.unit, RATE_UNITS, "reference.r")


def _unit(unit: str, units: dict[str, float], where: str) -> float:
    if unit not in units:
        raise ValueError(f"{where}.unit: {unit!r} is no unit of this signal (one of {', '.join(units)})")
    return units[unit]


# ---------------------------------------------------------------- resolved mapping


@dataclass(frozen=True)
class SignalMap:
    """One signal, resolved: SI value = ``scale`` · raw (the unit's factor times the sign, over a steering ratio)."""

    name: str  # what the signal is in the run: "speed", "steering", "yaw rate of node 3", "reference β", …
    channel: str
    field: str
    scale: float
    offset_ns: int  # added to the channel's stamps


@dataclass(frozen=True)
class SensorMap:
    """A yaw-rate sensor: its signal and where the logged sensor is declared fault-free (log seconds; None: everywhere)."""

    node: int
    signal: SignalMap
    healthy: tuple[tuple[float, float], ...] | None  # None: the whole log; (): nowhere

    def healthy_at(self, t_s: float) -> bool:
        return self.healthy is None or any(a <= t_s <= b for a, b in self.healthy)


@dataclass(frozen=True)
class LogMapping:
    """A validated mapping (SI units): see the module doc."""

    path: str
    format: str | None
    time: str
    time_scale: float  # the time column's unit in seconds
    start_s: float | None
    gap_tolerance_s: float | None
    speed: SignalMap
    steering: SignalMap
    sensors: tuple[SensorMap, ...]
    beta: SignalMap | None = None
    r: SignalMap | None = None
    accuracy: tuple[float, float] = (0.0, 0.0)  # (β [rad], r [rad/s]) half-widths of the reference's box
    reorder_s: float = REORDER_S  # how far out of time order a sample may come in the file

    @property
    def inputs(self) -> list[SignalMap]:
        """The model's inputs: needed at every step."""
        return [self.speed, self.steering]

    @property
    def signals(self) -> list[SignalMap]:
        """Every mapped signal, inputs first, then readings, then the reference."""
        ref = [s for s in (self.beta, self.r) if s is not None]
        return [self.speed, self.steering, *(s.signal for s in self.sensors), *ref]

    def sensor(self, node: int) -> SensorMap | None:
        return next((s for s in self.sensors if s.node == node), None)


@dataclass(frozen=True)
class LogSource:
    """A run's recorded drive: the log, its mapping, and whether the run's steps were given (else the log's own
    length decides them: logs/drive.py ``with_log_steps``)."""

    path: str
    mapping: LogMapping
    steps_given: bool


def _signal(name: str, s: SignalSpec, factor: float) -> SignalMap:
    return SignalMap(name, s.channel, s.field, factor * s.sign, round(s.offset_s * 1e9))


def resolve(path: Path, m: MappingFile) -> LogMapping:
    """The mapping in SI units, every signal with its scale."""
    st = m.steering
    steer_factor = ANGLE_UNITS[st.unit] / (st.ratio if st.ratio is not None else 1.0)
    sensors = tuple(
        SensorMap(
            s.node,
            _signal(f"yaw rate of node {s.node}", s, RATE_UNITS[s.unit]),
            None if s.healthy is True else () if s.healthy is False else tuple((float(a), float(b)) for a, b in s.healthy),
        )
        for s in m.yaw_rate
    )
    ref = m.reference
    return LogMapping(
        path=str(path),
        format=m.log.format,
        time=m.log.time,
        time_scale=TIME_UNITS[m.log.time_unit],
        start_s=m.log.start_s,
        gap_tolerance_s=m.log.gap_tolerance_s,
        speed=_signal("speed", m.speed, SPEED_UNITS[m.speed.unit]),
        steering=_signal("steering", st, steer_factor),
        sensors=sensors,
        beta=None if ref is None else _signal("reference β", ref.beta, ANGLE_UNITS[ref.beta.unit]),
        r=None if ref is None else _signal("reference r", ref.r, RATE_UNITS[ref.r.unit]),
        accuracy=(0.0, 0.0) if ref is None else (ref.accuracy.beta * ANGLE_UNITS[ref.beta.unit], ref.accuracy.r * RATE_UNITS[ref.r.unit]),
        reorder_s=m.log.reorder_s,
    )


def log_format(log: Path, mapping: LogMapping) -> str:
    """The log's format: the mapping's ``[log] format``, else the file's suffix (a directory is a ROS 2 bag)."""
    if mapping.format is not None:
        return mapping.format
    if log.is_dir():
        return "rosbag"
    fmt = SUFFIX_FORMATS.get(log.suffix.lower())
    if fmt is None:
        raise ValueError(f"{log}: cannot tell the log's format from its suffix {log.suffix!r}: say [log] format = one of {', '.join(FORMATS)} in the mapping")
    return fmt


__all__ = ["FORMATS", "LogMapping", "LogSource", "MappingFile", "SensorMap", "SignalMap", "log_format", "resolve"]
