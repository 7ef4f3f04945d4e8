"""The sector of a saturating sensor for one step, derived from what the node knows (docs/estimator.md).

For the saturation σ(r) = sign(r)·min(r_max, |r|), σ(r)/r ∈ [min(1, r_max/R), 1] for every 0 < |r| ≤ R.
So if the node can prove |r_k| ≤ R_k for the truth's r_k = C̄ x̄_k, the sector condition
φ(h r − φ) ≥ 0 with φ = σ(r) − h1 r holds for h1 = min(1, r_max/R_k) and h = 1 − h1 (1 is the exact upper
slope of a saturation: any h2 ≥ 1 is valid but looser, an h2 < 1 is false for small |r|).  If R_k ≤ r_max
the sensor provably does not saturate at k: φ_k ≡ 0 and the φ slot is dropped.

R_k comes from an interval [lo, hi] ∋ r_k, the intersection of whatever the node can prove:

- ``measurement``: ỹ = γσ(r) + Dv v with v² ≤ R gives σ(r) ∈ [s_lo, s_hi]; σ is the identity on
  (−r_max, r_max), so s_hi < r_max ⇒ r ≤ s_hi and s_lo > −r_max ⇒ r ≥ s_lo (a measurement at the limit
  is a one-sided constraint);
- ``fault-bound``: the node's certified set of step k−1 propagated through that step's blended dynamics
  and the wind bound, with f_k − f_k−1 ∈ [−δ, δ] (declared rate) and/or f_k ∈ [−F, F] (declared size);
  at step 0 the prior set (Assumption 1) and the size bound.

Every bound is a support function of an ellipsoid plus interval radii: exact, no approximation.  If
neither gives a finite R_k (no fault bound declared and the measurement at the limit), the paper's
fixed sector (h1, h2 − h1 of the profile) is used and marked ``assumed``: it holds only while
|r_k| ≤ r_max/h1, which the collector checks against the truth.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from netsetest.models.sensor import NX, Sensor, measured_intervals
from netsetest.models.uncertainty import ModelUncertainty

SATURATION_UPPER_SLOPE = 1.0  # sup σ(r)/r of a saturation: the exact h2
SectorBasis = Literal["none", "measurement", "fault-bound", "assumed"]


@dataclass(frozen=True)
class FaultBound:
    """Declared bound on a sensor's fault: |f_k − f_k−1| ≤ rate, |f_k| ≤ size (None: not declared)."""

    rate: float | None = None
    size: float | None = None


@dataclass(frozen=True)
class Sector:
    """Sector of φ at one step: φ = σ(r) − h1·r ∈ [0, h·r]; ``basis`` says what it rests on.

    h = 0 (then h1 = 1): the sensor provably does not saturate at this step, φ ≡ 0 (no φ slot).
    """

    h1: float
    h: float
    basis: SectorBasis

    @property
    def has_phi(self) -> bool:
        return self.h > 0.0


@dataclass(frozen=True)
class Interval:
    lo: float
    hi: float

    def __and__(self, other: Interval) -> Interval:
        return Interval(max(self.lo, other.lo), min(self.hi, other.hi))

    @property
    def radius(self) -> float:
        """max |r| over the interval."""
        return max(abs(self.lo), abs(self.hi))


UNBOUNDED = Interval(-math.inf, math.inf)


def measurement_interval(sensor: Sensor, y: float, gamma: float) -> Interval:
    """r ∈ this interval for every r with γσ(r) + Dv v = y, v² ≤ R: :meth:`~netsetest.models.sensor.Sensor.measured_interval`
    rounded outward (one-sided where σ is at the limit), as an :class:`Interval`: what every estimator uses."""
    return Interval(*sensor.measured_interval(y, gamma, outward=True))


def _support(g: np.ndarray, P: np.ndarray, rho: float) -> float:
    """max gᵀ(x̄ − x̂) over {(x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ}."""
    return math.sqrt(max(rho * float(g @ P @ g), 0.0))


@dataclass(frozen=True)
class Propagation:
    """The node's certified set of step k, {x̄: (x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ}, through step k → k+1: the blended Ā (2×2), B̄,
    D̄ (2,), the input u, the wind bound w² ≤ W and the declared model mismatch (None: e = 0).  Built once per step;
    :meth:`interval` gives what it proves of any sensor's r⁺ = C̄ x̄⁺."""

    xhat: np.ndarray
    P: np.ndarray
    rho: float
    a: np.ndarray
    b: np.ndarray
    d: np.ndarray
    u: float
    W: float
    uncertainty: ModelUncertainty | None = None

    def interval(self, sensor: Sensor, bound: FaultBound) -> Interval:
        """r⁺ = C(a x + b u + d w) + Ds f⁺ over x̄ in the ellipsoid of step k, w² ≤ W, f⁺ by the fault bound.

        Rate: r⁺ = (gₓ + Ds e₃)ᵀx̄ + C b u + C d w + C e + Ds(f⁺ − f), one support function over the joint set (x and
        f correlated).  Size: r⁺ = gₓᵀx̄ + C b u + C d w + C e + Ds f⁺ with |f⁺| ≤ F.  Both hold; the result is their
        intersection.  (e: the declared model mismatch, docs/plant.md; its support function adds to the wind's.)
        """
        C, Ds = sensor.C, sensor.Ds
        gx = np.append(self.a.T @ C, 0.0)  # (np.r_ costs 10 µs a call)
        centre_u = float(C @ self.b) * self.u
        wind = abs(float(C @ self.d)) * math.sqrt(self.W)
        if self.uncertainty is not None:
            wind += self.uncertainty.support(C)
        out = UNBOUNDED
        if bound.rate is not None:
            g = gx + np.append(np.zeros(NX), Ds)
            c = float(g @ self.xhat) + centre_u
            rad = _support(g, self.P, self.rho) + wind + abs(Ds) * bound.rate
            out = out & Interval(c - rad, c + rad)
        if bound.size is not None:
            c = float(gx @ self.xhat) + centre_u
            rad = _support(gx, self.P, self.rho) + wind + abs(Ds) * bound.size
            out = out & Interval(c - rad, c + rad)
        return out


def prior_interval(sensor: Sensor, bound: FaultBound, xhat: np.ndarray, P: np.ndarray, rho: float) -> Interval:
    """r₀ = C̄ x̄₀ over the prior ellipsoid (Assumption 1), and with |f₀| ≤ F where declared."""
    cbar = sensor.Cbar
    c = float(cbar @ xhat)
    rad = _support(cbar, P, rho)
    out = Interval(c - rad, c + rad)
    if bound.size is not None:
        gx = np.append(sensor.C, 0.0)
        cx, radx = float(gx @ xhat), _support(gx, P, rho) + abs(sensor.Ds) * bound.size
        out = out & Interval(cx - radx, cx + radx)
    return out


def derive_sector(sensor: Sensor, bound: FaultBound, meas: Interval, prior: Interval | None) -> Sector | None:
    """The step's sector from the measurement interval and (if a fault bound is declared) the propagated one.

    None: the sensor models no saturation.  h = 0: it provably does not saturate at this step.
    """
    if not sensor.saturated:
        return None
    declared = bound.rate is not None or bound.size is not None
    basis: SectorBasis = "measurement"
    rng = meas
    if declared and prior is not None:
        both = meas & prior
        if both.radius < meas.radius:
            rng, basis = both, "fault-bound"
    if not math.isfinite(rng.radius):
        return Sector(sensor.h1, sensor.h2 - sensor.h1, "assumed")
    if rng.radius <= sensor.r_max:
        return Sector(1.0, 0.0, basis)
    h1 = sensor.r_max / rng.radius
    h2 = SATURATION_UPPER_SLOPE
    if rng.lo > 0.0 or rng.hi < 0.0:  # one sign of r: σ(r)/r ≤ r_max/min|r| (a reading at the limit)
        h2 = min(h2, sensor.r_max / min(abs(rng.lo), abs(rng.hi)))
    return Sector(h1, h2 - h1, basis)


def sector_ok(sensor: Sensor, sector: Sector | None, r: float) -> bool:
    """Whether the step's sector holds for the truth's r = C̄ x̄ (None: the sensor models no saturation)."""
    if sector is None or not sensor.saturated:
        return True
    limit = sensor.r_max / sector.h1
    return abs(r) <= limit * (1 + 1e-12)


@dataclass(frozen=True)
class Reads:
    """The sensors whose readings of a step a node may use, by id (``sensors``: references, bounded readings, its k-of-N
    group), the references among them (declared fault-free) and a sensor of uᵀx alone (the k-of-N direction; None:
    no k-of-N group), fixed for the node's run."""

    sensors: Mapping[int, Sensor]
    references: Mapping[int, Sensor]
    u_sensor: Sensor | None = None


@dataclass(frozen=True)
class ReadingRanges:
    """What a step's readings prove (:func:`reading_ranges`): each reading's measurement interval (outward, a side at
    the sensor's limit open), keyed by its sensor's id; each reference's interval with an open side closed by the
    node's set through the step, where that leaves it finite and not empty; and uᵀx⁺ over the node's set through the
    step (the k-of-N prediction; None without a k-of-N group)."""

    measured: dict[int, Interval]
    closed: dict[int, Interval]
    u_pred: Interval | None


@dataclass(frozen=True)
class StepRanges:
    """Everything a step needs of this module, in one call (:func:`step_ranges`): the own measurement's interval, the
    own sector, the proven interval of r⁺ used as the measurement where the sector is derived and the sensor may
    saturate (None: the measurement itself), the in-neighbours whose published sector has a φ slot, and what the
    readings prove (None: not read yet, :meth:`LocalEstimator.prepare`)."""

    meas: Interval
    sector: Sector | None
    reading: Interval | None
    phi_from: frozenset[int]
    readings: ReadingRanges | None


FAULT_FREE = FaultBound(size=0.0)  # a reference's, and uᵀx's (no fault term)


def step_ranges(
    own: Sensor,
    bound: FaultBound,
    y: float,
    gamma: float,
    prop: Propagation,
    neighbours: Mapping[int, Sector | None],
    readings: Mapping[int, tuple[float, float]] | None,
    reads: Reads,
) -> StepRanges:
    """The step's :class:`StepRanges` from the own reading (ỹ⁺, γ⁺), the node's set through the step (``prop``), the
    in-neighbours' published sectors of step k and the readings of the step (None: not read yet)."""
    used = [] if readings is None else [j for j in readings if j in reads.sensors]
    intervals = measured_intervals([(own, y, gamma), *((reads.sensors[j], *readings[j]) for j in used)], outward=True)  # type: ignore[index]  # (used is empty where readings is None)
    meas = Interval(*intervals[0])
    sector: Sector | None = None
    reading: Interval | None = None
    if own.saturated:
        r_set = prop.interval(own, bound)
        sector = derive_sector(own, bound, meas, r_set)
        if sector is not None and sector.has_phi and sector.basis != "assumed":
            reading = meas & r_set if sector.basis == "fault-bound" else meas
    phi_from = frozenset(j for j, s in neighbours.items() if s is not None and s.has_phi)
    ranges = None if readings is None else _reading_ranges(prop, reads, {j: Interval(*iv) for j, iv in zip(used, intervals[1:])})
    return StepRanges(meas, sector, reading, phi_from, ranges)


def reading_ranges(prop: Propagation, readings: Mapping[int, tuple[float, float]], reads: Reads) -> ReadingRanges:
    """What the step's readings prove (:class:`ReadingRanges`), for a step whose :func:`step_ranges` did not read them."""
    used = [j for j in readings if j in reads.sensors]
    intervals = measured_intervals([(reads.sensors[j], *readings[j]) for j in used], outward=True)
    return _reading_ranges(prop, reads, {j: Interval(*iv) for j, iv in zip(used, intervals)})


def _reading_ranges(prop: Propagation, reads: Reads, measured: dict[int, Interval]) -> ReadingRanges:
    """:class:`ReadingRanges` from the readings' measurement intervals (in the readings' order)."""
    closed: dict[int, Interval] = {}
    for j, iv in measured.items():
        sensor = reads.references.get(j)
        if sensor is None:
            continue
        if not (math.isfinite(iv.lo) and math.isfinite(iv.hi)):
            iv = iv & prop.interval(sensor, FAULT_FREE)
        if math.isfinite(iv.lo) and math.isfinite(iv.hi) and iv.hi > iv.lo:
            closed[j] = iv
    u_pred = None if reads.u_sensor is None else prop.interval(reads.u_sensor, FAULT_FREE)
    return ReadingRanges(measured, closed, u_pred)


__all__ = [
    "FAULT_FREE",
    "FaultBound",
    "ReadingRanges",
    "Reads",
    "StepRanges",
    "reading_ranges",
    "step_ranges",
    "Sector",
    "SectorBasis",
    "Interval",
    "measurement_interval",
    "Propagation",
    "prior_interval",
    "derive_sector",
    "sector_ok",
    "SATURATION_UPPER_SLOPE",
]
