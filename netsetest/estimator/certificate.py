"""The certificate of node i's step and the guaranteed fallback when there is none.

:func:`certify` checks a backend's answer (P, L, τ) in floating point against the S-procedure condition
of the LMI (docs/design.md §2) and returns the ρ' it proves; :func:`publishable` says whether a set can be
published at all; :func:`fallback_shape` bounds the error without any solver (L = 0, a Minkowski sum).
Nothing here trusts a solver: a set is published only with a certificate or as the fallback.
"""

from __future__ import annotations

import math
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
    two answers of the same data): Q (m, d, d), Q reshaped (m, d²), Σ_m Q_m, whether all are finite, each
    Q_m's diagonal (m, d), whether every Q_m is diagonal (the ball facts: then :func:`certify` takes its
    closed form) and each |Q_m|'s row sums (m, d)."""

    Q: np.ndarray
    Qflat: np.ndarray
    Qsum: np.ndarray
    finite: bool
    diag: np.ndarray
    diagonal: bool
    rows: np.ndarray  # (m, d): each |Q_m|'s row sums (:func:`lmi_proven`'s rounding bound)

    @classmethod
    def of(cls, facts: Sequence[np.ndarray]) -> FactStack:
        Q = np.asarray(facts)
        m, d = Q.shape[0], Q.shape[-1]
        flat = Q.reshape(m, -1)
        diag = flat[:, :: d + 1]
        diagonal = np.count_nonzero(flat) == np.count_nonzero(diag)
        return cls(Q, flat, Q.sum(axis=0), bool(np.isfinite(Q).all()), diag, diagonal, np.abs(Q).sum(axis=2))


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

    Where every fact is diagonal (the ball facts: every step without a φ slot), the condition is checked on
    a 4×4 matrix with outward rounding margins (:func:`diagonal_certificate`), else on the d×d one
    (:func:`_dense_certificate`).
    """
    fs = facts if isinstance(facts, FactStack) else FactStack.of(facts)
    if not (fs.finite and _finite(P, pi, tau)):
        return None  # a NaN passes Cholesky silently
    P = 0.5 * (P + P.T)
    if fs.diagonal and P.shape == (3, 3):
        out = diagonal_certificate(P, pi, tau, fs)
        return None if out is None else out[0]
    out = _dense_certificate(P, pi, tau, fs)
    return None if out is None else out[0]


def certified(
    P: np.ndarray, pi: np.ndarray, tau: np.ndarray, facts: Sequence[np.ndarray] | FactStack, xhat: np.ndarray, rho: float
) -> tuple[float, np.ndarray] | None:
    """A set's certificate in one call: ρ' of :func:`certify` and the shape published with it, P·ρ'/ρ (P symmetrised),
    where that set (centre ``xhat``) is :func:`publishable`; None where either fails (a certified set nobody can use is
    no certificate).  The step's solved set and every slab cut are certified here."""
    rho_c = certify(P, pi, tau, facts)
    if rho_c is None:
        return None
    shape = 0.5 * (P + P.T) * rho_c / rho
    return (rho_c, shape) if publishable(xhat, shape) else None


U = linalg.U  # the unit roundoff of float64
RUMP_C = 8.0  # the shift of :func:`rump_definite` is RUMP_C (n + 2) u tr(a): Rump's γ_{n+1}/(1 − 2γ_{n+1}) tr(a) ≈ (n + 1) u tr(a), and then some
RUMP_FLOOR = 1e-290  # its absolute part: Rump's underflow term (a few multiples of the smallest subnormal), and then some
RUMP_MAX = 1e300  # a diagonal entry beyond this: refused (far from any step; no overflow in the scaling)


def rump_definite(a: list[list[float]]) -> bool:
    """Whether the symmetric 4×4 matrix ``a`` (plain floats, its lower triangle read) is proven positive definite.

    First scaled by a power of two per row and column (D a D, exact: no rounding unless an entry becomes subnormal,
    an absolute error far below RUMP_FLOOR) so that its diagonal lies in [1/4, 4); then the floating-point Cholesky
    factorisation of the scaled matrix less cI must run to completion, c = RUMP_C (n + 2) u tr + RUMP_FLOOR (n = 4).
    S. M. Rump, "Verification of positive definiteness", BIT 46 (2006) 433–452: if the floating-point Cholesky
    factorisation of a − cI runs to completion for a c ≥ γ_{n+1}/(1 − 2γ_{n+1}) tr(a) (plus an underflow term), a
    is positive definite, whatever the order of the operations (fused or not).  False is no proof of the opposite.
    Unrolled: the certificate's hot path (:func:`rump_proven`: any n, by one LAPACK Cholesky)."""
    (a00, _, _, _), (a10, a11, _, _), (a20, a21, a22, _), (a30, a31, a32, a33) = a
    if not (a00 > 0.0 and a11 > 0.0 and a22 > 0.0 and a33 > 0.0 and max(a00, a11, a22, a33) < RUMP_MAX):
        return False  # (a NaN fails here too)
    k0, k1, k2, k3 = (-(math.frexp(x)[1] // 2) for x in (a00, a11, a22, a33))
    ld = math.ldexp
    a00, a11, a22, a33 = ld(a00, 2 * k0), ld(a11, 2 * k1), ld(a22, 2 * k2), ld(a33, 2 * k3)
    a10, a20, a30 = ld(a10, k1 + k0), ld(a20, k2 + k0), ld(a30, k3 + k0)
    a21, a31, a32 = ld(a21, k2 + k1), ld(a31, k3 + k1), ld(a32, k3 + k2)
    c = RUMP_C * 6 * U * (a00 + a11 + a22 + a33) + RUMP_FLOOR
    s = a00 - c
    if not s > 0.0:
        return False
    l00 = math.sqrt(s)
    l10, l20, l30 = a10 / l00, a20 / l00, a30 / l00
    s = a11 - c - l10 * l10
    if not s > 0.0:
        return False
    l11 = math.sqrt(s)
    l21, l31 = (a21 - l20 * l10) / l11, (a31 - l30 * l10) / l11
    s = a22 - c - l20 * l20 - l21 * l21
    if not s > 0.0:
        return False
    l22 = math.sqrt(s)
    l32 = (a32 - l30 * l20 - l31 * l21) / l22
    return a33 - c - l30 * l30 - l31 * l31 - l32 * l32 > 0.0


def diagonal_certificate(P: np.ndarray, pi: np.ndarray, tau: np.ndarray, fs: FactStack) -> tuple[float, np.ndarray] | None:
    """:func:`certify` where every Q_m is diagonal, P (3, 3) symmetric: (ρ', τ') with, in exact arithmetic on
    these floats, Πᵀ P⁻¹ Π + Σ τ'_m Q_m ⪯ ρ' e₁e₁ᵀ; None where that is not proven.

    With δ = Σ τ'_m diag(Q_m) and E_k = −δ_k > 0 (k ≥ 1), the condition is, by two Schur complements
    (over P, then over the diagonal block E),

        [[S, π₀], [π₀ᵀ, ρ' − δ₀]] ⪰ 0,   S = P − G,   G = Σ_{k≥1} π_k π_kᵀ / E_k   (π_k: column k of Π),

    and the lower block of the LMI is strictly negative exactly where S ≻ 0.  Rounding: each entry of S as
    computed is within γ (|P_ij| + Σ_k |π_ik||π_jk|/E_k) of the exact one, γ = 2 (d + m + 8) u (E_k's own sum of
    m terms, the quotients, G's sum of d terms, the difference), and Σ_k |π_ik||π_jk|/E_k ≤ (G_ii G_jj)^½ (Cauchy–
    Schwarz), so the error's spectral norm is at most γ (max_i Σ_j |P_ij| + tr G); S is moved down by twice that
    (μ I), δ₀ up by twice its own bound and ρ' − δ₀ rounded down, so the exact matrix is at least the one
    checked, which :func:`rump_definite` proves positive definite.  The multipliers are nudged as :func:`certify`
    says (the first ε whose S has a Cholesky factor in floating point), and ρ' is widened as the d×d check widens
    it.  tests/unit/test_certificate.py holds every answer to an exact rational check."""
    tau = np.maximum(tau, 0.0)
    d, m = pi.shape[1], len(tau)
    gamma2 = 4.0 * (d + m + 8) * U  # 2γ
    rest = pi[:, 1:]
    (p00, p01, p02), (_, p11, p12), (_, _, p22) = P.tolist()
    prow = max(abs(p00) + abs(p01) + abs(p02), abs(p01) + abs(p11) + abs(p12), abs(p02) + abs(p12) + abs(p22))
    for eps in max(1.0, float(tau.max())) * EPS_LADDER:
        t = tau + eps  # τ' (the statement is about these floats)
        delta = t @ fs.diag
        e = -delta[1:]
        if not e.min() > 0.0:
            continue
        (g00, g01, g02), (_, g11, g12), (_, _, g22) = ((rest / e) @ rest.T).tolist()
        mu = gamma2 * (prow + g00 + g11 + g22)
        s00, s01, s02, s11, s12, s22 = p00 - g00 - mu, p01 - g01, p02 - g02, p11 - g11 - mu, p12 - g12, p22 - g22 - mu
        if not s00 > 0.0:  # a Cholesky factor of S in floating point (the proof is the bordered check below)
            continue
        l00 = math.sqrt(s00)
        l10, l20 = s01 / l00, s02 / l00
        a = s11 - l10 * l10
        if not a > 0.0:
            continue
        l11 = math.sqrt(a)
        l21 = (s12 - l20 * l10) / l11
        b = s22 - l20 * l20 - l21 * l21
        if b > 0.0:
            l22 = math.sqrt(b)
            break
    else:
        return None
    q0, q1, q2 = pi[:, 0].tolist()
    y0 = q0 / l00  # π₀ᵀ S⁻¹ π₀ = ‖L⁻¹π₀‖²: an estimate, proven below
    y1 = (q1 - l10 * y0) / l11
    y2 = (q2 - l20 * y0 - l21 * y1) / l22
    delta0 = float(delta[0]) + gamma2 * float(t @ np.abs(fs.diag[:, 0]))  # δ₀ rounded up
    rho_c = (delta0 + (y0 * y0 + y1 * y1 + y2 * y2)) * (1 + 1e-9) + 1e-12
    for _ in range(60):
        corner = rho_c - delta0 - 4.0 * U * (abs(rho_c) + abs(delta0))  # ρ' − δ₀ rounded down
        if rump_definite([[s00, s01, s02, q0], [s01, s11, s12, q1], [s02, s12, s22, q2], [q0, q1, q2, corner]]):
            return (rho_c, t) if rho_c > 0 else None
        rho_c *= 1 + 1e-6
    return None


def rump_proven(a: np.ndarray) -> bool:
    """:func:`rump_definite` of a symmetric n×n float64 array (its lower triangle read), by LAPACK's Cholesky: the same
    power-of-two scaling (exact), the same shift c = RUMP_C (n + 2) u tr + RUMP_FLOOR; Rump's theorem holds for a
    floating-point Cholesky factorisation in any order of its operations, LAPACK's blocked or fused ones too."""
    diag = a.diagonal()
    if not (float(diag.min()) > 0.0 and float(diag.max()) < RUMP_MAX):
        return False  # (a NaN fails here too)
    k = -(np.frexp(diag)[1] >> 1)
    s = np.ldexp(a, k[:, None] + k[None, :])  # D a D, exact
    n = len(diag)
    c = RUMP_C * (n + 2) * U * float(s.trace()) + RUMP_FLOOR
    s.flat[:: n + 1] -= c
    try:
        linalg.cholesky(s)  # (the lower triangle: numpy's cholesky reads it)
    except np.linalg.LinAlgError:
        return False
    return True


def _dense_certificate(P: np.ndarray, pi: np.ndarray, tau: np.ndarray, fs: FactStack) -> tuple[float, np.ndarray] | None:
    """:func:`certify` on the d×d matrix (any facts): (ρ', τ') as :func:`diagonal_certificate` gives them.

    Estimate (LAPACK's Cholesky and solves), as the S-procedure's Schur complements say: K = Πᵀ P⁻¹ Π + Σ τ'_m Q_m
    (Πᵀ P⁻¹ Π = XᵀX, X = C⁻¹Π with C Cᵀ = P), the first ε of the ladder whose lower block −K₂₂ has a Cholesky factor
    in floating point, and ρ' = k₁₁ − kᵀK₂₂⁻¹k widened by a hair.  Proof, on these floats (P, Π, τ' = τ + ε, ρ'),
    :func:`lmi_proven`; where it fails, ρ' is widened by 10⁻⁶ up to 60 times."""
    try:
        chol = linalg.cholesky(P)
    except np.linalg.LinAlgError:
        return None
    x = linalg.solve(chol, pi)  # Πᵀ P⁻¹ Π = xᵀx
    base = x.T @ x
    tau = np.maximum(tau, 0.0)
    scale = max(1.0, float(tau.max()))
    d = base.shape[0]
    for eps in scale * EPS_LADDER:
        t = tau + eps  # τ' (the statement is about these floats)
        K = base + (t @ fs.Qflat).reshape(d, d)
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
    for _ in range(60):
        if lmi_proven(P, pi, t, fs, rho_c):
            return (rho_c, t) if rho_c > 0 else None
        rho_c *= 1 + 1e-6
    return None


def lmi_proven(P: np.ndarray, pi: np.ndarray, t: np.ndarray, fs: FactStack, rho: float, margin: float | None = None) -> bool:
    """Whether, in exact arithmetic on these floats, M = [[P, Π], [Πᵀ, N]] ≻ 0 with N = ρ e₁e₁ᵀ − Σ_m t_m Q_m: the
    S-procedure condition Πᵀ P⁻¹ Π + Σ t_m Q_m ⪯ ρ e₁e₁ᵀ (its Schur complement over P), strictly.

    P and Π enter M exactly.  Each computed entry of N is within γ_{m+1} A_ij of the exact one, A = Σ_m t_m |Q_m| +
    ρ e₁e₁ᵀ (a sum of m + 1 terms, any order, fused or not), so the exact N less the computed one is ⪰ −diag(γ_{m+1} Σ_j
    A_ij) (their difference is diagonally dominant with a non-negative diagonal; every Q_m built here is symmetric).  N's diagonal
    is moved down, row by row, by μ_i = :data:`DENSE_MARGIN` (m + 2) u (A's row sum as computed), at least twice that
    bound (γ_{m+1} < 2 (m + 2) u; the computed row sums are within (m + d) u of theirs), and each moved entry by a
    further 8u of its terms (its own rounding); :func:`rump_proven` proves the moved matrix positive definite, and M
    is at least it.  ``margin``: DENSE_MARGIN unless given (tests/unit/test_certificate.py shrinks it to show that
    it is needed)."""
    n, d = P.shape[0], pi.shape[1]
    low = -(t @ fs.Qflat).reshape(d, d)  # N without ρ
    size = t @ fs.rows  # A's row sums without ρ
    size[0] += abs(rho)
    mu = (DENSE_MARGIN if margin is None else margin) * (len(t) + 2) * U * size  # per row
    m = np.empty((n + d, n + d))
    m[:n, :n], m[n:, :n], m[:n, n:] = P, pi.T, pi
    m[n:, n:] = low
    dg = low.diagonal().copy()
    dg[0] += rho
    slack = 8.0 * U if margin is None else 8.0 * U * (margin / DENSE_MARGIN)
    dg -= mu * (1.0 + 4.0 * U) + slack * np.abs(low.diagonal())
    dg[0] -= slack * abs(rho)
    m.flat[n * (n + d + 1) :: n + d + 1] = dg
    return rump_proven(m)


DENSE_MARGIN = 4.0  # μ_i = DENSE_MARGIN (m + 2) u (row i's sum of A): γ_{m+1} < 2 (m + 2) u, so at least twice the error bound


COND_MAX = 1e13  # largest eigenvalue ratio of a published shape: beyond it E = eᵀP⁻¹e is rounding noise
FALLBACK_INFLATE = 1e-9  # relative: makes a rank-deficient Minkowski bound positive definite


class FallbackUnavailable(ArithmeticError):
    """Even the guaranteed fallback ellipsoid is not representable (the profile's magnitudes are out of range)."""


def publishable(xhat: np.ndarray, P: np.ndarray) -> bool:
    """A centre and shape a node may publish: finite, symmetric positive definite, not degenerate."""
    if not (np.isfinite(xhat).all() and np.isfinite(P).all()) or not np.array_equal(P, P.T):
        return False
    if P.shape == (3, 3) and _clearly_conditioned(P.tolist()):
        return True  # (most shapes: no eigen decomposition then)
    try:
        eig = linalg.eigvalsh(P)
    except np.linalg.LinAlgError:
        return False
    # (no Cholesky besides: with every eigenvalue > 0 and the ratio ≤ COND_MAX, far below 1/ε, it cannot fail)
    return bool(eig[0] > 0 and eig[-1] <= COND_MAX * eig[0])


CLEAR = 1e-6  # relative: a leading minor this far above its rounding bound has its computed sign


def _clearly_conditioned(p: list[list[float]]) -> bool:
    """Whether the symmetric 3×3 ``p`` (finite plain floats) is positive definite with an eigenvalue ratio at most half
    COND_MAX, by its leading minors (Sylvester) and λ_max / λ_min ≤ tr³ / (4 det) (λ_max ≤ tr, and λ_min ≥ 4 det / tr²
    since the other two multiply to at most (tr/2)²), each minor clearly above its rounding (a sum of k products of
    3 factors at most is within 8 k u of its terms' magnitude).  True implies what the eigenvalues would say; False
    says nothing (:func:`publishable` then asks them)."""
    (a, b, c), (_, d, e), (_, _, f) = p
    m2, m2_size = a * d - b * b, abs(a * d) + b * b
    det = a * (d * f - e * e) - b * (b * f - e * c) + c * (b * e - d * c)
    size = abs(a) * (abs(d * f) + e * e) + abs(b) * (abs(b * f) + abs(e * c)) + abs(c) * (abs(b * e) + abs(d * c))
    tr = a + d + f
    return a > 0.0 and m2 > CLEAR * m2_size and det > CLEAR * size and tr * tr * tr <= 2.0 * COND_MAX * det


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


__all__ = ["COND_MAX", "FactStack", "FallbackUnavailable", "certified", "certify", "fallback_shape", "publishable"]
