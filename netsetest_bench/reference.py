"""The yardsticks of the benchmark: node i's SDP written the straightforward way, solved through cvxpy.

``StraightforwardSDP`` is the formulation issue #4 describes — full η with a 3-vector z_j for every
in-neighbour j (the node's own z_i included), the φ slots kept for every j ∈ N_i and for φ⁺ even
without saturation (h = 0 turns their sector facts into −φ² ≥ 0), one multiplier per fact, built
once from cvxpy Parameters and solved with Clarabel's default settings:

    η = [1, z_j (j ∈ {i} ∪ N_i), w, v_j (j ∈ N_i), v⁺, φ_j (j ∈ N_i), φ⁺]       (19 slots for the paper's nodes)
    [[−P, Π₀ − L ℓᵀ], [(Π₀ − L ℓᵀ)ᵀ, −ρ e₁e₁ᵀ + Σ_m τ_m Q_m]] ⪯ 0,  τ ≥ 0,  min trace(P)   (22×22)

``NaiveSDP`` is the same mathematics with the cvxpy problem rebuilt from constants at every step.
Both certify their answers with :func:`netsetest.estimator.certificate.certify` on their own facts, exactly
like the estimator, so their published shapes are comparable with the fast path's.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np

from netsetest.estimator.certificate import certify
from netsetest.estimator.sdp import NeighbourState
from netsetest.models.sensor import NA, NX, Sensor
from netsetest.models.vehicle import N_RULES, TSModel


@dataclass
class RefResult:
    xhat: np.ndarray
    P: np.ndarray | None  # published shape (P·ρ'/ρ), None if the answer did not certify
    status: str
    step_ms: float  # data + solve + certification
    solve_ms: float  # cvxpy (parameter update / problem build) + Clarabel


@dataclass(frozen=True)
class RefData:
    """One step of the straightforward LMI over its d η slots (cf. netsetest.estimator.problem.StepData)."""

    pi0: list[np.ndarray]  # Π₀ per rule, each (NA, d)
    ell: np.ndarray  # (d,)
    facts: list[np.ndarray]  # Q_m, each (d, d)
    x_pred: np.ndarray  # (NA,) the L-free part of x̂⁺
    innov_sum: float  # Σ_j a_ij y̌_j


class FullEta:
    """Slots of the straightforward η and its data (Π₀ per rule, ℓ, Q_m) for one step."""

    def __init__(self, node_id: int, own: Sensor, neighbours: dict[int, Sensor], weights: dict[int, float], model: TSModel, W: float, variant: str) -> None:
        self.i, self.own, self.sensors, self.weights, self.model, self.W = node_id, own, neighbours, weights, model, W
        self.n_rules = N_RULES if variant == "per-rule" else 1
        self.neigh = list(neighbours)
        zs = [node_id] + [j for j in self.neigh if j != node_id]
        idx = 1
        self.z: dict[int, list[int]] = {}
        for j in zs:
            self.z[j] = list(range(idx, idx + NA))
            idx += NA
        self.w, idx = idx, idx + 1
        self.v: dict[int, int] = {}
        for j in self.neigh:
            self.v[j], idx = idx, idx + 1
        self.v_new, idx = idx, idx + 1
        self.phi: dict[int, int] = {}
        for j in self.neigh:
            self.phi[j], idx = idx, idx + 1
        self.phi_new, idx = idx, idx + 1
        self.dim = idx
        self.n_facts = len(self.z) + 1 + len(self.v) + 1 + len(self.phi) + 1

    def data(
        self, xhat: np.ndarray, P: np.ndarray, rho: float, alpha: np.ndarray, u: float, y_new: float, gamma_new: float, neigh: dict[int, NeighbourState]
    ) -> RefData:
        d, own = self.dim, self.own
        T, G = own.descriptor_gains(gamma_new)
        g = G[:, 0]
        Mi = np.sqrt(rho) * np.linalg.cholesky(0.5 * (P + P.T))

        def aug(a: np.ndarray, b: np.ndarray, dw: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            ab = np.zeros((NA, NA))
            ab[:NX, :NX] = a
            return ab, np.r_[b[:, 0], 0.0], np.r_[dw[:, 0], 0.0]

        blended = aug(*self.model.blend(alpha))
        rules = [blended] if self.n_rules == 1 else [aug(self.model.A[r], self.model.B[r], self.model.Dw[r]) for r in range(N_RULES)]
        pi0 = []
        for ab, _, db in rules:
            p = np.zeros((NA, d))
            p[:, self.z[self.i]] = T @ ab @ Mi
            p[:, self.w] = T @ db
            p[:, self.v_new] = -g * own.Dv
            p[:, self.phi_new] = -g * gamma_new
            pi0.append(p)
        ell = np.zeros(d)
        facts = []
        for j, zs in self.z.items():
            q = np.zeros((d, d))
            q[0, 0] = 1.0
            q[zs, zs] = -1.0
            facts.append(q)
        facts.append(self._ball(self.w, self.W))
        for j in self.neigh:
            facts.append(self._ball(self.v[j], self.sensors[j].R))
        facts.append(self._ball(self.v_new, own.R))
        for j in self.neigh:
            sj, nb = self.sensors[j], neigh.get(j)
            gr = np.zeros(d)
            if nb is not None:
                a = self.weights[j]
                cbar = sj.Cbar
                Mj = Mi if j == self.i else np.sqrt(nb.rho) * np.linalg.cholesky(0.5 * (nb.P + nb.P.T))
                ell[0] += a * (nb.gamma * sj.h1 - 1.0) * (cbar @ nb.xhat)
                ell[self.z[j]] += a * nb.gamma * sj.h1 * (cbar @ Mj)
                ell[self.v[j]] += a * sj.Dv
                ell[self.phi[j]] += a * nb.gamma
                gr[0] = cbar @ nb.xhat
                gr[self.z[j]] = cbar @ Mj
            facts.append(self._sector(self.phi[j], gr, sj.h))
        ab, bb, db = blended
        x_pred = T @ ab @ xhat + T @ bb * u + g * y_new
        cbar, cg = own.Cbar, float(own.Cbar @ g)
        gn = np.zeros(d)
        gn[0] = cbar @ x_pred
        gn[self.z[self.i]] = cbar @ T @ ab @ Mi
        gn[self.w] = cbar @ T @ db
        gn[self.v_new] = -cg * own.Dv
        gn[self.phi_new] = -cg * gamma_new
        facts.append(self._sector(self.phi_new, gn, own.h))
        innov = sum(self.weights[j] * neigh[j].innov for j in self.neigh if j in neigh)
        return RefData(pi0, ell, facts, x_pred, float(innov))

    def _ball(self, slot: int, bound: float) -> np.ndarray:
        q = np.zeros((self.dim, self.dim))
        q[0, 0] = 1.0
        q[slot, slot] = -1.0 / bound
        return q

    def _sector(self, slot: int, g: np.ndarray, h: float) -> np.ndarray:
        e = np.zeros(self.dim)
        e[slot] = 1.0
        return 0.5 * h * (np.outer(e, g) + np.outer(g, e)) - np.outer(e, e)


def _lmi_problem(cp, d: int, m: int, n_rules: int, pi0, ell, facts, rho):
    """min trace(P) s.t. one LMI per rule; the data are Parameters or plain arrays."""
    P = cp.Variable((NA, NA), symmetric=True)
    Ls = [cp.Variable((NA, 1)) for _ in range(n_rules)]
    taus = [cp.Variable(m, nonneg=True) for _ in range(n_rules)]
    e11 = np.zeros((d, d))
    e11[0, 0] = 1.0
    cons = []
    for r in range(n_rules):
        pi = pi0[r] - Ls[r] @ ell
        mult = -rho * e11 + sum(taus[r][q] * facts[q] for q in range(m))
        lmi = cp.bmat([[-P, pi], [pi.T, mult]])
        cons.append(0.5 * (lmi + lmi.T) << 0)
    return cp.Problem(cp.Minimize(cp.trace(P)), cons), P, Ls, taus


class StraightforwardSDP:
    """The straightforward formulation, built once from cvxpy Parameters, Clarabel defaults."""

    rebuild = False

    def __init__(
        self, node_id: int, own: Sensor, neighbours: dict[int, Sensor], weights: dict[int, float], model: TSModel, W: float, variant: str = "scheduled"
    ) -> None:
        import cvxpy as cp

        self.cp = cp
        self.eta = FullEta(node_id, own, neighbours, weights, model, W, variant)
        d, m, nr = self.eta.dim, self.eta.n_facts, self.eta.n_rules
        if not self.rebuild:
            self.p_pi0 = [cp.Parameter((NA, d)) for _ in range(nr)]
            self.p_ell = cp.Parameter((1, d))
            self.p_q = [cp.Parameter((d, d), symmetric=True) for _ in range(m)]
            self.p_rho = cp.Parameter(nonneg=True)
            self.problem, self.v_P, self.v_L, self.v_tau = _lmi_problem(cp, d, m, nr, self.p_pi0, self.p_ell, self.p_q, self.p_rho)

    def _solve(self, dat: RefData, rho: float) -> tuple[str, np.ndarray | None, list, list]:
        cp = self.cp
        if self.rebuild:
            e = self.eta
            self.problem, self.v_P, self.v_L, self.v_tau = _lmi_problem(cp, e.dim, e.n_facts, e.n_rules, dat.pi0, dat.ell[None, :], dat.facts, rho)
        else:
            for r, p in enumerate(dat.pi0):
                self.p_pi0[r].value = p
            self.p_ell.value = dat.ell[None, :]
            for q, Q in enumerate(dat.facts):
                self.p_q[q].value = Q
            self.p_rho.value = rho
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self.problem.solve(solver=cp.CLARABEL)
        except cp.error.SolverError as exc:
            return f"error: {exc}", None, [], []
        if self.v_P.value is None:
            return str(self.problem.status), None, [], []
        return str(self.problem.status), self.v_P.value, [v.value for v in self.v_L], [v.value for v in self.v_tau]

    def step(
        self, xhat: np.ndarray, P: np.ndarray, rho: float, alpha: np.ndarray, u: float, y_new: float, gamma_new: float, neigh: dict[int, NeighbourState]
    ) -> RefResult:
        t0 = time.perf_counter()
        dat = self.eta.data(xhat, P, rho, alpha, u, y_new, gamma_new, neigh)
        t1 = time.perf_counter()
        status, Pv, Ls, taus = self._solve(dat, rho)
        t2 = time.perf_counter()
        P_pub, xhat_new = None, dat.x_pred
        if Pv is not None:
            if len(Ls) == 1:
                L, tau, pi0 = Ls[0], taus[0], dat.pi0[0]
            else:
                L = sum(a * v for a, v in zip(alpha, Ls))
                tau = sum(a * v for a, v in zip(alpha, taus))
                pi0 = sum(a * p for a, p in zip(alpha, dat.pi0))
            rho_c = certify(Pv, pi0 - L @ dat.ell[None, :], tau, dat.facts)
            if rho_c is not None:
                P_pub = 0.5 * (Pv + Pv.T) * rho_c / rho
                xhat_new = dat.x_pred + L[:, 0] * dat.innov_sum
        t3 = time.perf_counter()
        return RefResult(xhat_new, P_pub, status, 1e3 * (t3 - t0), 1e3 * (t2 - t1))


class NaiveSDP(StraightforwardSDP):
    """The same formulation, with the cvxpy problem rebuilt from constants at every step."""

    rebuild = True


__all__ = ["FullEta", "NaiveSDP", "RefData", "RefResult", "StraightforwardSDP"]
