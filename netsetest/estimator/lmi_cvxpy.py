"""The ``cvxpy`` backend of node i's SDP: the LMI of docs/design.md §2 exactly as written, in cvxpy.

Built once per pattern from cvxpy Parameters (``d`` η slots, ``m`` facts, ``n_lmi`` LMIs) and re-solved
with Clarabel every step: slower than :mod:`netsetest.estimator.conic`, and the reference it is checked
against.  cvxpy itself is imported only when a solver is built (it costs ~120 MB and ~1 s).
"""

from __future__ import annotations

import warnings

import numpy as np

from netsetest.estimator.problem import Solution, StepData
from netsetest.models.sensor import NA


class CvxpySolver:
    """The LMI exactly as written, built once from cvxpy Parameters and re-solved with Clarabel."""

    def __init__(self, d: int, m: int, n_lmi: int) -> None:
        import cvxpy as cp  # only here: importing cvxpy costs ~120 MB and ~1 s

        self.cp, self.n_lmi = cp, n_lmi
        self.p_pi0 = [cp.Parameter((NA, d), name=f"Pi0_{r}") for r in range(n_lmi)]
        self.p_ell = cp.Parameter((1, d), name="ell")
        self.p_q = [cp.Parameter((d, d), symmetric=True, name=f"Q_{q}") for q in range(m)]
        self.p_rho = cp.Parameter(nonneg=True, name="rho")
        self.v_P = cp.Variable((NA, NA), symmetric=True, name="P")
        self.v_L = [cp.Variable((NA, 1), name=f"L_{r}") for r in range(n_lmi)]
        self.v_tau = [cp.Variable(m, nonneg=True, name=f"tau_{r}") for r in range(n_lmi)]
        e11 = np.zeros((d, d))
        e11[0, 0] = 1.0
        cons = []
        for r in range(n_lmi):
            pi = self.p_pi0[r] - self.v_L[r] @ self.p_ell
            mult = -self.p_rho * e11 + sum(self.v_tau[r][q] * self.p_q[q] for q in range(m))
            lmi = cp.bmat([[-self.v_P, pi], [pi.T, mult]])
            cons.append(0.5 * (lmi + lmi.T) << 0)
        self.problem = cp.Problem(cp.Minimize(cp.trace(self.v_P)), cons)
        assert self.problem.is_dcp(dpp=True)  # type: ignore[call-arg]  # cvxpy's annotation of is_dcp omits its dpp keyword

    def solve(self, data: StepData, rho: float) -> Solution:
        cp = self.cp
        for r in range(self.n_lmi):
            self.p_pi0[r].value = data.pi0[r]
        self.p_ell.value = data.ell[None, :]
        for q, Q in enumerate(data.facts):
            self.p_q[q].value = Q
        self.p_rho.value = rho
        try:
            with warnings.catch_warnings():  # "inaccurate" answers are certified by the estimator, not trusted
                warnings.simplefilter("ignore", UserWarning)
                self.problem.solve(solver=cp.CLARABEL)
            status = str(self.problem.status)
        except cp.error.SolverError as exc:
            return Solution(None, [], [], f"error: {exc}")
        if self.v_P.value is None or status not in ("optimal", "optimal_inaccurate"):
            return Solution(None, [], [], status)
        L = [np.asarray(v.value) for v in self.v_L]  # solved: every variable has a value
        return Solution(self.v_P.value, L, [np.asarray(v.value) for v in self.v_tau], status)


__all__ = ["CvxpySolver"]
