"""Can a neighbour's state be honest?  Exact tests a node applies before it uses one (it only drops).

Node i uses neighbour j's step-k message through the facts of its S-procedure (netsetest.estimator.sdp):
the innovation enters as

    y̌_j = (γ_j h1_j − 1) C̄_j x̂_j + γ_j h1_j c_j s_j + γ_j φ_j + Dv_j v_j,   c_j = (ρ_j C̄_j P_j C̄_jᵀ)^½,

with |s_j| ≤ 1, v_j² ≤ R_j and φ_j in the sector [0, h_j r_j] (h = h2 − h1) of r_j = C̄_j x̂_j + c_j s_j
(no φ_j for an unsaturated sensor: h1 = h2 = 1).  h1_j and h_j are the sector j published with this
message (``NodeState.sector``, derived per step: netsetest.estimator.sector), the very numbers node i's
facts use for j; the test below takes them from there, so it stays exact for a per-step sector.  s_j, v_j and φ_j enter e⁺ only through this sum, so
node i's guarantee holds for *any* message whose innovation some admissible (s_j, v_j, φ_j) produces —
honest or not.  Writing r = C̄_j x̂_j + c_j s_j, the sum plus C̄_j x̂_j is γ_j·σ + Dv_j v_j with σ between
h1 r and h2 r, so the innovations the message can honestly carry form the interval

    [γ_j · lo(r_min) − |Dv_j|√R_j,  γ_j · hi(r_max) + |Dv_j|√R_j] − C̄_j x̂_j,
    r_min,max = C̄_j x̂_j ∓ c_j,   lo(r) = min(h1 r, h2 r),   hi(r) = max(h1 r, h2 r)

(lo and hi are monotone in r).  :func:`innovation_possible` is that test, without tolerance: an
innovation outside it cannot come from an honest neighbour whose set holds the truth, and using it
would void the guarantee; dropping it is always sound (its η slots are zeroed).

:func:`states_disjoint` is the second test: the (β, r) part of the neighbour's ellipsoid and of node i's
own certified ellipsoid of the same step both contain the true state when the assumptions hold, so if
they are disjoint one of them is wrong — node i then leaves the neighbour out (sound either way).
"""

from __future__ import annotations

import math

import numpy as np

from netsetest.estimator.sector import Sector
from netsetest.models.sensor import NX, Sensor

DISJOINT_MARGIN = 1e-9  # relative: call two ellipses disjoint only when clearly so (rounding)
LAMBDA_GRID = np.linspace(0.005, 0.995, 199)  # any λ ∈ (0, 1) gives a valid separation certificate


def innovation_interval(sensor: Sensor, xhat: np.ndarray, P: np.ndarray, rho: float, gamma: float, sector: Sector | None) -> tuple[float, float]:
    """The innovations y̌ = ỹ − C̄ x̂ a sensor with this published ellipsoid, sector and noise bound can
    produce; ``sector`` None: the sensor's fixed h1, h2 (1, 1 for a sensor without saturation)."""
    # scalar arithmetic on the 3-vectors: a node runs this for every neighbour message, and numpy's
    # per-call overhead on 3×3 data is most of the cost
    # (unrolled, and tolist() rather than a comprehension: the comprehensions were most of its cost)
    c0, c1, c2 = float(sensor.C[0]), float(sensor.C[1]), float(sensor.Ds)
    x0, x1, x2 = np.asarray(xhat, dtype=float).tolist()
    (p00, p01, p02), (p10, p11, p12), (p20, p21, p22) = np.asarray(P, dtype=float).tolist()
    cx = c0 * x0 + c1 * x1 + c2 * x2
    pc0, pc1, pc2 = p00 * c0 + p01 * c1 + p02 * c2, p10 * c0 + p11 * c1 + p12 * c2, p20 * c0 + p21 * c1 + p22 * c2
    cpc = c0 * pc0 + c1 * pc1 + c2 * pc2
    c = math.sqrt(max(rho * cpc, 0.0))
    r_lo, r_hi = cx - c, cx + c
    h1, h2 = (sector.h1, sector.h1 + sector.h) if sector is not None else (sensor.h1, sensor.h2)
    noise = abs(sensor.Dv) * math.sqrt(sensor.R)
    lo = gamma * min(h1 * r_lo, h2 * r_lo) - noise - cx
    hi = gamma * max(h1 * r_hi, h2 * r_hi) + noise - cx
    return lo, hi


def innovation_possible(sensor: Sensor, xhat: np.ndarray, P: np.ndarray, rho: float, gamma: float, sector: Sector | None, innov: float) -> bool:
    lo, hi = innovation_interval(sensor, xhat, P, rho, gamma, sector)
    return bool(lo <= innov <= hi)


def states_disjoint(x1: np.ndarray, P1: np.ndarray, rho1: float, x2: np.ndarray, P2: np.ndarray, rho2: float) -> bool:
    """Whether the (β, r) projections of two ellipsoids {x: (x − x̂)ᵀP⁻¹(x − x̂) ≤ ρ} are disjoint.

    For λ ∈ (0, 1), (1−λ)q₁(x) + λq₂(x) ≤ 1 on the intersection, and its minimum over x is
    dᵀ(A₁/(1−λ) + A₂/λ)⁻¹d with d = c₂ − c₁ and A the projected shapes ρ P[:2, :2]; a minimum above 1
    for some λ proves the sets disjoint.  Only such a proof (with a margin) returns True.
    """
    if _overlap_bound(np.asarray(P1).tolist(), rho1, np.asarray(P2).tolist(), rho2, float(x2[0]) - float(x1[0]), float(x2[1]) - float(x1[1])) <= 1.0:
        return False  # no λ can prove disjointness (the common case: honest neighbours overlap)
    A1 = rho1 * np.asarray(P1)[:NX, :NX]
    A2 = rho2 * np.asarray(P2)[:NX, :NX]
    d = np.asarray(x2)[:NX] - np.asarray(x1)[:NX]
    # S(λ) = A₁/(1−λ) + A₂/λ for every λ of the grid at once; dᵀS⁻¹d by the 2×2 adjugate
    S = A1[None] / (1.0 - LAMBDA_GRID)[:, None, None] + A2[None] / LAMBDA_GRID[:, None, None]
    det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] * S[:, 1, 0]
    num = d[0] ** 2 * S[:, 1, 1] - d[0] * d[1] * (S[:, 0, 1] + S[:, 1, 0]) + d[1] ** 2 * S[:, 0, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        val = num / det
    ok = np.isfinite(val) & (det > 0)
    return bool(np.any(val[ok] > 1.0 + DISJOINT_MARGIN))


def _overlap_bound(p1: list[list[float]], rho1: float, p2: list[list[float]], rho2: float, d0: float, d1: float) -> float:
    """dᵀ(A₁ + A₂)⁻¹d, an upper bound of dᵀS(λ)⁻¹d for every λ ∈ (0, 1): S(λ) = A₁/(1−λ) + A₂/λ ⪰ A₁ + A₂
    ≻ 0, so S(λ)⁻¹ ⪯ (A₁ + A₂)⁻¹.  At most 1: no λ proves the sets disjoint (+inf if A₁ + A₂ is not
    definite, which leaves the decision to the full test).  Plain floats (the P's as nested lists, d = c₂ − c₁
    over β, r): the same roundings as the arrays' ρP[:2, :2] sums, without numpy's per-call cost, and every
    node runs it for every neighbour state it keeps."""
    a, b = rho1 * p1[0][0] + rho2 * p2[0][0], rho1 * p1[0][1] + rho2 * p2[0][1]  # A₁ + A₂ = [[a, b], [c, e]]
    c, e = rho1 * p1[1][0] + rho2 * p2[1][0], rho1 * p1[1][1] + rho2 * p2[1][1]
    det = a * e - b * c
    if not det > 0.0 or not a > 0.0:
        return math.inf
    return (d0 * d0 * e - d0 * d1 * (b + c) + d1 * d1 * a) / det
