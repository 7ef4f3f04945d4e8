"""Backend ``clarabel``: the reduced conic problem of one node solved with Clarabel, in the three steps of
cvxpy's Clarabel interface (``cvxpy/reductions/solvers/conic_solvers/clarabel_conif.py``).

:meth:`ConicSolver.apply` turns a step's data into Clarabel's (:class:`ConicData`) plus what maps the answer
back (:class:`InverseData`), :meth:`ConicSolver.solve_via_data` runs the node's kept solver of the template,
:meth:`ConicSolver.invert` maps Clarabel's status (:data:`STATUS_MAP`) and point back to a
:class:`~netsetest.estimator.problem.Solution` of the LMI; :meth:`ConicSolver.solve` does the three.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import clarabel
import numpy as np

import netsetest.linalg as linalg

from netsetest.estimator.conic.reduction import Aggregate, Reduction, StepScales
from netsetest.estimator.conic.template import P_ENTRIES, StepValues, Template, TemplateKey, build_template
from netsetest.estimator.problem import Solution, StepData
from netsetest.models.sensor import NA

_S = clarabel.SolverStatus
STATUS_MAP: dict[Any, bool] = {
    # Clarabel's status → whether its point is an answer to map back (cvxpy: Solved → optimal, AlmostSolved →
    # optimal_inaccurate, both with a solution).  An inaccurate answer is mapped back too: certify() judges it.
    _S.Solved: True,
    _S.AlmostSolved: True,
    _S.Unsolved: False,
    _S.PrimalInfeasible: False,
    _S.DualInfeasible: False,
    _S.AlmostPrimalInfeasible: False,
    _S.AlmostDualInfeasible: False,
    _S.MaxIterations: False,
    _S.MaxTime: False,
    _S.NumericalError: False,
    _S.InsufficientProgress: False,
    _S.CallbackTerminated: False,
}


class CscMatrix:
    """The compressed-sparse-column matrix Clarabel reads (its attributes are scipy's), without scipy.

    Importing scipy.sparse would add ~0.1 s (and a few MB) to a node process's start-up for three arrays.
    Rows within each column must be sorted and unique (``has_canonical_format``).
    """

    format = "csc"
    has_canonical_format = True

    def __init__(self, data: np.ndarray, indices: np.ndarray, indptr: np.ndarray, shape: tuple[int, int]) -> None:
        self.data, self.indices, self.indptr, self.shape = data, indices, indptr, shape
        self.nnz = len(data)

    @classmethod
    def empty(cls, m: int, n: int) -> CscMatrix:
        return cls(np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(n + 1, dtype=np.int64), (m, n))

    def toarray(self) -> np.ndarray:
        out = np.zeros(self.shape)
        for c in range(self.shape[1]):
            sl = slice(self.indptr[c], self.indptr[c + 1])
            out[self.indices[sl], c] = self.data[sl]
        return out


def default_settings() -> clarabel.DefaultSettings:
    """Clarabel settings of the fast path; every answer is certified afterwards (certificate.certify).

    Tolerances stay at 1e-8: looser ones (1e-7, 1e-6) save one or two iterations but let the SAIM
    answers drift 3e-5 / 2e-4 above the optimum (2–7 % before the scaling of step 3).  Equilibration
    is off because the assembly scales the problem itself (on: +5 iterations and worse optima in
    SAIM); presolve is off so that Clarabel allows updating the data in place.
    """
    st = clarabel.DefaultSettings()
    st.verbose = False
    st.max_iter = 100
    st.tol_gap_abs = 1e-8
    st.tol_gap_rel = 1e-8
    st.tol_feas = 1e-8
    st.equilibrate_enable = False
    st.presolve_enable = False
    return st


# The smallest LMI whose PSD cone Clarabel's own chordal decomposition is left to split.  A decomposed problem's
# data cannot be updated in place, so each step sets up a new solver (about 0.25 ms); below this size that set-up
# costs more than the decomposition saves.  Measured per solve on paper6 and paper6_max_faulty SAIM (434 solves,
# each the fastest of 3, alternating): LMI 8 0.96 → 0.64 ms and 1.06 → 0.80, LMI 10 1.42 → 1.21, LMI 12 1.89 →
# 2.31 (so 12 keeps it); LMI 6 has nothing to decompose (its solver was kept already).
CHORDAL_FROM = 12


def _copied(st: clarabel.DefaultSettings) -> clarabel.DefaultSettings:
    """A copy of ``st`` (Clarabel's settings have no copy of their own)."""
    out = clarabel.DefaultSettings()
    for name in dir(st):
        if not name.startswith("_") and not callable(getattr(st, name)):
            try:
                setattr(out, name, getattr(st, name))
            except (AttributeError, TypeError):
                pass
    return out


def _kept_settings(st: clarabel.DefaultSettings) -> clarabel.DefaultSettings:
    """``st`` without Clarabel's chordal decomposition, so that the solver's data can be updated in place
    (:data:`CHORDAL_FROM`)."""
    out = _copied(st)
    out.chordal_decomposition_enable = False
    return out


def _decomposed_settings(st: clarabel.DefaultSettings) -> clarabel.DefaultSettings:
    """``st`` for the clique problems (saturation): the cliques are ours, and iterative refinement of the KKT
    solves bought nothing there (same widths to 1e-7, no fallback in 1440 SAIM node-steps with paper and
    worst-case signals) for 12-15 % of the time; the SOCP keeps it (one fallback without)."""
    out = _kept_settings(st)
    out.iterative_refinement_enable = False
    return out


@dataclass(frozen=True)
class ConicData:
    """Clarabel's problem of one step: minimise ½xᵀPx + qᵀx subject to b − A x ∈ cones (P = 0)."""

    P: CscMatrix  # (nv, nv), empty: the objective is linear
    q: np.ndarray  # (nv,)
    A: CscMatrix  # (n_rows, nv)
    b: np.ndarray  # (n_rows,)
    cones: list
    key: TemplateKey  # which template (and which kept solver) this is


@dataclass(frozen=True)
class InverseData:
    """What maps a conic point x back to (P, L_ℓ, τ_ℓ) of the LMI (cvxpy's ``inverse_data``)."""

    tpl: Template
    values: StepValues  # the step's values (S, the scales, B, ℓ, Π₀, ρ)
    agg: Aggregate  # the step's ξ (its weights split τ_ξ back over the aggregated facts)

    @property
    def slot0_cone(self) -> bool:
        return self.tpl.key[1]


@dataclass(frozen=True)
class ConicPoint:
    """A conic point x in the LMI's terms: P_c (NA, NA; zero without an LMI), per LMI L_ℓ (NA, 1), τ_ℓ over
    the original facts, and the compact multipliers (n_tau,) they come from."""

    P: np.ndarray
    L: list[np.ndarray]
    tau: list[np.ndarray]
    tau_compact: list[np.ndarray]


class ConicSolver:
    """Assembles and solves the reduced conic problem of one node (structure: ``red``, fixed by the topology).

    A template (the pattern of A, b and the cones) is built once per :data:`TemplateKey`, and one Clarabel
    solver is kept per template with its data updated in place where Clarabel allows it.
    """

    def __init__(self, red: Reduction, settings: clarabel.DefaultSettings | None = None) -> None:
        self.red = red
        self._slot0 = red.closed_form  # (a pure SOCP: the η₁ slot gets a cone of its own where ℓ₀ ≠ 0)
        self.settings = settings or default_settings()
        self.settings_decomposed = _decomposed_settings(self.settings)
        self.settings_kept = _kept_settings(self.settings)
        self._templates: dict[TemplateKey, Template] = {}
        self._solvers: dict[TemplateKey, clarabel.DefaultSolver] = {}

    def template(self, key: TemplateKey) -> Template:
        """The pattern of one template key, built on first use."""
        tpl = self._templates.get(key)
        if tpl is None:
            tpl = self._templates[key] = build_template(self.red, key)
        return tpl

    def apply(self, data: StepData, rho: float, scales: StepScales | None = None) -> tuple[ConicData, InverseData]:
        """Clarabel's data for one step and what maps its answer back to (P, L, τ) (cvxpy's ``apply``);
        ``scales``: the step's ξ and scales where the caller has them already (the closed form's fallback)."""
        red = self.red
        scales = red.before(data.ell, data.facts) if scales is None else scales  # (one call into the reduction)
        agg, sc, kappa = scales.agg, scales.sc, scales.kappa
        has_lmi = bool(red.lmi_slots)
        tpl = self.template((agg.use_xi, self._slot0 and float(data.ell[0]) != 0.0))
        S = data.Mi / math.sqrt(rho)  # congruence of the P rows: P_prev = S Sᵀ (data.Mi = ρ^½ chol(P_prev))
        values = StepValues(data.ell, data.facts, data.pi0, S, linalg.inv(S) if has_lmi else None, sc, kappa, agg.B, rho)
        a, b, q = tpl.fill(values)
        A = CscMatrix(a, tpl.indices, tpl.indptr, (tpl.n_rows, tpl.nv))
        conic = ConicData(CscMatrix.empty(tpl.nv, tpl.nv), q, A, b, tpl.cones, tpl.key)
        return conic, InverseData(tpl, values, agg)

    def solve(self, data: StepData, rho: float, scales: StepScales | None = None) -> Solution:
        """The step's answer from Clarabel (``scales`` as for :meth:`apply`)."""
        conic, inv = self.apply(data, rho, scales)
        try:
            sol = self.solve_via_data(conic)
        except Exception as exc:  # a solver failure is a fallback step, not a crash
            self._solvers.pop(conic.key, None)
            return Solution(None, [], [], f"error: {exc}")
        return self.invert(sol, inv)

    def solve_via_data(self, conic: ConicData) -> Any:  # clarabel's DefaultSolution (untyped)
        """Solve with the node's solver for this template, its data updated in place where Clarabel
        allows it (no chordal decomposition of its own, :data:`CHORDAL_FROM`; no presolve, no equilibration):
        the set-up (KKT symbolic factorisation) is then paid once per node, not per step."""
        solver = self._solvers.get(conic.key)
        if solver is not None:
            try:
                solver.update(q=conic.q, A=conic.A.data, b=conic.b)
                return solver.solve()
            except Exception:  # refused update: set up a fresh solver below
                del self._solvers[conic.key]
        tpl = self._templates[conic.key]
        st = self.settings_decomposed if tpl.decomposed else self.settings_kept if tpl.lmi_n < CHORDAL_FROM else self.settings
        solver = clarabel.DefaultSolver(conic.P, conic.q, conic.A, conic.b, conic.cones, st)
        if solver.is_data_update_allowed():
            self._solvers[conic.key] = solver
        return solver.solve()

    def invert(self, sol: Any, inv: InverseData) -> Solution:
        """(P, L_ℓ, τ_ℓ) of the LMI from Clarabel's solution (cvxpy's ``invert``); no P where its status
        (:data:`STATUS_MAP`) or its point has no answer; in ``scheduled`` the smallest P for (L, τ)."""
        status = str(sol.status)
        if not STATUS_MAP.get(sol.status, False):
            return Solution(None, [], [], status, sol.iterations)
        x = np.asarray(sol.x)
        if not np.all(np.isfinite(x)):
            return Solution(None, [], [], "non-finite", sol.iterations)
        Pc, Ls, tcs = self._point(x, inv)
        v = inv.values
        P, taus = self.red.after(Pc, Ls, tcs, inv.agg, v.pi0[0], v.ell, None, v.rho)  # (one call into the reduction)
        return Solution(P, Ls, taus, status, sol.iterations)

    def unpack(self, x: np.ndarray, inv: InverseData) -> ConicPoint:
        """P_c, L_ℓ and τ_ℓ over the original facts from a conic point x (L = S L̃, τ = τ̂/κ clipped at 0)."""
        P, Ls, tcs = self._point(x, inv)
        return ConicPoint(P, Ls, [self.red.fact_tau(tc, inv.agg) for tc in tcs], tcs)

    def _point(self, x: np.ndarray, inv: InverseData) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
        """P_c, L_ℓ and the compact multipliers of a conic point x (:meth:`unpack`, without τ over the facts)."""
        var, S = inv.tpl.var, inv.values.S  # (the template's variables: attributes, read once)
        Ls = [S @ x[i][:, None] for i in var.iL]
        tcs = [np.maximum(x[var.iT[r]], 0.0) / inv.values.kappa for r in range(self.red.n_lmi)]
        P = np.zeros((NA, NA))
        if self.red.lmi_slots:
            iP = var.iP
            for k, (i, j) in enumerate(P_ENTRIES):
                P[i, j] = P[j, i] = x[iP[k]]
            P = S @ P @ S.T
        return P, Ls, tcs


__all__ = ["CHORDAL_FROM", "STATUS_MAP", "ConicData", "ConicPoint", "ConicSolver", "CscMatrix", "InverseData", "default_settings"]
