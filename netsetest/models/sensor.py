"""Yaw-rate sensor i with fault, noise, saturation and incomplete measurement (paper (9)-(15), (18)-(20)).

Augmented state x̄_i = [x; f_i] (n = 3), C̄_i = [C_i, Ds_i].  The measurement is

    ỹ_i = γ_i σ(C̄_i x̄_i) + Dv_i v_i,        v_i² ≤ R_i                                   (12)
    σ(r) = sign(r)·min(r_max, |r|) = h1·r + φ(r),   φ(r)(φ(r) − h·r) ≤ 0,  h = h2 − h1     (14)-(15)

The sector condition (15) holds exactly while |r| ≤ r_max/h1 (docs/design.md §1).  The profile's fixed h1
is the paper's; the estimator derives a sector per step instead (netsetest/estimator/sector.py) and
falls back to the fixed one, marked assumed, only without a declared fault bound.  A sensor without saturation has
h1 = h2 = 1, σ = identity and φ ≡ 0.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

NX = 2  # vehicle state [β, r]
NA = 3  # augmented state [β, r, f]

E_DESCRIPTOR = np.diag([1.0, 1.0, 0.0])  # E of (11)
# relative margin against floating-point rounding at the saturation limit: an end of the measured
# σ-interval this close to ±r_max may be the limit itself rounded (worst-case noise at exactly its
# bound) and is treated as open, which is always sound (also used by estimator/sector.py)
ROUNDING_MARGIN = 1e-9


def augmented(x: np.ndarray | Sequence[float], f: float) -> np.ndarray:
    """x̄ = [β, r, f] (NA,) of the vehicle state x (NX,) and a sensor fault f (np.r_ costs ≈8 µs, this ≈1)."""
    xbar = np.empty(NA)
    xbar[:NX] = x
    xbar[NX] = f
    return xbar


@dataclass(frozen=True)
class Sensor:
    """Static data of one yaw-rate sensor (what a neighbour needs to interpret an innovation)."""

    C: np.ndarray  # (2,)
    Ds: float
    Dv: float
    R: float
    saturated: bool = False  # model saturation at all (SAIM) or not (NSNIM)
    r_max: float = np.inf
    h1: float = 1.0
    h2: float = 1.0

    @functools.cached_property
    def Cbar(self) -> np.ndarray:
        """C̄_i = [C_i, Ds_i] (1×3 as a flat vector; read-only, built once: roles use it per message)."""
        cbar = np.array([self.C[0], self.C[1], self.Ds])
        cbar.flags.writeable = False
        return cbar

    @property
    def direction(self) -> np.ndarray:
        """u = C/‖C‖ (2,): the combination of the state the sensor measures (C = ‖C‖ uᵀ); sensors with one u
        can form a k-of-N group (config/schema.py checks it, estimator/health.py uses it)."""
        return self.C / np.linalg.norm(self.C)

    @property
    def h(self) -> float:
        """Sector width h = h2 − h1 of φ."""
        return self.h2 - self.h1

    @property
    def sector_limit(self) -> float:
        """|C̄ x̄| up to which the sector condition (15) holds."""
        return self.r_max / self.h1 if self.saturated else np.inf

    def sigma(self, r: float) -> float:
        """Saturation σ(r) of (13)."""
        if not self.saturated:
            return r
        return float(np.sign(r) * min(self.r_max, abs(r)))

    def measure(self, xbar: np.ndarray, gamma: float, v: float) -> float:
        """ỹ = γ σ(C̄ x̄) + Dv v (12)."""
        return gamma * self.sigma(float(self.Cbar @ xbar)) + self.Dv * v

    def measured_interval(self, y: float, gamma: float, outward: bool = False) -> tuple[float, float]:
        """The interval of r = C̄ x̄ consistent with ỹ = γ σ(r) + Dv v, v² ≤ R; ±inf is an open side.  The one
        measurement interval: ``outward`` for every estimator and region (estimator/sector.py's
        ``measurement_interval`` is that one as an Interval); not for the exact limit (analysis/exact.py), whose bounds
        a witness trajectory attains within the noise bound (docs/estimator.md, "The measurement interval").

        σ(r) ∈ [(ỹ − |Dv|√R)/γ, (ỹ + |Dv|√R)/γ] = [a, b]; σ is non-decreasing and the identity on
        [−r_max, r_max], so σ(r) ≥ a ⇔ r ≥ a unless a ≤ −r_max (then every r), and likewise for b.
        An end within ROUNDING_MARGIN of ±r_max is open: with v at its bound a saturated reading puts b at r_max up
        to one ulp, and a one-ulp "below the limit" would wrongly prove that the sensor does not saturate (seen with
        worst-case signals).  ``outward``: the half-width grows by ROUNDING_MARGIN (relative, and of |ỹ|) too, so
        that the rounding of ỹ ∓ |Dv|√R never leaves the truth out of an estimator's set.
        """
        return measured_intervals([(self, y, gamma)], outward)[0]

    def sector_holds(self, xbar: np.ndarray) -> bool:
        """Whether φ(C̄ x̄) satisfies the sector condition (15) that the estimator assumes."""
        return abs(float(self.Cbar @ xbar)) <= self.sector_limit

    def descriptor_gains(self, gamma: float, h1: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """T, G with T E + G γ h1 C̄ = I, by the pseudo-inverse of Θ = [E; γ h1 C̄] ((18)-(20), S = 0).

        ``h1``: the step's sector slope (default: the profile's fixed h1).
        """
        h1 = self.h1 if h1 is None else h1
        theta = np.vstack([E_DESCRIPTOR, gamma * h1 * self.Cbar[None, :]])
        pinv = np.linalg.pinv(theta)  # (3, 4)
        return pinv[:, :NA], pinv[:, NA:]


def measured_intervals(readings: Iterable[tuple[Sensor, float, float]], outward: bool = False) -> list[tuple[float, float]]:
    """:meth:`Sensor.measured_interval` of each (sensor, ỹ, γ), in order: a step reads several sensors in one call."""
    margin = ROUNDING_MARGIN if outward else 0.0
    out = []
    for s, y, gamma in readings:
        half = abs(s.Dv) * math.sqrt(s.R) * (1 + margin) + margin * abs(y)
        lo, hi = (y - half) / gamma, (y + half) / gamma
        edge = s.r_max * (1 - ROUNDING_MARGIN)  # (inf without saturation: never open)
        out.append(((lo if lo > -edge else -math.inf), (hi if hi < edge else math.inf)))
    return out
