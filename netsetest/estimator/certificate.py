"""The certificate of node i's step and the guaranteed fallback when there is none.

:func:`certify` checks a backend's answer (P, L, τ) in floating point against the S-procedure condition
of the LMI (docs/design.md §2) and returns the ρ' it proves; :func:`publishable` says whether a set can be
published at all; :func:`fallback_shape` bounds the error without any solver (L = 0, a Minkowski sum).
Nothing here trusts a solver: a set is published only with a certificate or as the fallback.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

import netsetest.linalg as linalg

from netsetest.estimator.problem import OwnUpdate
from netsetest.models.sensor import NA, NX
from netsetest.models.uncertainty import ModelUncertainty


EPS_LADDER = 10.0 ** np.arange(-10.0, -2.0)  # relative nudges of the multipliers, smallest first


@dataclass(frozen=True)
class FactStack:
    """A step's facts Q_m stacked once, for every certificate of that step (objective ``bank`` certifies
    two answers of the same data): Q (m, d, d), Q reshaped (m, d²), Σ_m Q_m, and whether all are finite."""

    Q: np.ndarray
    Qflat: np.ndarray
    Qsum: np.ndarray
    finite: bool

    @classmethod
    def of(cls, facts: Sequence[np.ndarray]) -> FactStack:
        Q = np.asarray(facts)
        return cls(Q, Q.reshape(Q.shape[0], -1), Q.sum(axis=0), bool(np.isfinite(Q).all()))


def _finite(*arrays: np.ndarray) -> bool:
    return all(np.isfinite(a).all() for a in arrays)


def certify(P: np.ndarray, pi: np.ndarray, tau: np.ndarray, facts: Sequence[np.ndarray] | FactStack) -> float | None:
    """Smallest ρ' (up to rounding) with Πᵀ P⁻¹ Π + Σ τ_m Q_m ⪯ ρ' e₁e₁ᵀ, or None if there is none.

    This is the S-procedure condition itself, checked in floating point on the solver's answer: then
    for the truth eᵀP⁻¹e ≤ ρ' and the published shape P·ρ'/ρ_i satisfies eᵀ(·)⁻¹e ≤ ρ_i.  The
    multipliers are nudged up by the smallest ε in 1e-10, 1e-9, … (relative) that makes the lower block
    strictly negative: every η slot other than the first has a strictly negative diagonal in some Q_m,
    so a solver answer that is feasible up to its tolerance becomes strictly feasible there, at a cost
    of O(ε) in ρ'.
    """
    fs = facts if isinstance(facts, FactStack) else FactStack.of(facts)
    if not (fs.finite and _finite(P, pi, tau)):
        return None  # a NaN passes Cholesky silently
    P = 0.5 * (P + P.T)
    try:
        chol = linalg.cholesky(P)
    except np.linalg.LinAlgError:
        return None
    x = linalg.solve(chol, pi)  # Πᵀ P⁻¹ Π = xᵀx
    base = x.T @ x
    tau = np.maximum(tau, 0.0)
    scale = max(1.0, float(tau.max()))
    d = base.shape[0]
    K0 = base + np.dot(tau.reshape(1, -1), fs.Qflat).reshape(d, d)  # Σ τ_m Q_m, exactly as np.tensordot(tau, Q, 1)
    for eps in scale * EPS_LADDER:
        K = K0 + eps * fs.Qsum
        K = 0.5 * (K + K.T)
        k11, k, K22 = K[0, 0], K[1:, 0], K[1:, 1:]
        try:
            c22 = linalg.cholesky(-K22)
            break
        except np.linalg.LinAlgError:
            continue
    else:
        return None
    y = linalg.solve(c22, k)
    rho_c = float(k11 + y @ y)  # Schur complement: K − ρ' e₁e₁ᵀ ⪯ 0 ⇔ K22 ≺ 0 and ρ' ≥ k11 − kᵀK22⁻¹k
    rho_c = rho_c * (1 + 1e-9) + 1e-12
    for _ in range(60):  # confirm with eigenvalues; widen by a hair if rounding says otherwise
        Kc = K.copy()
        Kc[0, 0] -= rho_c
        if linalg.eigvalsh(Kc)[-1] <= 0.0:
            return rho_c if rho_c > 0 else None
        rho_c *= 1 + 1e-6
    return None


COND_MAX = 1e13  # largest eigenvalue ratio of a published shape: beyond it E = eᵀP⁻¹e is rounding noise
FALLBACK_INFLATE = 1e-9  # relative: makes a rank-deficient Minkowski bound positive definite


class FallbackUnavailable(ArithmeticError):
    """Even the guaranteed fallback ellipsoid is not representable (the profile's magnitudes are out of range)."""


def publishable(xhat: np.ndarray, P: np.ndarray) -> bool:
    """A centre and shape a node may publish: finite, symmetric positive definite, not degenerate."""
    if not (np.isfinite(xhat).all() and np.isfinite(P).all()) or not np.array_equal(P, P.T):
        return False
    try:
        eig = linalg.eigvalsh(P)
    except np.linalg.LinAlgError:
        return False
    # (no Cholesky besides: with every eigenvalue > 0 and the ratio ≤ COND_MAX, far below 1/ε, it cannot fail)
    return bool(eig[0] > 0 and eig[-1] <= COND_MAX * eig[0])


def fallback_shape(Mi: np.ndarray, own: OwnUpdate, W: float, abar: np.ndarray, dbar: np.ndarray, uncertainty: ModelUncertainty | None = None) -> np.ndarray:
    """A guaranteed shape without the solver: L = 0 and an outer ellipsoid of a Minkowski sum.

    ``abar``, ``dbar``: the step's blended Ā (NA, NA) and D̄ (NA,) over x̄ = (x, f) (the step's Blend).
    e⁺ = T Ā ρ^½ M z + T D̄ w − G Dv v⁺ − G γ⁺ φ⁺ with |z| ≤ 1, |w| ≤ √W, |v⁺| ≤ √R and, under the sector
    assumption |C̄ x̄⁺| ≤ r_max/h1, |φ⁺| ≤ (1 − h1) r_max; plus T [G; 0] ζ for a declared model mismatch
    (one term per ball of ζ, docs/plant.md).  For terms F_k ξ_k with |ξ_k| ≤ 1 the sum lies
    in {e: eᵀ(Σ F_kF_kᵀ/p_k)⁻¹e ≤ 1} for any p_k > 0 with Σ p_k = 1; p_k ∝ ‖F_k‖_F minimises the trace.

    Computed scale-free (each term divided by its largest entry before squaring) so that magnitudes up to
    the schema's limits neither overflow nor underflow; raises :class:`FallbackUnavailable` when an input
    or the result is not finite (a profile outside those limits) — never a silently wrong shape.
    """
    T, G, gamma_new, sensor = own.T, own.G, own.gamma, own.sensor
    terms = [T @ abar @ Mi, (T @ dbar * np.sqrt(W))[:, None], G * sensor.Dv * np.sqrt(sensor.R)]
    if uncertainty is not None:
        ebar = np.zeros((NA, NX))
        ebar[:NX] = uncertainty.G
        terms += [T @ ebar[:, list(ball)] for ball in uncertainty.balls]
    if sensor.saturated:
        terms.append(G * gamma_new * (1.0 - sensor.h1) * sensor.r_max)
    if not all(np.all(np.isfinite(f)) for f in terms):
        raise FallbackUnavailable("a term of the fallback bound is not finite")
    scales = [float(np.max(np.abs(f))) for f in terms]
    live = [(f / s, s) for f, s in zip(terms, scales) if s > 0]
    if not live:
        raise FallbackUnavailable("every term of the fallback bound is zero")
    unit = [(u, s, float(np.linalg.norm(u))) for u, s in live]  # ‖F‖_F = s ‖F/s‖_F, ‖F/s‖_F ∈ [1, √9]
    total = sum(s * n for _, s, n in unit)
    # Σ_k F_kF_kᵀ / p_k with p_k = s_k n_k / total:  = total · Σ_k (s_k / n_k) U_k U_kᵀ
    with np.errstate(over="ignore", invalid="ignore"):  # overflow is detected below, not warned about
        shape = total * sum((s / n) * (u @ u.T) for u, s, n in unit)
        shape = 0.5 * (shape + shape.T)
        trace = float(np.trace(shape))
    if not (np.all(np.isfinite(shape)) and np.isfinite(trace)):
        raise FallbackUnavailable("the fallback bound overflows")
    # a rank-deficient sum is still an outer bound once inflated a little in every direction
    return shape + FALLBACK_INFLATE * max(trace, np.finfo(float).tiny / FALLBACK_INFLATE) * np.eye(NA)


__all__ = ["COND_MAX", "FactStack", "FallbackUnavailable", "certify", "fallback_shape", "publishable"]
