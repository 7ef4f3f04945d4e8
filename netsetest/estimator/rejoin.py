"""A safe initial ellipsoid for a node that (re)joins a running network.

The node has lost its own estimate, so it builds one from what is guaranteed at step k:

- the vehicle state x_k: the projection on x of an in-neighbour's published ellipsoid of step k
  (x̄_j = [x; f_j] lies in {x̂_j, ρ_j P_j}, so x lies in {x̂_j[:2], ρ_j P_j[:2, :2]}); among several
  neighbours the one with the smallest projected trace is used;
- its own fault f_i,k: from its own measurement ỹ = γ σ(C x + Ds f) + Dv v with |v| ≤ √R:
  σ(r) ∈ [(ỹ − |Dv|√R)/γ, (ỹ + |Dv|√R)/γ]; where that interval reaches the saturation level the
  sector assumption bounds |r| ≤ r_max/h1; then f = (r − C x)/Ds with C x in its interval.

The Cartesian product {x-ellipsoid} × {|f − f_c| ≤ δ} lies in the ellipsoid with shape
diag(S_x/p, δ²/(1 − p)) for any p ∈ (0, 1); p = √tr S_x / (√tr S_x + δ) minimises its trace.
The result holds whenever the neighbour's ellipsoid holds and the node's own noise bound and sector
condition hold at step k — the same assumptions the collector checks for that step.
"""

from __future__ import annotations

import numpy as np

from netsetest.estimator.sdp import NeighbourState
from netsetest.models.sensor import NA, NX, Sensor


class RejoinError(ValueError):
    """No in-neighbour ellipsoid to start from."""


def rejoin_ellipsoid(own: Sensor, y: float, gamma: float, rho: float, neighbours: list[NeighbourState]) -> tuple[np.ndarray, np.ndarray]:
    """(x̂, P) with [x_k; f_i,k] ∈ {e: eᵀP⁻¹e ≤ ρ} given neighbours' step-k ellipsoids."""
    if not neighbours:
        raise RejoinError("a rejoining node needs at least one in-neighbour's ellipsoid of the same step")
    best = min(neighbours, key=lambda n: n.rho * np.trace(n.P[:NX, :NX]))
    xc = best.xhat[:NX].copy()
    Sx = best.rho * best.P[:NX, :NX]

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
