"""The reduced problem without an LMI block (NSNIM, scheduled) solved in closed form over τ and by Newton over
L (:class:`~netsetest.estimator.sum_of_norms.SumOfNorms`), with Clarabel where that finds no answer; and the
choice of the ``clarabel`` backend's solver for a node (:func:`clarabel_backend`).

The answer is mapped back as Clarabel's is (:meth:`~netsetest.estimator.conic.reduction.Reduction.after`) and
certified like every answer: τ_g = ρ a_g / Σ a, P = Σ_g β_g Π_gΠ_gᵀ/τ_g + (B²/τ_ξ + ℓ₀²/λ₀) L Lᵀ.
"""

from __future__ import annotations

import numpy as np

from netsetest.estimator.conic.reduction import Aggregate, Reduction
from netsetest.estimator.conic.solver import ConicSolver
from netsetest.estimator.problem import EtaLayout, Solution, StepData
from netsetest.estimator.sum_of_norms import SumOfNorms
from netsetest.models.sensor import NA

CLOSED_FORM_STATUS = "Solved (closed form)"


class ClosedFormSolver:
    """The pure SOCP of a reduction with no LMI block by its closed form; Clarabel (``fallback``, the same
    reduction) where Newton does not converge or a term vanishes."""

    def __init__(self, red: Reduction) -> None:
        assert red.closed_form, "the closed form needs a problem without an LMI block"
        self.red = red
        self.fallback = ConicSolver(red)
        # the groups' columns side by side, scaled by √β: F(L) = Σ_g ‖M_g − L b_gᵀ‖ + c‖L‖ (sum_of_norms.py)
        self._cols = np.array([s for g in red.groups for s in g.slots], dtype=int)
        self._col_sqrtb = red.scale[self._cols]
        self._onehot = np.zeros((len(self._cols), len(red.groups)))
        self._onehot[np.arange(len(self._cols)), [k for k, g in enumerate(red.groups) for _ in g.slots]] = 1.0
        self._facts = [g.fact for g in red.groups]

    def solve(self, data: StepData, rho: float) -> Solution:
        """The step's answer in closed form, else from Clarabel (the step's ξ and scales computed once for both: one call
        into the reduction before the solve, one after it)."""
        scales = self.red.before(data.ell, data.facts)
        sol = self._closed_form(data, rho, scales.agg)
        return sol if sol is not None else self.fallback.solve(data, rho, scales)

    def _closed_form(self, data: StepData, rho: float, agg: Aggregate) -> Solution | None:
        """Newton over L, then τ_g = ρ a_g / Σ a and the smallest P; None if there is no minimum to trust."""
        ell, pi0 = data.ell, data.pi0[0]
        ell0 = abs(float(ell[0]))
        B = agg.B if agg.use_xi else 0.0
        sqrtb = self._col_sqrtb
        problem = SumOfNorms(pi0[:, self._cols] * sqrtb, ell[self._cols] * sqrtb, self._onehot, B + ell0)
        found = problem.minimise()
        if found is None:
            return None
        L, a, ln, iterations = found
        a_xi, a0 = B * ln, ell0 * ln
        total = float(a.sum()) + a_xi + a0
        tc = np.zeros(self.red.n_tau)  # compact multipliers, as Clarabel's answer holds them
        tc[self._facts] = rho * a / total
        if a_xi > 0.0:  # (L = 0: ξ and the η₁ slot need no multiplier, their columns −L ℓ are zero)
            assert self.red.xi is not None  # a_xi > 0 only with ξ
            tc[self.red.xi] = rho * a_xi / total
        lam0 = rho * a0 / total if a0 > 0.0 else 0.0  # the η₁ slot's multiplier
        Lc = L[:, None]
        P, taus = self.red.after(np.zeros((NA, NA)), [Lc], [tc], agg, pi0, ell, lam0, rho)
        return Solution(P, [Lc], taus, CLOSED_FORM_STATUS, iterations)


def clarabel_backend(lay: EtaLayout, n_lmi: int) -> ConicSolver | ClosedFormSolver:
    """The solver of one pattern for the ``clarabel`` backend: the closed form where there is no LMI block."""
    red = Reduction(lay, n_lmi)
    return ClosedFormSolver(red) if red.closed_form else ConicSolver(red)


__all__ = ["CLOSED_FORM_STATUS", "ClosedFormSolver", "clarabel_backend"]
