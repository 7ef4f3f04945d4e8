"""The scheduled problem without sector facts (NSNIM) in closed form over τ, by Newton's method over L.

The pure SOCP of :mod:`netsetest.estimator.conic` (no LMI block: every fact is a ball) is

    minimise Σ_g a_g(L)² / τ_g   over L ∈ R³, τ ≥ 0 with Σ_g τ_g ≤ ρ

where g runs over the ball groups (a_g = √β_g ‖Π₀_g − L ℓ_gᵀ‖_F), ξ (a_ξ = B ‖L‖) and, when ℓ₀ ≠ 0, the η₁
slot (a₀ = |ℓ₀| ‖L‖, its multiplier λ₀ = ρ − Σ τ).  For a fixed L the best multipliers are
τ_g = ρ a_g / Σ a (Cauchy–Schwarz), with the value (Σ_g a_g(L))² / ρ, so the problem is the convex
sum of norms

    F(L) = Σ_g ‖M_g − L b_gᵀ‖_F + c ‖L‖,   M_g = √β_g Π₀_g, b_g = √β_g ℓ_g, c = B + |ℓ₀|,

in three unknowns.  L = 0 is the minimum when the innovations' information costs more than their noise
(a subgradient test; on the paper's NSNIM data it is, on every step); elsewhere F is smooth unless a term
vanishes, and damped Newton from the least-squares gain converges in a few steps.  A minimum where a
term vanishes (a group with M_g = L b_gᵀ: the readings' update often has its minimum there) would
stall Newton; each such point is tested first like L = 0: it is the minimum if the rest's gradient
there is at most ‖b_g‖ long.  A minimum close to a kink but off it can still draw Newton onto the kink,
its steps ever shorter: it gives up there (KINK_NEAR, STALL_HALVINGS).  Nothing here is trusted: the answer is mapped back exactly
as Clarabel's is and certified against the LMI like every answer (:func:`~netsetest.estimator.certificate.certify`);
where Newton does not converge, or a term vanishes, the caller solves with Clarabel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import netsetest.linalg as linalg

MAX_NEWTON = 50  # iterations (quadratic convergence near the minimum; damped steps before)
MAX_HALVINGS = 40  # Armijo backtracking
WARM_HALVINGS = 10  # from a warm start: a step cut this often means Newton is stalling at a kink (the cold start is tried)
ARMIJO = 1e-4
DECREMENT_TOL = 1e-12  # converged: the Newton decrement (≈ 2 (F − min F)) this small relative to F
ROUNDING_TOL = 1e-8  # no descent left to rounding and a decrement this small: converged as far as F can tell
TINY = 1e-290  # a term this small is treated as vanished (F is not smooth there)
KINK_TOL = 1e-9  # a group's term counts as vanishing at its own least-squares L below this (relative); margin of the test
KINK_NEAR = 1e-6  # a term this small (relative to F) while the line search needs STALL_HALVINGS: Newton is creeping onto its kink
STALL_HALVINGS = 10
KINK_FLOOR = 1e-12  # the vanished term's norm used for its multiplier (relative): its columns of Π are ~0


@dataclass(frozen=True)
class SumOfNorms:
    """F(L) = Σ_g ‖M_g − L b_gᵀ‖_F + c ‖L‖ with the groups' columns side by side: M (NA, n), b (n,), the
    group of each column ``onehot`` (n, G)."""

    M: np.ndarray
    b: np.ndarray
    onehot: np.ndarray
    c: float

    def value(self, L: np.ndarray) -> float:
        R = self.M - L[:, None] * self.b[None, :]
        return float(np.sqrt((R * R).sum(axis=0) @ self.onehot).sum() + self.c * np.sqrt(L @ L))

    def minimise(self, start: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, float, int] | None:
        """(L, the group norms a_g, ‖L‖, iterations) at the minimum, or None (a vanished term, no convergence).

        L = 0 (no use for the innovations) is the minimum exactly when the gradient of the groups' part there
        is at most c long: then c‖L‖'s subgradient cancels it (found without iterating).  Else Newton starts
        from ``start`` (a warm start: the last step's gain), and from the least-squares gain Σ M_g b_g / Σ ‖b_g‖²
        (the minimiser of the squared terms) if there is none or it stalls: a warm start next to a term's kink
        (the last minimum close to a vanished term) drives Newton onto the kink, where its steps shrink to
        nothing (paper6_max_faulty's readings' update: 1 step in 12 fell back to Clarabel that way)."""
        r0 = np.sqrt((self.M * self.M).sum(axis=0) @ self.onehot)
        if r0.min() <= TINY:
            return None
        g0 = ((self.M * self.b[None, :]) @ self.onehot) @ (1.0 / r0)  # −∇ of Σ_g ‖M_g − L b_gᵀ‖ at L = 0
        if float(np.sqrt(g0 @ g0)) <= self.c:
            return np.zeros_like(g0), r0, 0.0, 0
        kink = self._kink()  # a minimum where a term vanishes: Newton would stall there
        if kink is not None:
            return kink
        if start is not None:  # a warm start next to a term's kink can stall Newton: then from the cold start
            found = self._newton(start.copy(), WARM_HALVINGS)
            if found is not None:
                return found
        return self._newton((self.M @ self.b) / float(((self.b * self.b) @ self.onehot).sum()), MAX_HALVINGS)

    def _newton(self, L: np.ndarray, max_halvings: int) -> tuple[np.ndarray, np.ndarray, float, int] | None:
        """Damped Newton from ``L``: the minimum, or None (a vanished term, no convergence, or a line search
        that needed more than ``max_halvings`` halvings without being converged as far as F can tell)."""
        nb = (self.b * self.b) @ self.onehot  # ‖b_g‖²
        eye = np.eye(L.shape[0])
        for it in range(1, MAX_NEWTON + 1):
            R = self.M - L[:, None] * self.b[None, :]
            r = np.sqrt((R * R).sum(axis=0) @ self.onehot)
            ln = float(np.sqrt(L @ L))
            if r.min() <= TINY or (self.c > 0.0 and ln <= TINY):
                return None
            W = (R * self.b[None, :]) @ self.onehot  # R_g b_g, (NA, G)
            F = float(r.sum() + self.c * ln)
            grad = -(W @ (1.0 / r))  # ∇ ‖M_g − L b_gᵀ‖ = −R_g b_g / r_g
            H = float((nb / r).sum()) * eye - (W / r**3) @ W.T
            if self.c > 0.0:
                u = L / ln
                grad = grad + self.c * u
                H = H + (self.c / ln) * (eye - np.outer(u, u))
            try:
                step = linalg.solve(H, -grad)
            except np.linalg.LinAlgError:
                return None
            dec = -float(grad @ step)  # the Newton decrement² (H ≻ 0 for a convex F with no vanished term)
            if not np.isfinite(dec) or dec < 0.0:
                return None
            if dec <= DECREMENT_TOL * F:
                return L, r, ln, it
            t = 1.0
            for halvings in range(max_halvings):
                if self.value(L + t * step) <= F - ARMIJO * t * dec:
                    break
                t *= 0.5
            else:
                return (L, r, ln, it) if dec <= ROUNDING_TOL * F else None
            if halvings >= STALL_HALVINGS and r.min() <= KINK_NEAR * F:
                return None  # creeping onto a term's kink, which minimise's test ruled out as the minimum: it would stall there
            L = L + t * step
        return None

    def _kink(self) -> tuple[np.ndarray, np.ndarray, float, int] | None:
        scale = float(np.abs(self.M).max(initial=0.0))
        for g in range(self.onehot.shape[1]):
            cols = self.onehot[:, g] > 0
            bg, Mg = self.b[cols], self.M[:, cols]
            nb2 = float(bg @ bg)
            if nb2 <= TINY:
                continue
            L = Mg @ bg / nb2  # the least-squares L of the group alone: its term vanishes there if Mg is rank one along bg
            if float(np.abs(Mg - L[:, None] * bg[None, :]).max()) > KINK_TOL * max(scale, TINY):
                continue
            R = self.M - L[:, None] * self.b[None, :]
            r = np.sqrt((R * R).sum(axis=0) @ self.onehot)
            others = np.arange(len(r)) != g
            if r[others].min(initial=np.inf) <= TINY:
                continue
            W = (R * self.b[None, :]) @ self.onehot
            grad = -(W[:, others] @ (1.0 / r[others]))  # ∇ of the other groups' terms
            ln = float(np.sqrt(L @ L))
            if self.c > 0.0:
                if ln <= TINY:
                    continue
                grad = grad + self.c * L / ln
            if float(np.sqrt(grad @ grad)) <= np.sqrt(nb2) * (1.0 - KINK_TOL):  # 0 ∈ ∂F(L): the minimum
                r[g] = max(float(r[g]), KINK_FLOOR * max(scale, TINY))  # its multiplier share: positive, negligible
                return L, r, ln, 0
        return None


__all__ = ["SumOfNorms"]
