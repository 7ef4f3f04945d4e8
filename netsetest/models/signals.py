"""Exogenous signals of a run: speed and steering profiles, faults, disturbance, noise, availability.

Two signal families for w and v (selected per run, seeded):

- ``paper``: w_k = −1 + 2·rand (Sec. VI), v_i,k = cos(2π f_i (k−1) τs) with f_i the node's noise frequency;
- ``worst``: w and v held at the edge of their bounds (±√W, ±√R_i), the sign switching at random
  (bang-bang, each step a fresh sign) — the hardest bounded signals for a set-membership estimator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

SignalKind = Literal["paper", "worst"]
SIGNAL_KINDS: tuple[SignalKind, ...] = ("paper", "worst")


@dataclass(frozen=True)
class SquareFault:
    """amplitude·sign(sin(2π k/period)) for start ≤ k < end (f1, f4 of Sec. VI)."""

    amplitude: float
    period: int
    start: int
    end: int

    def __call__(self, k: int) -> float:
        if not (self.start <= k < self.end):
            return 0.0
        # exact sign of sin(2πk/P) on integers (avoids sin(π) = 1.2e-16 deciding the sign)
        phase2 = (2 * k) % (2 * self.period)  # 2k mod 2P: 0 and P are the zeros
        if phase2 == 0 or phase2 == self.period:
            return 0.0
        return self.amplitude if phase2 < self.period else -self.amplitude


@dataclass(frozen=True)
class PiecewiseLinearFault:
    """Linear interpolation through (k, f) points, zero outside [first k, last k) (f2, f6 of Sec. VI)."""

    points: tuple[tuple[float, float], ...]

    def __call__(self, k: int) -> float:
        ks = [p[0] for p in self.points]
        if not (ks[0] <= k < ks[-1]):
            return 0.0
        return float(np.interp(k, ks, [p[1] for p in self.points]))


@dataclass(frozen=True)
class NoFault:
    def __call__(self, k: int) -> float:
        return 0.0


Fault = SquareFault | PiecewiseLinearFault | NoFault


@dataclass(frozen=True)
class SpeedProfile:
    """Vx(t) = mean + amplitude·sin(2π t/period) [km/h]: smooth and inside [80, 120] km/h (Fig. 4 stand-in)."""

    mean_kmh: float
    amplitude_kmh: float
    period_s: float

    def kmh(self, t: float) -> float:
        return self.mean_kmh + self.amplitude_kmh * np.sin(2 * np.pi * t / self.period_s)

    def ms(self, t: float) -> tuple[float, float]:
        """(Vx, dVx/dt) at t in m/s and m/s² (a plant's speed reference)."""
        w = 2 * math.pi / self.period_s
        return (self.mean_kmh + self.amplitude_kmh * math.sin(w * t)) / 3.6, self.amplitude_kmh * w * math.cos(w * t) / 3.6


class ExogenousSignals:
    """Seeded generator of u_k, w_k, v_i,k, γ_i,k for one run; draws happen in a fixed order per step."""

    def __init__(
        self,
        kind: SignalKind,
        seed: int,
        steer_low: float,
        steer_high: float,
        W: float,
        R: list[float],
        noise_freq: list[float],
        gamma_ranges: list[tuple[float, float]] | None,
        tau_s: float,
    ) -> None:
        self.kind = kind
        self.rng = np.random.default_rng(seed)
        self.steer_low, self.steer_high = steer_low, steer_high
        self.W, self.R, self.noise_freq = W, R, noise_freq
        self.gamma_ranges = gamma_ranges
        self.tau_s = tau_s

    def draw(self, k: int) -> tuple[float, float, np.ndarray, np.ndarray]:
        """(u_k, w_k, v_k per node, γ_k per node)."""
        n = len(self.R)
        u = self.steer_low + (self.steer_high - self.steer_low) * self.rng.random()
        if self.kind == "paper":
            w = -1.0 + 2.0 * self.rng.random()
            v = np.array([np.cos(2 * np.pi * f * (k - 1) * self.tau_s) for f in self.noise_freq])
        else:
            signs = self.rng.choice([-1.0, 1.0], size=n + 1)
            w = signs[0] * np.sqrt(self.W)
            v = signs[1:] * np.sqrt(np.asarray(self.R))
        if self.gamma_ranges is None:
            gamma = np.ones(n)
        else:
            lo = np.array([g[0] for g in self.gamma_ranges])
            hi = np.array([g[1] for g in self.gamma_ranges])
            gamma = lo + (hi - lo) * self.rng.random(n)
        return float(u), float(w), v, gamma
