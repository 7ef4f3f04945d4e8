"""Configuration files: node profiles (``nodes/*.toml``) and network topologies (``topologies/*.toml``).

Every file is validated with msgspec (``msgspec.convert`` into frozen Structs, strictly: no string or
fractional value is taken for a number — a quoted ``"from" = "1.0"`` once silently rewired an edge; an
integer is still accepted for a float).  :func:`load_topology` returns a :class:`Scenario` (plain numpy data for the roles)
or raises :class:`ConfigError` naming the file, the field and the reason on one line (msgspec stops at
the first error).

Physical ranges.  Every magnitude a node's estimator works with is bounded so that the estimator, its
certificate and its guaranteed fallback ellipsoid (:func:`netsetest.estimator.certificate.fallback_shape`) stay
in floating-point range: a profile outside them is rejected at load (exit 2) rather than crashing a node
mid-run.  The limits (the ``*_MIN``/``*_MAX`` constants below, documented in docs/configuration.md) are generous for
a yaw-rate sensor — gains, offsets and signals in rad, rad/s and the sensor's unit are O(1) — and the
extreme-profile sweep (tests/inmemory/test_estimator_edges.py) runs the network at their corners.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
import stat
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal, TypeVar, cast

import msgspec
import numpy as np
from msgspec import Meta, Struct, field

# CPython's own SHA-256, which hashlib.sha256 is: every role loads its topology (the settings digest), and
# importing hashlib would also load OpenSSL's libcrypto (+3.3 MB resident in every node process)
try:
    from _sha2 import sha256  # CPython ≥ 3.12
except ImportError:
    try:
        from _sha256 import sha256  # CPython ≤ 3.11
    except ImportError:
        from hashlib import sha256  # another interpreter: the same function

from netsetest.estimator.names import NODE_ESTIMATOR_NAMES, SDP
from netsetest.models.sensor import Sensor
from netsetest.models.signals import Fault, NoFault, PiecewiseLinearFault, SpeedProfile, SquareFault
from netsetest.models.manoeuvres import MANOEUVRES, SINE_SPEED, STEERING_MAX_RAD, ManoeuvreName, steering_range
from netsetest.extras import MissingExtra
from netsetest.config.logmap import LogMapping, LogSource, MappingFile, resolve as resolve_mapping
from netsetest.models.plant import PLANTS, VEHICLE_IDS, PlantKind, derived_params
from netsetest.models.envelope import HOLDS_RTOL, OperatingEnvelope
from netsetest.models.uncertainty import ModelUncertainty
from netsetest.models.vehicle import KMH, TSModel, VehicleParams
from netsetest.scenarios import bundled_topologies, resolve_topology
from netsetest.validation import FINITE_BOUND_TEXT, Finite, Positive, split_error

Case = Literal["nsnim", "saim"]
Variant = Literal["scheduled", "per-rule"]
FaultBoundsMode = Literal["used", "all", "none"]  # where declared fault bounds are applied (Scenario.fault_bounded)
FAULT_BOUNDS_MODES: tuple[FaultBoundsMode, ...] = ("used", "all", "none")
_T = TypeVar("_T")


class ConfigError(Exception):
    """A configuration file is missing, unreadable or invalid; the message says where and why."""


class _Strict(Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """A table of a configuration file: unknown keys are errors (a typo must not be silently ignored)."""


MAGNITUDE_MAX = 1e3  # |C|, |Ds|, Dv, |x̂0|, r_max, h2, fault values: a sensor gain or signal of 1000 is not a yaw-rate sensor
DS_MIN = 1e-6  # |Ds|: smaller makes the fault practically unobservable and the descriptor gain G ~ 1/Ds overflow later steps
DV_MIN = 1e-9  # Dv > 0: every real sensor is noisy; Dv = 0 leaves the estimator's noise slot empty
R_MIN, R_MAX = 1e-12, 1e6  # noise bound v² ≤ R
P0_MIN, P0_MAX = 1e-9, 1e6  # eigenvalues of the initial shape P0
RHO_MIN, RHO_MAX = 1e-6, 1e6  # radius of the initial ellipsoid
H1_MIN = 1e-3  # sector 0 < h1 < 1: h1 → 0 makes γ h1 C̄ (hence T, G) degenerate
GAMMA_MIN = 1e-3  # availability γ ∈ [GAMMA_MIN, 1]
W_MIN, W_MAX = 1e-12, 1e6  # side-wind bound w² ≤ W
FREQ_MAX = 1e6  # |noise_frequency|
SPEED_MAX_KMH = 500.0  # mean and amplitude of the speed profile: no road vehicle is faster
MASS_KG = (1.0, 1e5)  # [vehicle] m
YAW_INERTIA_KGM2 = (1.0, 1e6)  # [vehicle] Jz
AXLE_DISTANCE_M = (0.05, 20.0)  # [vehicle] lf, lr (and |lw|)
CORNERING_STIFFNESS_N_PER_RAD = (1.0, 1e7)  # [vehicle] cf, cr
WIND_GAIN_MAX_N = 1e5  # [vehicle] |fw|
STATE_MAX = 10.0  # |β| [rad], |r| [rad/s] of the initial state
SAMPLING_PERIOD_S = (1e-4, 10.0)  # τs: the T-S rules are discretised exactly at it (expm stays in range)
MAX_STEPS = 10**7  # a run's steps (a record line per node-step: 10⁷ steps is days of a real clock)
PERIOD_MIN_S, PERIOD_MAX_S = 1e-3, 1e6  # of the speed profile: shorter than a millisecond is no speed profile
MAX_NAME = 200  # characters of a label or a profile name
PROFILE_NAME_PATTERN = r"^[^/\\\x00]+$"  # a file name in the node directory: no path separators, no NUL

Magnitude = Annotated[float, Meta(ge=-MAGNITUDE_MAX, le=MAGNITUDE_MAX)]


# ---------------------------------------------------------------- node profile (nodes/*.toml)


class SaturationSpec(_Strict, frozen=True, kw_only=True):
    """σ(r) = sign(r) min(r_max, |r|) with sector scalars 0 < h1 < 1 ≤ h2 (used in the SAIM case)."""

    r_max: Annotated[float, Meta(gt=0, le=MAGNITUDE_MAX)]
    h1: Annotated[float, Meta(ge=H1_MIN, lt=1)]
    h2: Annotated[float, Meta(ge=1, le=MAGNITUDE_MAX)]


class AvailabilitySpec(_Strict, frozen=True, kw_only=True):
    """γ_i,k uniform in [gamma_min, gamma_max] ⊂ (0, 1] (used in the SAIM case)."""

    gamma_min: Annotated[float, Meta(ge=GAMMA_MIN, le=1)]
    gamma_max: Annotated[float, Meta(ge=GAMMA_MIN, le=1)]

    def __post_init__(self) -> None:
        if self.gamma_min > self.gamma_max:
            raise ValueError("gamma_min must not exceed gamma_max")


FAULT_FIELDS_OF: dict[str, tuple[str, ...]] = {"none": (), "square": ("amplitude", "period", "start", "end"), "piecewise": ("points",)}
FAULT_FIELDS = ("amplitude", "period", "start", "end", "points")


class FaultSpec(_Strict, frozen=True, kw_only=True):
    """``none``; ``square``: amplitude·sign(sin(2πk/period)) on [start, end); ``piecewise``: through points."""

    kind: Literal["none", "square", "piecewise"] = "none"
    amplitude: Magnitude | None = None
    period: Annotated[int, Meta(gt=0)] | None = None
    start: Annotated[int, Meta(ge=0)] | None = None
    end: Annotated[int, Meta(ge=0)] | None = None
    points: list[tuple[Finite, Magnitude]] | None = None

    def __post_init__(self) -> None:
        foreign = [n for n in FAULT_FIELDS if n not in FAULT_FIELDS_OF[self.kind] and getattr(self, n) is not None]
        if foreign:  # once silently ignored: a user's points under kind = "square" never reached the truth
            uses = ", ".join(f"{k}: {', '.join(f) or 'none'}" for k, f in FAULT_FIELDS_OF.items())
            raise ValueError(f"{', '.join(foreign)}: not a field of a {self.kind!r} fault (fields per kind: {uses})")
        if self.kind == "square":
            missing = [n for n in ("amplitude", "period", "start", "end") if getattr(self, n) is None]
            if missing:
                raise ValueError(f"square fault needs {', '.join(missing)}")
            if self.end <= self.start:  # type: ignore[operator]  # both set: checked just above for kind = square
                raise ValueError("end must be after start")
        if self.kind == "piecewise":
            if not self.points or len(self.points) < 2:
                raise ValueError("piecewise fault needs at least two points [k, value]")
            ks = [p[0] for p in self.points]
            if any(b <= a for a, b in zip(ks, ks[1:])):
                raise ValueError("piecewise fault points must have increasing k")

    def build(self) -> Fault:
        if self.kind == "square":
            return SquareFault(self.amplitude, self.period, self.start, self.end)  # type: ignore[arg-type]  # every field set: __post_init__ checked them for kind = square
        if self.kind == "piecewise":
            return PiecewiseLinearFault(tuple((float(a), float(b)) for a, b in self.points))  # type: ignore[union-attr]  # points set: __post_init__ checked them for kind = piecewise
        return NoFault()


FaultBoundValue = Annotated[float, Meta(gt=0, le=MAGNITUDE_MAX)]


class FaultBoundSpec(_Strict, frozen=True, kw_only=True):
    """Declared physical bounds on the sensor fault: |f_k+1 − f_k| ≤ rate and/or |f_k| ≤ size.

    An assumption like the noise bound: the estimator may rely on it (the adaptive sector of the SAIM
    case, docs/estimator.md), and the collector checks it against the truth and attributes misses to it.
    """

    # at most MAGNITUDE_MAX like the fault values themselves: 1e300 overflowed the SAIM node's fallback set
    rate: Annotated[FaultBoundValue | None, Meta(description="δ_i: largest fault change per step")] = None
    size: Annotated[
        Annotated[float, Meta(ge=0, le=MAGNITUDE_MAX)] | None,
        Meta(description="F_i: largest fault magnitude; 0 declares a reference sensor (fault-free, docs/network.md)"),
    ] = None


def _p0_problem(v: list[list[float]]) -> str | None:
    """Why a matrix P0 is not a 3×3 SPD matrix with eigenvalues in [P0_MIN, P0_MAX] (None if it is)."""
    if len(v) != 3 or any(len(row) != 3 for row in v):
        return f"must be 3×3, got {len(v)} rows of lengths {[len(row) for row in v]}"
    a = np.asarray(v, dtype=float)
    if not np.allclose(a, a.T) or np.linalg.eigvalsh(a).min() <= 0:
        return "must be symmetric positive definite"
    eig = np.linalg.eigvalsh(0.5 * (a + a.T))
    if eig.min() < P0_MIN or eig.max() > P0_MAX:
        return f"eigenvalues must lie in [{P0_MIN:g}, {P0_MAX:g}], got [{eig.min():.3g}, {eig.max():.3g}]"
    return None


class NodeProfile(_Strict, frozen=True, kw_only=True):
    """One yaw-rate sensor: y = C x + Ds f + Dv v, v² ≤ R, plus its estimator's initial ellipsoid."""

    label: Annotated[str, Meta(max_length=MAX_NAME)] = ""
    C: tuple[Magnitude, Magnitude]
    Ds: Magnitude
    Dv: Annotated[float, Meta(ge=DV_MIN, le=MAGNITUDE_MAX)]
    R: Annotated[float, Meta(ge=R_MIN, le=R_MAX)]
    noise_frequency: Annotated[float, Meta(ge=-FREQ_MAX, le=FREQ_MAX, description="f_i of v_i,k = cos(2π f_i (k−1) τs)")]
    x0_hat: tuple[Magnitude, Magnitude, Magnitude]
    P0: Annotated[Annotated[float, Meta(ge=P0_MIN, le=P0_MAX)] | list[list[Finite]], Meta(description="scalar (× I3) or a 3×3 SPD matrix")]
    rho: Annotated[float, Meta(ge=RHO_MIN, le=RHO_MAX)] = 1.0
    saturation: SaturationSpec | None = None
    availability: AvailabilitySpec | None = None
    fault: FaultSpec = field(default_factory=FaultSpec)
    fault_bound: FaultBoundSpec = field(default_factory=FaultBoundSpec)

    def __post_init__(self) -> None:
        if abs(self.Ds) < DS_MIN:
            raise ValueError(f"Ds: |Ds| must be at least {DS_MIN:g}, else the fault is (practically) unobservable")
        if isinstance(self.P0, list):
            problem = _p0_problem(self.P0)
            if problem:
                raise ValueError(f"P0: {problem}")

    def P0_matrix(self) -> np.ndarray:
        return np.eye(3) * self.P0 if isinstance(self.P0, (int, float)) else np.asarray(self.P0, dtype=float)


# ---------------------------------------------------------------- topology (topologies/*.toml)


def _between(lo: float, hi: float) -> object:
    return Annotated[float, Meta(ge=lo, le=hi)]


class CarSpec(_Strict, frozen=True, kw_only=True):
    """The topology's ``[vehicle]`` section, the car: the plant that generates the truth, its manoeuvre, and the T-S
    model's parameters (the vehicle *role*'s command line is runtime/rolespec.py's ``VehicleSpec``).

    ``plant = "ts"`` (default): the truth is the T-S model of m..cr (the paper's Table I by default).
    A nonlinear plant (``single-track``, ``single-track-linear``, ``multi-body``; the ``plant`` extra) is CommonRoad vehicle
    ``vehicle`` and the T-S model is derived from that car (models/plant.py): m..cr may not be given then.
    """

    plant: Annotated[str, Meta(description=f"the truth's vehicle: one of {', '.join(PLANTS)}")] = "ts"
    vehicle: Annotated[int, Meta(ge=min(VEHICLE_IDS), le=max(VEHICLE_IDS), description="CommonRoad parameters_vehicle<N> (a nonlinear plant only)")] | None = (
        None
    )
    manoeuvre: Annotated[str, Meta(description=f"one of {', '.join(MANOEUVRES)}")] = "paper"
    # physical ranges of a road vehicle (generous): a fuzzed wind gain of 1e300 overflowed a node's
    # guaranteed fallback set mid-run; the model must stay in floating-point range like the profiles
    m: _between(*MASS_KG) | None = None  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    Jz: _between(*YAW_INERTIA_KGM2) | None = None  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    lf: _between(*AXLE_DISTANCE_M) | None = None  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    lr: _between(*AXLE_DISTANCE_M) | None = None  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    cf: _between(*CORNERING_STIFFNESS_N_PER_RAD) | None = None  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    cr: _between(*CORNERING_STIFFNESS_N_PER_RAD) | None = None  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    fw: _between(-WIND_GAIN_MAX_N, WIND_GAIN_MAX_N) = 1360.0  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    lw: _between(-AXLE_DISTANCE_M[1], AXLE_DISTANCE_M[1]) = 0.5  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    vx_min_kmh: Annotated[float, Meta(gt=0, le=SPEED_MAX_KMH)] = 80.0
    vx_max_kmh: Annotated[float, Meta(gt=0, le=SPEED_MAX_KMH)] = 120.0
    x0: tuple[_between(-STATE_MAX, STATE_MAX), _between(-STATE_MAX, STATE_MAX)] = (0.0, 0.0)  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    source: Annotated[
        Literal["model", "log"], Meta(description="model: the plant drives the manoeuvre; log: a recorded drive is the world (docs/your-log.md)")
    ] = "model"
    log: Annotated[str, Meta(min_length=1, max_length=4096, description='the drive log (source = "log"), relative to this file')] | None = None
    mapping: Annotated[str, Meta(min_length=1, max_length=4096, description="the log's mapping file, relative to this file")] | None = None

    def __post_init__(self) -> None:
        if (self.log is not None or self.mapping is not None) and self.source != "log":
            raise ValueError('log, mapping: they name a recorded drive, which source = "log" uses; add it or remove them')
        if self.vx_min_kmh >= self.vx_max_kmh:
            raise ValueError("vx_min_kmh must be below vx_max_kmh")
        if self.plant not in PLANTS:
            raise ValueError(f"plant: unknown plant {self.plant!r} (one of {', '.join(PLANTS)})")
        if self.manoeuvre not in MANOEUVRES:
            raise ValueError(f"manoeuvre: unknown manoeuvre {self.manoeuvre!r} (one of {', '.join(MANOEUVRES)})")
        if self.plant == "ts" and self.vehicle is not None:  # it was silently ignored
            raise ValueError(
                f'vehicle = {self.vehicle}: a CommonRoad car drives only a nonlinear plant; plant = "ts" (the default) is the '
                "T-S model of m..cr: choose a plant (single-track, …; docs/plant.md) or remove vehicle"
            )
        given = [n for n in TABLE_I if getattr(self, n) is not None]
        if self.plant != "ts" and given:
            raise ValueError(f"{', '.join(given)}: the T-S model of a {self.plant} plant is derived from CommonRoad vehicle {self.car}; remove these keys")

    @property
    def car(self) -> int:
        """The CommonRoad vehicle of a nonlinear plant (:data:`DEFAULT_VEHICLE` unless given)."""
        return DEFAULT_VEHICLE if self.vehicle is None else self.vehicle

    def params(self) -> VehicleParams:
        """The T-S model's parameters: derived from the plant's car, else the keys given over Table I."""
        lo, hi = self.vx_min_kmh * KMH, self.vx_max_kmh * KMH
        if self.plant != "ts":
            return derived_params(self.car, self.fw, self.lw, lo, hi)
        table = VehicleParams()
        given = {n: getattr(self, n) for n in TABLE_I if getattr(self, n) is not None}
        return dataclasses.replace(table, **given, fw=self.fw, lw=self.lw, vx_min=lo, vx_max=hi)


DEFAULT_VEHICLE = 2  # CommonRoad's BMW 320i: the car of a nonlinear plant that names none
TABLE_I = ("m", "Jz", "lf", "lr", "cf", "cr")  # the bicycle model's parameters (VehicleParams defaults: the paper's)
UNCERTAINTY_MAX = 10.0  # |e_k| components [rad, rad/s] per step: beyond it the model says nothing


ReadingScope = Literal["network", "neighbours"]
NETWORK_DEFAULTS = {"reading_scope": "network", "neighbour_sets": True, "bounded_readings": True}  # (issue 44) left out of the settings digest at these values


class HealthGroupSpec(_Strict, frozen=True, kw_only=True):
    """``[[network.health_groups]]``: at most ``max_faulty`` of these sensors faulty at any step."""

    nodes: Annotated[list[int], Meta(min_length=2, description="the group's node ids (each node in at most one group)")]
    max_faulty: Annotated[int, Meta(ge=0, description="at most this many of the group's sensors have a fault above fault_tolerance at any step")]


class NetworkSpec(_Strict, frozen=True, kw_only=True):
    """Network-wide declarations."""

    fault_tolerance: Annotated[float, Meta(ge=0, le=MAGNITUDE_MAX, description="a fault with |f| ≤ this counts as no fault (detection, docs/fdi.md)")] = 0.0
    readings: Annotated[
        bool,
        Meta(
            description="the same-step exchange: reference sensors publish their reading before estimating and the "
            "SDP nodes use it (docs/network.md); false: every node uses its neighbours' states only"
        ),
    ] = True
    max_faulty: (
        Annotated[
            int,
            Meta(
                ge=0,
                description="at most this many sensors have a fault above fault_tolerance at any step: every "
                "node publishes its reading and uses everyone's (docs/network.md); default: no such bound",
            ),
        ]
        | None
    ) = None
    health_groups: Annotated[
        list[HealthGroupSpec],
        Meta(
            description="the same per group of sensors ([[network.health_groups]] nodes = [...], max_faulty = m): a "
            "node exchanges readings within its group only (docs/network.md); instead of max_faulty"
        ),
    ] = field(default_factory=list)
    reading_scope: Annotated[
        ReadingScope,
        Meta(
            description="who receives a node's reading (a reference's, a k-of-N group member's, one with a declared "
            "fault bound): every node (of its group; network), or only the sender's out-neighbours (neighbours) (docs/network.md)"
        ),
    ] = "network"
    neighbour_sets: Annotated[
        bool,
        Meta(description="every node cuts its region by its in-neighbours' published sets of the step before (docs/network.md)"),
    ] = True
    bounded_readings: Annotated[
        bool,
        Meta(
            description="a node whose sensor declares a fault bound publishes its reading of every step, and the nodes "
            "it reaches (reading_scope) cut their region by it with that bound (docs/network.md)"
        ),
    ] = True


class ModelUncertaintySpec(_Strict, frozen=True, kw_only=True):
    """Declared bound on the model mismatch e_k of x_{k+1} = Ā x_k + B̄ u_k + D̄ w_k + e_k (one of the two)."""

    box: tuple[_between(0, UNCERTAINTY_MAX), _between(0, UNCERTAINTY_MAX)] | None = None  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    ellipsoid: list[list[Finite]] | None = None

    def __post_init__(self) -> None:
        if (self.box is None) == (self.ellipsoid is None):
            raise ValueError("give exactly one of box = [b_beta, b_r] and ellipsoid = [[E11, E12], [E21, E22]]")
        if self.box is not None and min(self.box) <= 0:
            raise ValueError("box: half-widths must be positive")
        if self.ellipsoid is not None:
            e = self.ellipsoid
            if len(e) != 2 or any(len(row) != 2 for row in e):
                raise ValueError("ellipsoid: must be 2×2")
            a = np.asarray(e, dtype=float)
            if not np.allclose(a, a.T) or np.linalg.eigvalsh(0.5 * (a + a.T)).min() <= 0:
                raise ValueError("ellipsoid: must be symmetric positive definite")
            if np.sqrt(np.diag(a)).max() > UNCERTAINTY_MAX:
                raise ValueError(f"ellipsoid: semi-axes must be at most {UNCERTAINTY_MAX:g}")

    def build(self) -> ModelUncertainty:
        if self.box is not None:
            return ModelUncertainty.box(self.box)
        return ModelUncertainty.ellipsoid(np.asarray(self.ellipsoid, dtype=float))


AY_LIMIT = 30.0  # [m/s²] an envelope's lateral acceleration: 3 g, beyond any road car's grip


class EnvelopeSpec(_Strict, frozen=True, kw_only=True):
    """The operating envelope the [model_uncertainty] bound was calibrated for (models/envelope.py)."""

    ay_max: Annotated[float, Meta(gt=0, le=AY_LIMIT, description="largest |lateral acceleration| [m/s²]")]
    speed_kmh: tuple[Annotated[float, Meta(ge=0, le=SPEED_MAX_KMH)], Annotated[float, Meta(ge=0, le=SPEED_MAX_KMH)]]

    def __post_init__(self) -> None:
        if self.speed_kmh[0] > self.speed_kmh[1]:
            raise ValueError(f"speed_kmh: [lo, hi] with lo ≤ hi, got {list(self.speed_kmh)}")

    def build(self) -> OperatingEnvelope:
        return OperatingEnvelope(float(self.ay_max), (float(self.speed_kmh[0]), float(self.speed_kmh[1])))


def check_envelope_speeds(envelope: OperatingEnvelope, vx_min_kmh: float, vx_max_kmh: float) -> None:
    """ValueError (one line) where an operating envelope's speeds leave the model's range [vx_min_kmh, vx_max_kmh]:
    no drive of the run, and none of ``calibrate``'s, leaves that range (the vehicle schedules the model on it),
    so a bound cannot be calibrated, nor declared, for speeds outside it.  The one rule for the topology's
    ``[envelope]`` and ``calibrate --envelope --speed`` (HOLDS_RTOL: a range given in m/s and read back in km/h)."""
    lo, hi = envelope.speed_kmh
    tol = 1 + HOLDS_RTOL
    if lo * tol < vx_min_kmh or hi > vx_max_kmh * tol:
        raise ValueError(
            f"the envelope's speeds {lo:g}–{hi:g} km/h leave the model's range {vx_min_kmh:g}–{vx_max_kmh:g} km/h "
            "([vehicle] vx_min_kmh, vx_max_kmh), on which every drive stays: narrow the envelope ([envelope] speed_kmh, "
            "calibrate --speed) or widen that range"
        )


class SpeedSpec(_Strict, frozen=True, kw_only=True):
    mean_kmh: Annotated[float, Meta(gt=0, le=SPEED_MAX_KMH)] = 100.0
    amplitude_kmh: Annotated[float, Meta(ge=0, le=SPEED_MAX_KMH)] = 18.0
    period_s: Annotated[float, Meta(ge=PERIOD_MIN_S, le=PERIOD_MAX_S)] = 8.0


class SteeringSpec(_Strict, frozen=True, kw_only=True):
    low: _between(-STEERING_MAX_RAD, STEERING_MAX_RAD) = 0.0175  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    high: _between(-STEERING_MAX_RAD, STEERING_MAX_RAD) = 0.0542  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy

    def __post_init__(self) -> None:
        if self.low > self.high:
            raise ValueError("steering low must not exceed high")


class NodeRef(_Strict, frozen=True, kw_only=True):
    id: Annotated[int, Meta(ge=1)]
    profile: Annotated[
        str,
        Meta(
            min_length=1,
            max_length=MAX_NAME,
            pattern=PROFILE_NAME_PATTERN,
            description="file name in the node directory, without .toml (no path separators, no NUL)",
        ),
    ]
    estimator: Annotated[str, Meta(description=f"the node's estimator: one of {', '.join(NODE_ESTIMATOR_NAMES)}")] = SDP

    def __post_init__(self) -> None:
        if self.estimator not in NODE_ESTIMATOR_NAMES:
            raise ValueError(f"estimator: unknown estimator {self.estimator!r} (one of {', '.join(NODE_ESTIMATOR_NAMES)})")


class Edge(_Strict, frozen=True, kw_only=True):
    """a_ij > 0: node ``to`` (i) uses the innovation of node ``from`` (j); i = j is a self-loop."""

    to: Annotated[int, Meta(ge=1)]
    from_: Annotated[int, Meta(ge=1)] = field(name="from")
    weight: Positive = 1.0


class Burst(_Strict, frozen=True, kw_only=True):
    to: Annotated[int, Meta(ge=1)]
    from_: Annotated[int, Meta(ge=1)] = field(name="from")
    start: Annotated[int, Meta(ge=0)]
    length: Annotated[int, Meta(ge=1)]


class LinkLoss(_Strict, frozen=True, kw_only=True):
    """Scheduled loss of node messages: i.i.d. per link and step, plus bursts on chosen links."""

    probability: Annotated[float, Meta(ge=0, le=1)] = 0.0
    bursts: list[Burst] = []


class TopologyFile(_Strict, frozen=True, kw_only=True):
    name: str
    node_dir: str = "../nodes"
    steps: Annotated[int, Meta(ge=1, le=MAX_STEPS)] = 80
    tau_s: _between(*SAMPLING_PERIOD_S) = 0.1  # type: ignore[valid-type]  # an Annotated type built by _between: valid at run time, opaque to mypy
    case: Case = "nsnim"
    W: Annotated[float, Meta(ge=W_MIN, le=W_MAX, description="side-wind bound w² ≤ W")] = 2.0
    vehicle: CarSpec = field(default_factory=CarSpec)
    speed: SpeedSpec = field(default_factory=SpeedSpec)
    steering: SteeringSpec = field(default_factory=SteeringSpec)
    nodes: list[NodeRef]
    edges: list[Edge]
    loss: LinkLoss = field(default_factory=LinkLoss)
    model_uncertainty: ModelUncertaintySpec | None = None
    envelope: EnvelopeSpec | None = None
    network: NetworkSpec = field(default_factory=NetworkSpec)

    def __post_init__(self) -> None:
        self._check_envelope()
        self._check_graph()
        self._check_speed()
        self._check_model_uncertainty()
        self._check_network()

    def _check_envelope(self) -> None:
        """An envelope only with a nonlinear plant and its declared bound, within the model's speeds."""
        if self.envelope is not None and (self.model_uncertainty is None or self.vehicle.plant == "ts"):
            raise ValueError("envelope: it says where a plant's [model_uncertainty] bound holds; declare a nonlinear plant and that bound with it")
        if self.envelope is not None:
            try:
                check_envelope_speeds(self.envelope.build(), self.vehicle.vx_min_kmh, self.vehicle.vx_max_kmh)
            except ValueError as exc:
                raise ValueError(f"envelope: {exc}") from None

    def _check_model_uncertainty(self) -> None:
        """No declared model mismatch on a T-S plant (it is its own model)."""
        if self.vehicle.plant == "ts" and self.model_uncertainty is not None:
            raise ValueError(
                'model_uncertainty: a T-S plant (plant = "ts") is its own model, so e_k = 0 and a declared bound only widens '
                "every set; remove [model_uncertainty], or choose a nonlinear plant (docs/plant.md)"
            )

    def _check_graph(self) -> None:
        """Nodes with distinct ids; edges between them, each once; loss bursts on edges."""
        ids = [n.id for n in self.nodes]
        if not ids:
            raise ValueError("nodes: at least one node is needed")
        if len(set(ids)) != len(ids):
            raise ValueError(f"nodes: duplicate node id in {ids}")
        seen = set()
        for e in self.edges:
            for end in (e.to, e.from_):
                if end not in ids:
                    raise ValueError(f"edges: edge {e.from_}→{e.to} names unknown node {end}")
            if (e.to, e.from_) in seen:
                raise ValueError(f"edges: edge {e.from_}→{e.to} given twice")
            seen.add((e.to, e.from_))
        for b in self.loss.bursts:
            if (b.to, b.from_) not in seen or b.to == b.from_:
                raise ValueError(f"loss.bursts: {b.from_}→{b.to} is not an edge between two nodes")

    def _check_speed(self) -> None:
        """The speed reference within the model's speed range."""
        lo, hi = self.speed.mean_kmh - self.speed.amplitude_kmh, self.speed.mean_kmh + self.speed.amplitude_kmh
        if self.vehicle.manoeuvre not in SINE_SPEED:  # held at the mean speed
            lo = hi = self.speed.mean_kmh
        if lo < self.vehicle.vx_min_kmh or hi > self.vehicle.vx_max_kmh:
            raise ValueError(
                f"speed: manoeuvre {self.vehicle.manoeuvre!r}: its speed reference spans [{lo}, {hi}] km/h, "
                f"outside the model's [{self.vehicle.vx_min_kmh}, {self.vehicle.vx_max_kmh}] km/h"
            )

    def _check_network(self) -> None:
        """No k-of-N declaration and no reading scope where the readings' exchange is off."""
        if not self.network.readings and (self.network.max_faulty is not None or self.network.health_groups):
            what = "max_faulty" if self.network.max_faulty is not None else "health_groups"
            raise ValueError(f"network.{what}: the k-of-N declaration rests on the readings' exchange, which readings = false turns off; remove one of the two")
        if not self.network.readings and self.network.reading_scope != "network":
            raise ValueError(
                f"network.reading_scope: {self.network.reading_scope!r} says who receives the readings, which readings = false turns off; remove one of the two"
            )


# ---------------------------------------------------------------- resolved scenario


@dataclass(frozen=True)
class HealthGroup:
    """A k-of-N declaration: at most ``max_faulty`` of the sensors of ``nodes`` faulty at any step."""

    nodes: tuple[int, ...]
    max_faulty: int

    @property
    def need(self) -> int:
        """Sensors of the group healthy at every step."""
        return len(self.nodes) - self.max_faulty

    def holds(self, faults: dict[int, float], tolerance: float) -> bool:
        """Whether at most ``max_faulty`` of the group's faults at one step exceed ``tolerance``."""
        return sum(abs(faults[j]) > tolerance * (1 + 1e-12) for j in self.nodes if j in faults) <= self.max_faulty


@dataclass(frozen=True)
class NodeConfig:
    """Everything about node i that any process needs: sensor, signals, initial ellipsoid, neighbours."""

    id: int
    label: str
    sensor: Sensor
    noise_frequency: float
    gamma_range: tuple[float, float] | None
    fault: Fault
    x0_hat: np.ndarray
    P0: np.ndarray
    rho: float
    in_weights: dict[int, float]  # j → a_ij for j ∈ N_i (i itself when a_ii > 0)
    fault_rate: float | None = None  # declared δ_i: |f_k+1 − f_k| ≤ δ_i (None: not declared)
    fault_size: float | None = None  # declared F_i: |f_k| ≤ F_i (None: not declared; 0: a reference sensor)
    estimator: str = SDP  # estimator/names.py: NODE_ESTIMATOR_NAMES

    def gap_problem(self) -> str | None:
        """Why a set estimator of this node cannot bound its fault at a step > 0 without its reading (None: it can):
        nothing but a declared fault bound (|f⁺ − f| ≤ δ, |f| ≤ F) carries the fault through a step without a
        measurement (estimator/base.py StepInput; the SDP publishes nothing there instead)."""
        if self.fault_rate is None and self.fault_size is None:
            return f"node {self.id}: without a reading nothing bounds its fault; declare a [fault_bound] rate or size in its profile"
        return None


@dataclass(frozen=True)
class Scenario:
    path: str
    name: str
    case: Case
    steps: int
    tau_s: float
    W: float
    model: TSModel
    x0: np.ndarray
    speed: SpeedProfile
    steer_low: float
    steer_high: float
    nodes: list[NodeConfig]
    loss: LinkLoss = dataclasses.field(default_factory=LinkLoss)
    plant: PlantKind = "ts"
    vehicle_id: int = DEFAULT_VEHICLE  # CommonRoad parameters_vehicle<N> (a nonlinear plant only)
    manoeuvre: ManoeuvreName = "paper"
    uncertainty: ModelUncertainty | None = None  # declared bound on e_k (None: e_k = 0 is assumed)
    envelope: OperatingEnvelope | None = None  # where that bound was calibrated to hold (None: not declared)
    fault_tolerance: float = 0.0  # |f| ≤ this counts as no fault (fault detection, docs/fdi.md)
    readings: bool = True  # the same-step exchange of the references' readings (docs/network.md)
    health_groups: tuple[HealthGroup, ...] = ()  # declared: at most m of each group's sensors faulty (|f| > fault_tolerance) at any step
    settings_digest: str | None = None  # the files' values (load_topology's _settings_digest); None: built otherwise
    reading_scope: ReadingScope = "network"  # a reference's and a group member's reading go to every node (of the group), or to its out-neighbours only
    neighbour_sets: bool = True  # every node cuts its region by its in-neighbours' published sets (docs/network.md)
    bounded_readings: bool = True  # the readings of sensors with a declared fault bound used with that bound (docs/network.md)
    log: LogSource | None = None  # a recorded drive is the world ([vehicle] source = "log"; docs/your-log.md)

    def node(self, node_id: int) -> NodeConfig:
        n = self._by_id.get(node_id)
        if n is None:
            raise ConfigError(f"{self.path}: no node with id {node_id} (ids: {self.ids})")
        return n

    @functools.cached_property
    def _by_id(self) -> dict[int, NodeConfig]:  # roles look nodes up per message: a hundred nodes, every step
        return {n.id: n for n in self.nodes}

    @property
    def ids(self) -> list[int]:
        return list(self._by_id)

    def vx(self, k: int) -> float:
        """The speed reference at step k [m/s] (the T-S plant's Vx_k itself)."""
        return self.speed.kmh(k * self.tau_s) * KMH

    def speed_plausible(self, k: int, vx: float) -> bool:
        """Whether Vx_k can be the truth's: the reference itself (T-S plant) or inside the model's range (a plant, a log)."""
        if self.plant == "ts" and self.log is None:
            return vx == self.vx(k)
        return self.model.params.vx_min <= vx <= self.model.params.vx_max

    @property
    def plant_label(self) -> str:
        """The truth's vehicle in a few characters: ``ts``, e.g. ``single-track/2`` (CommonRoad vehicle 2), or ``log``."""
        if self.log is not None:
            return "log"
        return self.plant if self.plant == "ts" else f"{self.plant}/{self.vehicle_id}"

    @property
    def mismatch_generators(self) -> np.ndarray:
        """(NX, q) generators of the declared model mismatch, e ∈ G·[−1, 1]^q (an ellipsoid's G spans a box
        around it: sound for the linear set estimators; the SDP and ``exact`` use the ellipsoid itself)."""
        return self.uncertainty.G if self.uncertainty is not None else np.zeros((2, 0))

    def steering_range(self) -> tuple[float, float]:
        """Every steering angle the manoeuvre can command (a log's: a road car's whole range)."""
        if self.log is not None:
            return -STEERING_MAX_RAD, STEERING_MAX_RAD
        return steering_range(self.manoeuvre, self.steer_low, self.steer_high)

    def fault_bounded(self, mode: FaultBoundsMode) -> tuple[int, ...]:
        """Nodes whose declared fault bounds an analysis applies: ``used`` — where an estimator relies
        on them (a saturating sensor) and every reference sensor (``size = 0``: a health declaration);
        ``all`` — every node that declares one; ``none`` — no node."""
        if mode not in FAULT_BOUNDS_MODES:
            raise ConfigError(f"fault bounds mode must be one of {', '.join(FAULT_BOUNDS_MODES)}, got {mode!r}")
        declared = [n for n in self.nodes if n.fault_rate is not None or n.fault_size is not None]
        if mode == "none":
            return ()
        return tuple(n.id for n in declared if mode == "all" or n.sensor.saturated or n.fault_size == 0 or self.bound_relied(n.id))

    def references(self) -> tuple[int, ...]:
        """Reference sensors whose readings are exchanged: declared fault-free (``[fault_bound] size = 0``);
        they publish their reading of every step before estimating and every other node uses it
        (docs/network.md).  None with ``[network] readings = false``."""
        return tuple(n.id for n in self.nodes if n.fault_size == 0) if self.readings else ()

    @property
    def health_declared(self) -> bool:
        """Whether the nodes use the k-of-N health assumption (``[network] max_faulty`` or health groups, readings on)."""
        return bool(self.health_groups) and self.readings

    def health_group(self, i: int) -> HealthGroup | None:
        """Node i's k-of-N group (None: it is in none, or no health is used)."""
        if not self.health_declared:
            return None
        return next((g for g in self.health_groups if i in g.nodes), None)

    def silent_without_reading(self, i: int, k: int) -> bool:
        """Whether node i publishes nothing at step k when it has no reading there (a gap in a recorded drive,
        docs/your-log.md): an SDP node after step 0 (it resumes at its next reading); a set estimator publishes its
        prediction-only set, and every node at step 0 its prior."""
        return k > 0 and self.node(i).estimator == SDP

    def publishes_reading(self, i: int) -> bool:
        """Whether node i publishes its reading of every step: some node reads it (a reference, a member of a k-of-N
        group, a sensor whose reading others use with its declared fault bound)."""
        return i in self._read

    @functools.cached_property
    def _read(self) -> frozenset[int]:  # the nodes some node reads (once per scenario: a large ring asks for every node)
        return frozenset(j for i in self.ids for j in self.reading_sources(i))

    @functools.cached_property
    def _relied(self) -> frozenset[int]:  # the nodes whose declared bound some node reads their reading with
        return frozenset(j for i in self.ids for j in self.bounded_sources(i))

    def reading_sources(self, i: int, bounded: bool = True) -> tuple[int, ...]:
        """The nodes whose readings node i uses (its own reading comes with its input): the references, the other
        members of its k-of-N group and (``bounded``) the sensors whose reading it uses with their declared fault bound
        (:meth:`bounded_sources`); with ``reading_scope = "neighbours"`` only those among its in-neighbours."""
        group, refs = self.health_group(i), self.references()
        exchanged = {j for j in self.ids if j != i and (j in refs or (group is not None and j in group.nodes)) and self._reaches(j, i)}
        return tuple(sorted(exchanged | set(self.bounded_sources(i) if bounded else ())))

    def _reaches(self, j: int, i: int) -> bool:
        """Whether node j's reading goes to node i at all (``reading_scope``)."""
        return self.reading_scope == "network" or j in self.node(i).in_weights

    def bounded_sources(self, i: int) -> tuple[int, ...]:
        """The nodes j ≠ i whose reading of each step node i uses with j's declared fault bound (size and/or rate;
        not a reference, whose reading is used as fault-free): ``[network] bounded_readings``, within
        ``reading_scope``."""
        if not (self.readings and self.bounded_readings):
            return ()
        return tuple(
            n.id for n in self.nodes if n.id != i and n.fault_size != 0 and (n.fault_size is not None or n.fault_rate is not None) and self._reaches(n.id, i)
        )

    def reads_everyone(self, i: int) -> bool:
        """Whether node i reads every other node's reading in its step (then its neighbours' sets hold nothing it lacks
        but their priors' first steps: docs/network.md)."""
        return set(self.reading_sources(i)) >= set(self.ids) - {i}

    def bound_relied(self, i: int) -> bool:
        """Whether node i's declared fault bound is relied on at every step: another node uses its reading with it
        (:meth:`bounded_sources`); node i's own published set then rests on it too (docs/network.md)."""
        return i in self._relied

    def delays(self, i: int, first: bool = False) -> dict[int, int]:
        """d(j→i) for every node j whose data can reach node i: the steps the runtime needs to carry j's measurement of a
        step to i (docs/exact.md, *The network limit*).  At step k node i has its own measurement of k, the readings of
        k of its reading sources and its in-neighbours' states of k − 1, each of which holds what its node knew at
        k − 1: so one hop per step along the state edges, and a reading's hop in the same step.  ``first``: the delays
        of step 0's data (the prior and the first measurement), which no reading carries (a reading is of a step ≥ 1):
        state hops only.  d(i→i) = 0; a node whose data never reaches i is left out."""
        dist = {i: 0}  # state hops from l to i
        frontier = [i]
        while frontier:
            nxt = []
            for m in frontier:
                for src in self.node(m).in_weights:
                    if src not in dist:
                        dist[src] = dist[m] + 1
                        nxt.append(src)
            frontier = nxt
        out = dict(dist)
        for reader in self.ids if not first else ():
            if reader in dist:
                for j in self.reading_sources(reader):
                    out[j] = min(out.get(j, dist[reader]), dist[reader])
        return dict(sorted(out.items()))

    def health_holds(self, faults: dict[int, float]) -> bool:
        """The k-of-N assumption at one step: at most m faults above the tolerance in every declared group
        (True if none is declared)."""
        return all(g.holds(faults, self.fault_tolerance) for g in self.health_groups)

    def group_health_holds(self, i: int, faults: dict[int, float]) -> bool:
        """The k-of-N assumption of node i's group at one step (True if it is in none): what a set resting on
        its group's k-of-N interval needs."""
        group = self.health_group(i)
        return group is None or group.holds(faults, self.fault_tolerance)

    @property
    def health_label(self) -> str:
        """The declaration in a few words: ``max_faulty = 4`` (one group of every node) or the groups'."""
        if len(self.health_groups) == 1 and set(self.health_groups[0].nodes) == set(self.ids):
            return f"max_faulty = {self.health_groups[0].max_faulty}"
        return "; ".join(f"max_faulty = {g.max_faulty} of nodes {', '.join(map(str, g.nodes))}" for g in self.health_groups)

    def alone(self) -> Scenario:
        """The same scenario with every node on its own: a self-loop only, no reading exchanged (what the
        network is measured against, docs/network.md)."""
        return dataclasses.replace(self, nodes=[dataclasses.replace(n, in_weights={n.id: 1.0}) for n in self.nodes], readings=False)

    def out_neighbours(self, j: int) -> list[int]:
        """Nodes i ≠ j that use j's message."""
        return [n.id for n in self.nodes if j in n.in_weights and n.id != j]


_FIELD = re.compile(r"^Object (?P<what>contains unknown|missing required) field `(?P<name>[^`]*)`$")
_BOUND = re.compile(r"^Expected `(?:int|float)` (?P<op>>=|>|<=|<) (?P<value>\S+)$")
_BOUND_WORDS = {">=": "greater than or equal to", ">": "greater than", "<=": "less than or equal to", "<": "less than"}
_STEP = re.compile(r"\.?([^.\[\]]+)|\[(\d+)\]")  # "edges[3].from" → "edges", 3, "from"


def _value_at(data: object, loc: str) -> object:
    """The input value at msgspec's location ``loc`` (None if there is none)."""
    for name, index in _STEP.findall(loc):
        try:
            data = data[int(index)] if index else data[name]  # type: ignore[index]  # data is whatever TOML holds; a miss raises and returns None below
        except (KeyError, IndexError, TypeError, ValueError):
            return None
    return data


def _explain(err: msgspec.ValidationError, data: object) -> str:
    """msgspec's "Expected `int` >= 1 - at `$.steps`" as "steps: Input should be greater than or equal to 1"."""
    msg, loc = split_error(err)
    if f := _FIELD.match(msg):  # name the field itself, not the table holding it
        loc = f"{loc}.{f['name']}" if loc else f["name"]
        msg = "Field required" if f["what"] == "missing required" else "Extra inputs are not permitted (unknown field)"
    elif msg.startswith("Expected `str` matching regex"):  # the profile name is the only pattern
        msg = "Input should be a file name without '/', '\\' or NUL"
    elif b := _BOUND.match(msg):
        value = _value_at(data, loc)
        if (isinstance(value, float) and not math.isfinite(value)) or b["value"].lstrip("-") == FINITE_BOUND_TEXT:
            msg = "Input should be a finite number"  # NaN fails whichever bound is checked first
        else:
            msg = f"Input should be {_BOUND_WORDS[b['op']]} {b['value']}"
    return f"{loc}: {msg}" if loc else msg


def _validated(path: Path, data: dict, cls: type[_T]) -> _T:
    """``data`` as a ``cls`` (strict types: an int for a float is the only conversion), ConfigError otherwise."""
    try:
        return msgspec.convert(data, cls, strict=True)
    except msgspec.ValidationError as exc:
        raise ConfigError(f"{path}: {_explain(exc, data)}") from None  # one line: the file, the field, why


MAX_CONFIG_BYTES = 1 << 20  # a topology or profile is a few kB: larger is not one


def _read_toml(path: Path) -> dict:
    try:
        st = path.stat()  # a FIFO or a device would block or never end: only regular files are read
        if not stat.S_ISREG(st.st_mode):
            kind = "a directory" if stat.S_ISDIR(st.st_mode) else "a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device or socket"
            raise ConfigError(f"{path}: cannot read: {kind}, not a regular file")
        if st.st_size > MAX_CONFIG_BYTES:
            raise ConfigError(f"{path}: too large for a configuration file ({st.st_size} bytes)")
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML (not UTF-8: {exc.reason} at byte {exc.start})") from None
    except RecursionError:
        raise ConfigError(f"{path}: not valid TOML (nested too deeply)") from None
    except ValueError as exc:  # e.g. an embedded NUL byte in the path
        raise ConfigError(f"{path!r}: cannot read: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None


def load_profile(path: Path) -> NodeProfile:
    return _validated(path, _read_toml(path), NodeProfile)


def load_mapping(path: Path) -> LogMapping:
    """A drive log's mapping file (config/logmap.py), validated; ConfigError naming the file, the field and why."""
    return resolve_mapping(path, _validated(path, _read_toml(path), MappingFile))


def _log_source(path: Path, v: CarSpec, log: str | None, mapping: str | None, steps_given: bool) -> LogSource | None:
    """The run's recorded drive: ``log``/``mapping`` (the command line's, relative to the working directory) over
    the topology's ``[vehicle] log``/``mapping`` (relative to the file); the mapping defaults to the log's name with
    ``.map.toml``.  None: the model drives."""
    if log is None and mapping is None and v.source != "log":
        return None
    if log is None and v.log is None:
        raise ConfigError(f'{path}: vehicle.source = "log" names no log: give vehicle.log, or run with --log DRIVE')
    log_path = Path(log) if log is not None else path.parent / str(v.log)
    if not log_path.exists():
        raise ConfigError(f"{log_path}: drive log not found")
    map_path = Path(mapping) if mapping is not None else path.parent / v.mapping if v.mapping is not None else log_path.with_suffix(".map.toml")
    if not map_path.exists():
        raise ConfigError(f"{map_path}: the log's mapping file not found (give --map MAP.toml, or vehicle.mapping in the topology)")
    return LogSource(str(log_path), load_mapping(map_path), steps_given)


def _check_log_nodes(path: Path, src: LogSource, ids: list[int], case: str) -> None:
    """Every node is mapped to one yaw-rate channel and every mapped node is one of the topology's."""
    m = src.mapping
    mapped = [s.node for s in m.sensors]
    if unknown := sorted(set(mapped) - set(ids)):
        raise ConfigError(f"{m.path}: yaw_rate: node {unknown[0]} is not a node of {path} (ids: {ids})")
    if unmapped := sorted(set(ids) - set(mapped)):
        raise ConfigError(f"{m.path}: yaw_rate: no channel for node {unmapped[0]} of {path}: every node needs its reading")
    if case != "nsnim":
        raise ConfigError(f"{path}: case {case!r} on a log: a logged reading is the sensor's own (γ = 1, no saturation model of it), which is the nsnim case")


FAULT_SCALE_MAX = 10.0  # --fault-scale: a fault ten times its declared bound is already far outside every assumption


def scaled_fault(path: Path, prof: NodeProfile, scale: float) -> NodeProfile:
    """``prof`` with its fault's largest |f_k| set to ``scale`` × its declared ``[fault_bound] size`` (the shape
    kept: a square fault's amplitude, a piecewise fault's values scaled together); a fault-free profile as it
    is.  A faulty profile that declares no size has nothing to scale by: ConfigError naming it."""
    if not (math.isfinite(scale) and 0 <= scale <= FAULT_SCALE_MAX):
        raise ConfigError(f"fault scale must be between 0 and {FAULT_SCALE_MAX:g}, got {scale!r}")
    f = prof.fault
    peak = abs(f.amplitude or 0.0) if f.kind == "square" else max((abs(v) for _, v in f.points or ()), default=0.0)
    if f.kind == "none" or peak == 0.0:
        return prof
    size = prof.fault_bound.size
    if not size:  # None: no bound declared; 0: a reference sensor, declared fault-free (its fault breaks that)
        raise ConfigError(f"{path}: a fault scale needs [fault_bound] size > 0 for its {f.kind} fault (it scales the fault to a fraction of it)")
    k = scale * size / peak
    if f.kind == "square":
        return msgspec.structs.replace(prof, fault=msgspec.structs.replace(f, amplitude=k * f.amplitude))  # type: ignore[operator]  # a square fault has an amplitude: peak > 0
    return msgspec.structs.replace(prof, fault=msgspec.structs.replace(f, points=[(s, k * v) for s, v in f.points or ()]))


def load_topology(
    path: str | Path,
    case: Case | None = None,
    steps: int | None = None,
    estimator: str | None = None,
    manoeuvre: str | None = None,
    steer_high: float | None = None,
    speed_kmh: float | None = None,
    fault_scale: float | None = None,
    log: str | None = None,
    mapping: str | None = None,
) -> Scenario:
    """Read and validate a topology (a path, or the name of a bundled one such as ``paper6``) and its node
    profiles; ``case``/``steps``/``estimator`` (every node's)/``manoeuvre``/``steer_high`` (``[steering]
    high``)/``speed_kmh`` (``[speed] mean_kmh``) override the file; ``fault_scale`` sets every node's fault to
    that fraction of its declared ``[fault_bound] size`` (:func:`scaled_fault`); ``log``/``mapping`` make a
    recorded drive the world (docs/your-log.md).  The overrides are applied to the files' values before
    validation, so the scenario's ``settings_digest`` covers them."""
    path = resolve_topology(path)
    _check_arguments(path, case, steps, estimator)
    data = _overridden(_read_toml(path), manoeuvre, steer_high, speed_kmh)
    topo = _validated(path, data, TopologyFile)
    case = case or topo.case
    node_dir = _node_dir(path, topo)
    v = topo.vehicle
    log_source = _log_source(path, v, log, mapping, steps is not None or "steps" in data)
    try:
        params = v.params()
    except MissingExtra as exc:
        raise ConfigError(f"{path}: vehicle.plant = {v.plant!r}: {exc}") from None
    nodes = []
    profiles: dict[int, NodeProfile] = {}
    for ref in topo.nodes:
        ppath = node_dir / f"{ref.profile}.toml"
        if not ppath.exists():
            raise ConfigError(f"{path}: node {ref.id}: profile {ref.profile!r}: {ppath.name} not found in node_dir {topo.node_dir!r} ({node_dir})")
        prof = profiles[ref.id] = load_profile(ppath) if fault_scale is None else scaled_fault(ppath, load_profile(ppath), fault_scale)
        nodes.append(_node_config(ppath, prof, ref, topo, case, estimator))
    scenario = Scenario(
        path=str(path),
        name=topo.name,
        case=case,
        steps=steps if steps is not None else topo.steps,
        tau_s=topo.tau_s,
        W=topo.W,
        model=TSModel.build(params, topo.tau_s),
        x0=np.array(v.x0, dtype=float),
        # the speed reference: the sine profile, or its mean held (models/manoeuvres.py)
        speed=SpeedProfile(topo.speed.mean_kmh, topo.speed.amplitude_kmh if v.manoeuvre in SINE_SPEED else 0.0, topo.speed.period_s),
        steer_low=topo.steering.low,
        steer_high=topo.steering.high,
        nodes=nodes,
        loss=topo.loss,
        plant=cast(PlantKind, v.plant),  # one of PLANTS: CarSpec checked it
        vehicle_id=v.car,
        manoeuvre=cast(ManoeuvreName, v.manoeuvre),  # one of MANOEUVRES: CarSpec checked it
        uncertainty=topo.model_uncertainty.build() if topo.model_uncertainty is not None else None,
        envelope=topo.envelope.build() if topo.envelope is not None else None,
        fault_tolerance=topo.network.fault_tolerance,
        readings=topo.network.readings,
        health_groups=_health_groups(path, topo.network, nodes),
        settings_digest=_settings_digest(topo, profiles),
        reading_scope=topo.network.reading_scope,
        neighbour_sets=topo.network.neighbour_sets,
        bounded_readings=topo.network.bounded_readings,
        log=log_source,
    )
    if log_source is not None:
        _check_log_nodes(path, log_source, scenario.ids, scenario.case)
    return scenario


def _check_arguments(path: Path, case: str | None, steps: int | None, estimator: str | None) -> None:
    """:func:`load_topology`'s file and overrides that need no file to refuse."""
    if not path.exists():
        raise ConfigError(f"{path}: file not found (bundled topologies: {', '.join(bundled_topologies())})")
    if case is not None and case not in ("nsnim", "saim"):
        raise ConfigError(f"{path}: case must be 'nsnim' or 'saim', got {case!r}")
    if steps is not None and steps < 1:
        raise ConfigError(f"{path}: steps must be ≥ 1, got {steps}")
    if estimator is not None and estimator not in NODE_ESTIMATOR_NAMES:
        raise ConfigError(f"estimator must be one of {', '.join(NODE_ESTIMATOR_NAMES)}, got {estimator!r}")


def _overridden(data: dict, manoeuvre: str | None, steer_high: float | None, speed_kmh: float | None) -> dict:
    """The file's tables with the overrides in, validated with the file (a table that is no table fails validation as
    it is): the manoeuvre (the speed range depends on it), ``[steering] high`` (low ≤ high, the physical range),
    ``[speed] mean_kmh`` (the range, and the model's speed range at load)."""
    for table, key, value in (("vehicle", "manoeuvre", manoeuvre), ("steering", "high", steer_high), ("speed", "mean_kmh", speed_kmh)):
        if value is not None and isinstance(current := data.get(table, {}), dict):
            data[table] = {**current, key: value}
    return data


def _node_dir(path: Path, topo: TopologyFile) -> Path:
    """The topology's node directory, resolved against the file's directory; a ConfigError where there is none."""
    try:
        node_dir = (path.parent / topo.node_dir).resolve()
    except (RuntimeError, OSError, ValueError) as exc:  # a symlink loop, a NUL byte
        raise ConfigError(f"{path}: node_dir {topo.node_dir!r}: {exc}") from None
    if not node_dir.is_dir():  # a wrong node_dir once read as a missing profile file
        raise ConfigError(f"{path}: node_dir {topo.node_dir!r}: no such directory ({node_dir}; relative to the topology file's directory)")
    return node_dir


def _node_config(ppath: Path, prof: NodeProfile, ref: NodeRef, topo: TopologyFile, case: str, estimator: str | None) -> NodeConfig:
    """One node of the topology from its profile (``ppath``), for ``case``: its sensor, fault, prior and in-weights."""
    saim = case == "saim"
    if saim and (prof.saturation is None or prof.availability is None):
        raise ConfigError(f"{ppath}: the saim case needs [saturation] and [availability] sections")
    sat = prof.saturation if saim else None
    sensor = Sensor(
        C=np.array(prof.C, dtype=float),
        Ds=prof.Ds,
        Dv=prof.Dv,
        R=prof.R,
        saturated=sat is not None,
        r_max=sat.r_max if sat else np.inf,
        h1=sat.h1 if sat else 1.0,
        h2=sat.h2 if sat else 1.0,
    )
    in_w = {e.from_: e.weight for e in topo.edges if e.to == ref.id}
    return NodeConfig(
        id=ref.id,
        label=prof.label or ref.profile,
        sensor=sensor,
        noise_frequency=prof.noise_frequency,
        gamma_range=(prof.availability.gamma_min, prof.availability.gamma_max) if saim else None,  # type: ignore[union-attr]  # saim: the check above raised unless both sections exist
        fault=prof.fault.build(),
        x0_hat=np.array(prof.x0_hat, dtype=float),
        P0=prof.P0_matrix(),
        rho=prof.rho,
        in_weights=dict(sorted(in_w.items())),
        fault_rate=prof.fault_bound.rate,
        fault_size=prof.fault_bound.size,
        estimator=estimator or ref.estimator,
    )


def _settings_digest(topo: TopologyFile, profiles: dict[int, NodeProfile]) -> str:
    """A digest of what a run rests on in its files: every value, not the names, paths, steps, case or
    estimators (which a command line may change). A record keeps it, so that `netsetest exact` knows a
    topology that is not the run's even where its meta holds nothing that differs."""
    plain = msgspec.structs.replace
    own = msgspec.to_builtins(plain(topo, name="", node_dir="", steps=1, case="nsnim", nodes=[plain(n, profile="", estimator=SDP) for n in topo.nodes]))
    for key, default in NETWORK_DEFAULTS.items():  # fields added later: a file that leaves them at their default keeps its digest
        if own["network"][key] == default:
            del own["network"][key]
    for key in LOG_KEYS:  # where the drive comes from is no setting a run rests on (and a model run's digest stays as before)
        own["vehicle"].pop(key)
    body = msgspec.json.encode([own, [[i, plain(p, label="")] for i, p in sorted(profiles.items())]])
    return sha256(body).hexdigest()[:SETTINGS_DIGEST_HEX]


LOG_KEYS = ("source", "log", "mapping")  # [vehicle]'s keys that name the drive's source
SETTINGS_DIGEST_HEX = 16  # 64 bits: tells two files apart, never a security property


def _health_groups(path: Path, network: NetworkSpec, nodes: list[NodeConfig]) -> tuple[HealthGroup, ...]:
    """``[network] max_faulty`` (one group of every node) or ``[[network.health_groups]]``, checked: known,
    disjoint nodes, m fewer than the group, and every sensor of a group measuring the same combination of the
    state (C_j = s_j uᵀ), so that its k-of-N readings bound one quantity (estimator/health.py)."""
    if network.max_faulty is not None and network.health_groups:
        raise ConfigError(f"{path}: network.max_faulty and network.health_groups: give one (max_faulty is one group of every node)")
    if network.max_faulty is not None:
        specs = [(f"network.max_faulty = {network.max_faulty}", [n.id for n in nodes], network.max_faulty)]
    else:
        specs = [(f"network.health_groups[{k}]", g.nodes, g.max_faulty) for k, g in enumerate(network.health_groups)]
    by_id = {n.id: n for n in nodes}
    seen: set[int] = set()
    out = []
    for what, ids, m in specs:
        unknown = sorted(set(ids) - set(by_id))
        if unknown:
            raise ConfigError(f"{path}: {what}: no node with id {unknown[0]} (ids: {sorted(by_id)})")
        if len(set(ids)) != len(ids) or seen & set(ids):
            raise ConfigError(f"{path}: {what}: node {sorted(k for k in ids if ids.count(k) > 1 or k in seen)[0]} is in it twice or in two groups")
        seen |= set(ids)
        if m >= len(ids):
            raise ConfigError(f"{path}: {what}: max_faulty must be less than the number of its nodes ({len(ids)})")
        group = [by_id[i] for i in ids]
        u = group[0].sensor.direction
        for n in group:
            c = n.sensor.C
            if np.linalg.norm(c - (c @ u) * u) > 1e-9 * np.linalg.norm(c):
                raise ConfigError(
                    f"{path}: {what} needs every sensor to measure the same combination of the state; "
                    f"node {n.id}'s C = {list(c)} is not parallel to node {group[0].id}'s"
                )
        out.append(HealthGroup(tuple(ids), m))
    return tuple(out)
