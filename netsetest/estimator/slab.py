"""A certified ellipsoid cut by a proven interval of one combination cᵀx̄ (docs/estimator.md, "One step": the
`fault-size` cut; docs/network.md, "How the SDP uses it": the readings carried in the recursion).

Given the step's certified set E = {x̄: (x̄ − x̂)ᵀ(ρP)⁻¹(x̄ − x̂) ≤ 1} and an interval l ≤ cᵀx̄ ≤ u that the
truth is proven to lie in (the declared fault size |f⁺| ≤ F: c = e₃; a reading's interval of C̄ x̄), every
point of E ∩ {l ≤ cᵀx̄ ≤ u} satisfies, for any λ ≥ 0,

    (x̄ − x̂)ᵀ(ρP)⁻¹(x̄ − x̂) + λ (cᵀx̄ − l)(cᵀx̄ − u) ≤ 1

(the product is ≤ 0 inside the interval): an S-procedure with two facts, the ellipsoid and the slab.  The
left side is again an ellipsoid.  With Σ = ρP, s = cᵀΣc, m = (l + u)/2, h = (u − l)/2, d = m − cᵀx̂ and
t = λ/(1 + λs) ∈ [0, 1/s):

    centre  x̂ + t d Σc,     shape  r (Σ − t Σc cᵀΣ),     r = 1 + h² t/(1 − ts) − d² t,

whose half-width along c tends to h as t → 1/s while the other directions grow with r.  :func:`cut` picks t
minimising the step's objective trace(D Σ') on a grid and certifies the answer with the estimator's own
:func:`~netsetest.estimator.certificate.certified` (η = [1, u], x̄ = x̂ + (ρP)^½ u, facts 1 − uᵀu ≥ 0 and
the slab), so a rounding error in the closed form costs a larger ρ', never a set that misses the truth.
"""

from __future__ import annotations

import numpy as np

import netsetest.linalg as linalg

from netsetest.estimator.certificate import certified
from netsetest.models.sensor import NA
from netsetest.sets import Slab

GRID = np.linspace(0.0, 1.0, 257)[:-1]  # t·s over [0, 1): the grid the objective is minimised on
MIN_GAIN = 1e-6  # relative: a cut that gains less than this in the objective is not worth a new set


def _facts(lo: float, hi: float, row: np.ndarray, xk: float) -> list[np.ndarray]:
    """The facts over η = [1, u] (u ∈ R^NA): 1 − uᵀu ≥ 0 and (cᵀx̄ − lo)(hi − cᵀx̄) ≥ 0, cᵀx̄ = xk + row·u."""
    d = NA + 1
    ball = np.zeros((d, d))
    ball[0, 0] = 1.0
    ball[1:, 1:] = -np.eye(NA)
    a = np.append(xk, row)  # cᵀx̄ = aᵀη
    b0 = np.zeros(d)
    b0[0] = 1.0
    # (aᵀη − lo·η₀)(hi·η₀ − aᵀη) = −(aᵀη)² + (lo + hi) η₀ aᵀη − lo·hi η₀²
    slab = -np.outer(a, a) + 0.5 * (lo + hi) * (np.outer(a, b0) + np.outer(b0, a)) - lo * hi * np.outer(b0, b0)
    return [ball, slab]


def cut(xhat: np.ndarray, P: np.ndarray, rho: float, slab: Slab, weights: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(x̂', P', ρ') with E' = {(x̄ − x̂')ᵀP'⁻¹(x̄ − x̂') ≤ ρ} ⊇ E ∩ {lo ≤ cᵀx̄ ≤ hi} (c (NA,); a coordinate k:
    c = e_k), certified, minimising trace(D ρP') (ρ' the certified radius of the closed form's shape,
    P' = shape·ρ'/ρ) (D = diag(weights), None: I); None if the interval does not cut E or nothing is gained."""
    c, lo, hi = slab.a, slab.lo, slab.hi
    sigma = rho * 0.5 * (P + P.T)
    se = sigma @ c  # Σc
    s = float(c @ se)
    if not (s > 0.0 and np.isfinite(lo) and np.isfinite(hi)):
        return None
    half = np.sqrt(s)
    xc = float(c @ xhat)
    lo, hi = max(lo, xc - half), min(hi, xc + half)  # the interval within E's own range
    if not hi > lo or (hi - lo) >= 2.0 * half * (1.0 - MIN_GAIN):
        return None  # no cut (an empty one means the assumptions broke: the step's set stays as certified)
    w = np.ones(NA) if weights is None else np.asarray(weights, dtype=float)
    h, dd = 0.5 * (hi - lo), 0.5 * (hi + lo) - xc
    t = GRID / s
    r = 1.0 + h * h * t / (1.0 - GRID) - dd * dd * t
    obj = r * (float(w @ np.diag(sigma)) - t * float(w @ (se * se)))
    best = int(np.argmin(obj))
    if best == 0 or obj[best] >= (1.0 - MIN_GAIN) * obj[0]:
        return None
    tb = float(t[best])
    centre = xhat + tb * dd * se
    shape = float(r[best]) * (sigma - tb * np.outer(se, se))  # ρ P' before certification
    # certificate: e = x̄ − x̂' = (x̂ − x̂') + M u over η = [1, u]; eᵀ(ρP')⁻¹e + (1 − uᵀu)/r + λ·slab/r = 1
    M = linalg.covering_factor(P, rho)  # M Mᵀ ⪰ ρP exactly: x̄ = x̂ + M u covers the whole of E
    pi = np.concatenate([(xhat - centre)[:, None], M], axis=1)
    lam = tb / (1.0 - tb * s)
    facts = _facts(lo, hi, c @ M, xc)
    shape = 0.5 * (shape + shape.T)
    rb = float(r[best])
    out = certified(shape, pi, np.array([1.0 / rb, lam / rb]), facts, centre, rho)  # P' = shape·ρ'/ρ, publishable
    return None if out is None else (centre, out[1], out[0])


__all__ = ["cut"]
