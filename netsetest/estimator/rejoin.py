"""A safe initial ellipsoid for a node that (re)joins a running network, or resumes after missing measurements.

The node has lost its own estimate (a restart), or could not update it (no reading: a gap in a recorded drive,
docs/your-log.md), so it builds one from what is guaranteed at step k:

- the vehicle state x_k: the projection on x of an in-neighbour's published ellipsoid of step k
  (x̄_j = [x; f_j] lies in {x̂_j, ρ_j P_j}, so x lies in {x̂_j[:2], ρ_j P_j[:2, :2]}); among several
  neighbours the one with the smallest projected trace is used (:func:`rejoin_ellipsoid`); or, resuming, the
  projection on x of the node's own last set carried through the steps without a reading by the model alone
  (:func:`predict_x`, :func:`resume_ellipsoid`);
- its own fault f_i,k: from its own measurement ỹ = γ σ(C x + Ds f) + Dv v with |v| ≤ √R:
  σ(r) ∈ [(ỹ − |Dv|√R)/γ, (ỹ + |Dv|√R)/γ]; where that interval reaches the saturation level the
  sector assumption bounds |r| ≤ r_max/h1; then f = (r − C x)/Ds with C x in its interval.

The Cartesian product {x-ellipsoid} × {|f − f_c| ≤ δ} lies in the ellipsoid with shape
diag(S_x/p, δ²/(1 − p)) for any p ∈ (0, 1); p = √tr S_x / (√tr S_x + δ) minimises its trace.
The result holds whenever the neighbour's ellipsoid holds and the node's own noise bound and sector
condition hold at step k — the same assumptions the collector checks for that step.  Resuming, the x part
holds wherever the own set of the last step with a reading held and the wind and model-mismatch bounds held
on every transition since (the collector checks each: roles/judge.py).

Why resuming from the model alone loses little: with E = diag(I₂, 0) the fault is free at every step, so a
measurement after step 0 says nothing about x (docs/estimator.md, *Findings*): the exact x set is the model's
propagation whether the readings came or not, and the fault part is rebuilt from the next reading, as the
update would.
"""

from __future__ import annotations

import numpy as np

from netsetest.estimator.sdp import NeighbourState
from netsetest.models.sensor import NA, NX, Sensor
from netsetest.models.uncertainty import ModelUncertainty


class RejoinError(ValueError):
    """No in-neighbour ellipsoid to start from."""


def rejoin_ellipsoid(own: Sensor, y: float, gamma: float, rho: float, neighbours: list[NeighbourState]) -> tuple[np.ndarray, np.ndarray]:
    """(x̂, P) with [x_k; f_i,k] ∈ {e: eᵀP⁻¹e ≤ ρ} given neighbours' step-k ellipsoids."""
    if not neighbours:
        raise RejoinError("a rejoining node needs at least one in-neighbour's ellipsoid of the same step")
    best = min(neighbours, key=lambda n: n.rho * np.trace(n.P[:NX, :NX]))
    return resume_ellipsoid(own, y, gamma, rho, best.xhat[:NX].copy(), best.rho * best.P[:NX, :NX])


SUM_WIDEN = 1e-9  # relative widening of a propagated shape: the rounding of its sums stays inside


def predict_x(
    xc: np.ndarray, Sx: np.ndarray, a: np.ndarray, b: np.ndarray, d: np.ndarray, u: float, W: float, mismatch: ModelUncertainty | None
) -> tuple[np.ndarray, np.ndarray]:
    """The x set of step k+1, {x: (x − c)ᵀS⁻¹(x − c) ≤ 1}, from the one of step k by the model alone:
    x⁺ = a x + b u + d w + G ζ with w² ≤ W and ζ in the unit box or ball of the declared ``mismatch``
    (models/uncertainty.py; None: none declared, e = 0).

    ``a`` (NX, NX), ``b``, ``d`` (NX,): the transition's blended Ā, B̄, D̄.  The sum of ellipsoids E(Q₁) ⊕ … ⊕
    E(Q_n) lies in E(Σ Q_m/p_m) for every p_m > 0 with Σ p_m = 1 (Cauchy–Schwarz on x = Σ x_m);
    p_m ∝ √tr Q_m minimises its trace.  The terms: a S aᵀ (the set), W d dᵀ (the wind's segment), and the
    mismatch's (a box: g_m g_mᵀ per column of G; a ball: G Gᵀ)."""
    c = a @ xc + b * u
    terms = [a @ Sx @ a.T, W * np.outer(d, d)]
    if mismatch is not None:
        G = mismatch.G
        terms += [np.outer(g, g) for g in G.T] if mismatch.kind == "box" else [G @ G.T]
    roots = [np.sqrt(max(float(np.trace(q)), 0.0)) for q in terms]
    total = sum(roots)
    S = sum(q * (total / r) for q, r in zip(terms, roots) if r > 0.0)
    return c, 0.5 * (S + S.T) * (1 + SUM_WIDEN)


def resume_ellipsoid(own: Sensor, y: float, gamma: float, rho: float, xc: np.ndarray, Sx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x̂, P) with [x_k; f_i,k] ∈ {e: eᵀP⁻¹e ≤ ρ} given x_k ∈ {x: (x − xc)ᵀSx⁻¹(x − xc) ≤ 1} and the node's own
    step-k measurement ``y``, ``gamma`` (module doc)."""

    # interval of σ(r), then of r
    half_v = abs(own.Dv) * np.sqrt(own.R)
    s_lo, s_hi = (y - half_v) / gamma, (y + half_v) / gamma
    if own.saturated:
        # σ(r) = r below the saturation level; a σ interval touching ±r_max leaves r free up to
        # the sector limit r_max/h1 on that side
        r_lo = -own.sector_limit if s_lo <= -own.r_max else s_lo
        r_hi = own.sector_limit if s_hi >= own.r_max else s_hi
    else:
        r_lo, r_hi = s_lo, s_hi
    C = own.C
    cx_c, cx_half = float(C @ xc), float(np.sqrt(max(C @ Sx @ C, 0.0)))
    f_a, f_b = (r_lo - cx_c - cx_half) / own.Ds, (r_hi - cx_c + cx_half) / own.Ds
    f_lo, f_hi = min(f_a, f_b), max(f_a, f_b)
    fc, delta = 0.5 * (f_lo + f_hi), 0.5 * (f_hi - f_lo)

    tx = float(np.trace(Sx))
    p = np.sqrt(tx) / (np.sqrt(tx) + delta)
    S = np.zeros((NA, NA))
    S[:NX, :NX] = Sx / p
    S[NX, NX] = delta**2 / (1.0 - p)
    return np.r_[xc, fc], S / rho
