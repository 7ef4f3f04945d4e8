"""Local ellipsoidal set-membership estimator of node i (paper (16), (22), corrected as in DESIGN.md §2).

One step k → k+1 at node i, with everything a real node has:

    x̂⁺ = T Ā x̂ + T B̄ u + G ỹ⁺ + L Σ_j a_ij y̌_j                                                 (16)

where Ā, B̄, D̄ are the α_k-blend of the rule matrices (variant ``scheduled``), or, in the paper's
variant ``per-rule``, one gain L_ℓ per rule and the estimate blended with α_k.  The error is exactly

    e⁺ = Π(L) η,   η = [1, z_i, s_j (j ∈ N_i∖i), w, v_j (j ∈ N_i), v⁺, φ_j (saturating j), φ⁺]

    Π(L) = Π₀ − L ℓᵀ,  Π₀ η = T Ā ρ_i^½ M_i z_i + T D̄ w − G Dv_i v⁺ − G γ⁺ φ⁺,
    ℓᵀ η = Σ_j a_ij y̌_j(η),  y̌_j = (γ_j h1_j − 1) C̄_j x̂_j + γ_j h1_j C̄_j ρ_j^½ M_j z_j + γ_j φ_j + Dv_j v_j.

For a neighbour j ≠ i, z_j only enters through the scalar C̄_j M_j z_j = c_j s_j with
c_j = (C̄_j P_j C̄_jᵀ)^½ and |s_j| ≤ 1 — an exact reduction (DESIGN.md §2).  The truth satisfies the
quadratic facts ηᵀ Q_m η ≥ 0 (one per constraint):

    1 − z_iᵀz_i;  1 − s_j²;  1 − w²/W;  1 − v_j²/R_j;  1 − v⁺²/R_i;
    φ_j (h_j r_j − φ_j),  r_j = C̄_j x̂_j + ρ_j^½ C̄_j M_j z_j;
    φ⁺ (h_i r⁺ − φ⁺),   r⁺ = C̄_i x̄⁺ (the truth, so without L).

S-procedure and Schur complement give the LMI (one per rule in ``per-rule``)

    [[−P, Π(L)], [Π(L)ᵀ, −ρ_i e₁e₁ᵀ + Σ_m τ_m Q_m]] ⪯ 0,   P ≻ 0, τ ≥ 0,   minimise trace(P)

and then (x̄⁺ − x̂⁺)ᵀ P⁻¹ (x̄⁺ − x̂⁺) ≤ ρ_i.

Per step (docs/estimator.md): the own sensor's sector is derived from the node's certified set, the
wind bound, its reading and the declared fault bound (:mod:`netsetest.estimator.sector`); neighbours'
sectors come with their messages, so which φ slots exist changes per step (one layout and solver per
pattern).  Where the own sector is derived and the sensor may saturate, the proven interval of r⁺ is
used as the measurement instead of the φ⁺ sector fact.  Step 0 updates the prior with ỹ₀
(:meth:`LocalEstimator.first`).  The objective is trace(D P) (a congruence of the LMI); ``bank`` solves
each step twice and publishes the fault-weighted set while recurring on the trace-optimal one.

Two backends solve it.  ``clarabel`` (the default, :mod:`netsetest.estimator.conic`) assembles an
exactly equivalent, smaller conic problem for Clarabel directly from the step data (Π₀, ℓ, Q_m) and
maps its answer back to (P, L, τ) of the LMI above; ``cvxpy`` builds the LMI as written once from cvxpy
Parameters and re-solves it every step (cvxpy is imported only when this backend is chosen).  Either
way every answer is verified in floating point against the LMI above (:func:`certify`) before it is
published; if that fails, :func:`fallback_shape` gives a guaranteed (looser) ellipsoid and the step is
flagged.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from netsetest.estimator.objective import BANK_FAULT_WEIGHT, DEFAULT_OBJECTIVE, FAULT_WEIGHT, OBJECTIVES, Objective
from netsetest.estimator.sector import (
    FaultBound, Interval, Sector, derive_sector, measurement_interval, prior_interval, propagated_interval,
)  # fmt: skip
from netsetest.extras import require
from netsetest.models.sensor import NA, NX, Sensor
from netsetest.models.vehicle import N_RULES, TSModel

Variant = Literal["scheduled", "per-rule"]
Backend = Literal["clarabel", "cvxpy"]
Status = Literal["ok", "fallback"]
BACKENDS = ("clarabel", "cvxpy")


@dataclass(frozen=True)
class Ellipsoid:
    """{x̄: (x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ}."""

    xhat: np.ndarray  # (3,)
    P: np.ndarray  # (3, 3)
    rho: float


@dataclass(frozen=True)
class NeighbourState:
    """What node i uses of neighbour j's step-k message (static sensor data comes from the topology)."""

    xhat: np.ndarray  # x̂_j (3,)
    P: np.ndarray  # P_j (3, 3)
    rho: float
    gamma: float  # γ_j,k
    innov: float  # y̌_j,k = ỹ_j,k − C̄_j x̂_j,k
    sector: Sector | None = None  # j's sector of step k (None: j models no saturation)

    @property
    def h1(self) -> float:
        return self.sector.h1 if self.sector is not None else 1.0

    @property
    def has_phi(self) -> bool:
        return self.sector is not None and self.sector.has_phi


@dataclass(frozen=True)
class StepInput:
    """What node i has for step k → k+1 besides its own ellipsoid of step k."""

    alpha: np.ndarray  # α(Vx_k)
    u: float  # u_k
    y: float  # ỹ_i,k+1
    gamma: float  # γ_i,k+1
    neigh: dict[int, NeighbourState]  # step-k messages of the in-neighbours that arrived (and i's own)


@dataclass
class StepResult:
    xhat: np.ndarray
    P: np.ndarray  # published shape: e⁺ᵀ P⁻¹ e⁺ ≤ ρ_i
    status: Status
    rho_cert: float  # ρ' certified for the solver's P (P is published as P_solver·ρ'/ρ_i)
    solve_ms: float
    solver_status: str
    L: np.ndarray = field(default_factory=lambda: np.zeros((NA, 1)))
    sector: Sector | None = None  # the own sensor's sector of this step (None: no saturation modelled)
    published: StepResult | None = None  # objective ``bank``: the set to publish (None: this one)

    @property
    def public(self) -> StepResult:
        """What the node publishes: ``published`` if the bank made one, else this set."""
        return self.published if self.published is not None else self


@dataclass(frozen=True)
class FactInfo:
    """Structure of one quadratic fact ηᵀQ_m η ≥ 0, in the order of ``step_data()['facts']``.

    ``ball``: 1 − Σ_{k ∈ slots} η_k²/bound (Q[0,0] = 1, Q[k,k] = −1/bound, nothing else).
    ``sector``: φ (h gᵀη − φ) with φ = η[slots[0]]; ``support`` are the slots where g may be non-zero.
    """

    kind: Literal["ball", "sector"]
    slots: tuple[int, ...]
    bound: float = 1.0
    support: tuple[int, ...] = ()


class EtaLayout:
    """Slot indices of η for node i and its in-neighbours N_i (fixed by the topology)."""

    def __init__(self, node_id: int, neighbours: dict[int, Sensor], own: Sensor, W: float = 1.0, predict: bool = True) -> None:
        """``saturated`` of each sensor says whether it has a φ slot; ``predict`` False: the step-0 update
        (the prior updated by the own measurement through the self slot: no w, v⁺ or φ⁺)."""
        self.node_id = node_id
        self.neigh = list(neighbours)  # j ∈ N_i in a fixed order (may include i)
        idx = 1
        self.z = list(range(idx, idx + NA))
        idx += NA
        self.s: dict[int, int] = {}
        for j in self.neigh:
            if j != node_id:
                self.s[j], idx = idx, idx + 1
        self.w: int | None = None
        if predict:
            self.w, idx = idx, idx + 1
        self.v: dict[int, int] = {}
        for j in self.neigh:
            self.v[j], idx = idx, idx + 1
        self.v_new: int | None = None
        if predict:
            self.v_new, idx = idx, idx + 1
        self.phi: dict[int, int] = {}
        for j, sens in neighbours.items():
            if sens.saturated:  # no saturation ⇒ φ_j ≡ 0: no slot (DESIGN.md §2)
                self.phi[j], idx = idx, idx + 1
        self.phi_new: int | None = None
        if own.saturated and predict:
            self.phi_new, idx = idx, idx + 1
        self.dim = idx
        # one quadratic fact per constraint, in this order
        facts = [FactInfo("ball", tuple(self.z))]
        facts += [FactInfo("ball", (self.s[j],)) for j in self.s]
        if self.w is not None:
            facts.append(FactInfo("ball", (self.w,), W))
        facts += [FactInfo("ball", (self.v[j],), neighbours[j].R) for j in self.v]
        if self.v_new is not None:
            facts.append(FactInfo("ball", (self.v_new,), own.R))
        for j in self.neigh:
            if j in self.phi:
                r_slots = tuple(self.z) if j == node_id else (self.s[j],)
                facts.append(FactInfo("sector", (self.phi[j],), support=(0, *r_slots)))
        if self.phi_new is not None:
            facts.append(FactInfo("sector", (self.phi_new,), support=(0, *self.z, self.w, self.v_new, self.phi_new)))
        self.facts = facts
        self.n_facts = len(facts)
        # slots whose column of Π₀ is zero in every rule: they enter e⁺ only through L ℓᵀη
        self.pi0_zero = set(self.s.values()) | set(self.v.values()) | set(self.phi.values())


def _ball(d: int, slots: list[int], bound: float = 1.0) -> np.ndarray:
    """Q of the fact 1 − Σ_slots η²/bound ≥ 0."""
    q = np.zeros((d, d))
    q[0, 0] = 1.0
    for s in slots:
        q[s, s] = -1.0 / bound
    return q


def _sector(d: int, slot: int, g: np.ndarray, h: float) -> np.ndarray:
    """Q of the fact φ (h gᵀη − φ) ≥ 0 where φ = η[slot]."""
    q = np.zeros((d, d))
    hg = 0.5 * h * g
    q[slot, :] = hg
    q[:, slot] += hg
    q[slot, slot] -= 1.0
    return q


def _chol(p: np.ndarray) -> np.ndarray:
    return np.linalg.cholesky(0.5 * (p + p.T))


@dataclass
class _Pattern:
    """η layout, static ball facts and solver of one φ-slot pattern (which sensors saturate this step)."""

    lay: EtaLayout
    balls: list[np.ndarray]
    solver: object


class LocalEstimator:
    """The per-node SDP of one node: static data prepared once, solved every step by a backend.

    Which sensors have a φ slot changes from step to step (a sector derived per step may prove that a
    sensor does not saturate): one η layout and solver per pattern, built when first needed.
    """

    def __init__(
        self,
        node_id: int,
        own: Sensor,
        neighbours: dict[int, Sensor],
        weights: dict[int, float],
        model: TSModel,
        W: float,
        variant: Variant = "scheduled",
        backend: Backend = "clarabel",
        fault_bound: FaultBound = FaultBound(),
        objective: Objective = DEFAULT_OBJECTIVE,
    ) -> None:
        if variant not in ("scheduled", "per-rule"):
            raise ValueError(f"variant must be 'scheduled' or 'per-rule', got {variant!r}")
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
        if objective not in OBJECTIVES:
            raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
        if backend == "cvxpy":
            require("cvxpy", "the cvxpy estimator backend")  # at construction, not at the first solve
        self.node_id, self.own, self.model, self.W, self.variant = node_id, own, model, W, variant
        self.backend, self.fault_bound, self.objective = backend, fault_bound, objective
        self.sensors = neighbours
        self.weights = weights
        self.n_lmi = N_RULES if variant == "per-rule" else 1
        # static data, prepared once: augmented rule matrices Ā_ℓ, B̄_ℓ, D̄_ℓ
        nr = model.A.shape[0]
        self._abar = np.zeros((nr, NA, NA))
        self._abar[:, :NX, :NX] = model.A
        self._bbar = np.zeros((nr, NA))
        self._bbar[:, :NX] = model.B[:, :, 0]
        self._dbar = np.zeros((nr, NA))
        self._dbar[:, :NX] = model.Dw[:, :, 0]
        self._cbar = {j: s.Cbar for j, s in neighbours.items()} | {node_id: own.Cbar}
        self._own_cbar = own.Cbar
        self._gains: dict[tuple[float, float], tuple[np.ndarray, np.ndarray]] = {}
        self._patterns: dict[tuple, _Pattern] = {}
        self.last_iterations = 0  # of the last solve (bench)
        # objective weight: trace(D P) is trace(P') for P' = D^½ P D^½ (a congruence of the LMI)
        self._wh = np.sqrt(np.array([1.0, 1.0, FAULT_WEIGHT])) if objective == "fault" else None
        self._wh_pub = np.sqrt(np.array([1.0, 1.0, BANK_FAULT_WEIGHT])) if objective == "bank" else None

    def pattern(self, phi_from: frozenset[int], phi_new: bool, predict: bool = True) -> _Pattern:
        """Layout and solver for the neighbours in ``phi_from`` (and φ⁺ if ``phi_new``) having a φ slot."""
        key = (phi_from, phi_new, predict)
        pat = self._patterns.get(key)
        if pat is None:
            if predict:
                sens = {j: dataclasses.replace(s, saturated=j in phi_from) for j, s in self.sensors.items()}
            else:  # step 0: the prior and the own measurement, through the self slot
                sens = {self.node_id: dataclasses.replace(self.own, saturated=self.node_id in phi_from)}
            own = dataclasses.replace(self.own, saturated=phi_new)
            lay = EtaLayout(self.node_id, sens, own, self.W, predict)
            balls = []
            for f in lay.facts:
                if f.kind == "ball":
                    q = _ball(lay.dim, list(f.slots), f.bound)
                    q.flags.writeable = False
                    balls.append(q)
            n_lmi = self.n_lmi if predict else 1
            if self.backend == "clarabel":
                from netsetest.estimator.conic import ConicSolver

                solver: object = ConicSolver(lay, n_lmi)
            else:
                solver = _CvxpySolver(lay.dim, lay.n_facts, n_lmi)
            pat = self._patterns[key] = _Pattern(lay, balls, solver)
        return pat

    @property
    def lay(self) -> EtaLayout:
        """The layout with every saturating sensor's φ slot (the static worst case)."""
        sat = frozenset(j for j, s in self.sensors.items() if s.saturated)
        return self.pattern(sat, self.own.saturated).lay

    # ------------------------------------------------------------------ data of one step

    def descriptor_gains(self, gamma: float, h1: float) -> tuple[np.ndarray, np.ndarray]:
        """T, G of the own sensor for γ and the step's h1 (cached: both are constant in NSNIM)."""
        key = (gamma, h1)
        if key not in self._gains:
            if len(self._gains) > 64:  # SAIM: γ varies every step
                self._gains.clear()
            self._gains[key] = self.own.descriptor_gains(gamma, h1)
        return self._gains[key]

    def own_sector(self, prev: Ellipsoid, inp: StepInput) -> Sector | None:
        """The own sensor's sector of step k+1 (docs/estimator.md, "Adaptive sector")."""
        return self._own_range(prev, inp)[0]

    def _own_range(self, prev: Ellipsoid, inp: StepInput) -> tuple[Sector | None, Interval | None]:
        """The own sector of step k+1 and, where it is derived and the sensor may saturate, the proven
        interval of r⁺ = C̄ x̄⁺ (the step then uses it as the measurement; see ``step_data``)."""
        if not self.own.saturated:
            return None, None
        a, b, d = self.model.blend(np.asarray(inp.alpha, dtype=float))
        meas = measurement_interval(self.own, inp.y, inp.gamma)
        prop = propagated_interval(self.own, self.fault_bound, prev.xhat, prev.P, prev.rho, a, b[:, 0], d[:, 0], inp.u, self.W)
        sector = derive_sector(self.own, self.fault_bound, meas, prop)
        if sector is None or not sector.has_phi or sector.basis == "assumed":
            return sector, None
        return sector, (meas & prop if sector.basis == "fault-bound" else meas)

    def initial_sector(self, prior: Ellipsoid, y: float, gamma: float) -> Sector | None:
        """The own sensor's sector of step 0: the prior (Assumption 1), |f₀| ≤ F and the measurement."""
        if not self.own.saturated:
            return None
        meas = measurement_interval(self.own, y, gamma)
        return derive_sector(self.own, self.fault_bound, meas, prior_interval(self.own, self.fault_bound, prior.xhat, prior.P, prior.rho))

    def step_data(self, prev: Ellipsoid, inp: StepInput, sector: Sector | None, reading: Interval | None = None) -> dict:
        """Π₀ (per rule), ℓ, the facts Q_m and the L-free part of x̂⁺, as plain arrays.

        ``reading``: a proven interval [lo, hi] ∋ r⁺ used as the own measurement instead of the sector:
        r⁺ = m + Dv' v with m its centre, Dv' = (hi − lo)/(2√R) and v² ≤ R (so Θ = [E; C̄], no φ⁺).
        """
        own = self.own
        neigh = inp.neigh
        phi_from = frozenset(j for j in self.sensors if j in neigh and neigh[j].has_phi)
        phi_new = sector is not None and sector.has_phi and reading is None
        pat = self.pattern(phi_from, phi_new)
        lay, d = pat.lay, pat.lay.dim
        y_new, gamma_new, dv_new = inp.y, inp.gamma, own.Dv
        h1_new = sector.h1 if sector is not None else own.h1
        if reading is not None:
            y_new, gamma_new, h1_new = 0.5 * (reading.lo + reading.hi), 1.0, 1.0
            dv_new = 0.5 * (reading.hi - reading.lo) / np.sqrt(own.R)
        T, G = self.descriptor_gains(gamma_new, h1_new)
        g = G[:, 0]
        Mi = np.sqrt(prev.rho) * _chol(prev.P)  # ρ_i^½ M_i
        alpha = np.asarray(inp.alpha, dtype=float)
        ab = np.tensordot(alpha, self._abar, axes=1)  # the blended Ā, B̄, D̄ (exact for the truth)
        bb = alpha @ self._bbar
        db = alpha @ self._dbar
        TA = T @ ab
        Td = T @ db

        if self.variant == "scheduled":
            pi0 = np.zeros((1, NA, d))
            pi0[0][:, lay.z] = TA @ Mi
            pi0[0][:, lay.w] = Td
        else:
            pi0 = np.zeros((N_RULES, NA, d))
            pi0[:, :, lay.z] = T @ self._abar @ Mi
            pi0[:, :, lay.w] = self._dbar @ T.T
        pi0[:, :, lay.v_new] = -g * dv_new
        if lay.phi_new is not None:
            pi0[:, :, lay.phi_new] = -g * gamma_new

        ell, facts = self._innovations(lay, pat.balls, neigh, Mi)
        # L-free part of the centre; the blended matrices are exact for the truth in both variants
        x_pred = TA @ prev.xhat + (T @ bb) * inp.u + g * y_new
        if lay.phi_new is not None:
            cbar = self._own_cbar
            cg = float(cbar @ g)
            g_new = np.zeros(d)  # r⁺ = C̄ x̄⁺ of the truth, with the blended model in every rule
            g_new[0] = cbar @ x_pred
            g_new[lay.z] = cbar @ TA @ Mi
            g_new[lay.w] = cbar @ Td
            g_new[lay.v_new] = -cg * dv_new
            g_new[lay.phi_new] = -cg * gamma_new
            facts.append(_sector(d, lay.phi_new, g_new, sector.h))  # type: ignore[union-attr]
        innov_sum = sum(self.weights[j] * neigh[j].innov for j in lay.neigh if j in neigh)
        return {"pi0": list(pi0), "ell": ell, "facts": facts, "x_pred": x_pred, "innov_sum": float(innov_sum),
                "T": T, "G": G, "Mi": Mi, "lay": lay, "key": (phi_from, phi_new, True), "sector": sector,
                "own_meas": dataclasses.replace(own, Dv=dv_new, saturated=phi_new, h1=h1_new), "gamma": gamma_new}  # fmt: skip

    def _innovations(
        self, lay: EtaLayout, balls: list[np.ndarray], neigh: dict[int, NeighbourState], Mi: np.ndarray, weights: dict[int, float] | None = None
    ) -> tuple[np.ndarray, list[np.ndarray]]:
        """ℓ (ℓᵀη = Σ_j a_ij y̌_j(η)) and the facts: the balls and each neighbour's φ_j sector fact.

        A missing neighbour's slots stay zero (its facts then hold with η-slot 0).
        """
        weights = weights or self.weights
        d = lay.dim
        ell = np.zeros(d)
        facts: list[np.ndarray] = list(balls)
        for j in lay.neigh:
            sj, nb = (self.own if j == self.node_id else self.sensors[j]), neigh.get(j)
            g_r = np.zeros(d)  # r_j = gᵀη
            if nb is not None:
                a = weights[j]
                cbar = self._cbar[j]
                cx = float(cbar @ nb.xhat)
                ell[0] += a * (nb.gamma * nb.h1 - 1.0) * cx
                ell[lay.v[j]] += a * sj.Dv
                g_r[0] = cx
                if j == self.node_id:
                    row = cbar @ Mi  # the node's own z_i
                    ell[lay.z] += a * nb.gamma * nb.h1 * row
                    g_r[lay.z] = row
                else:
                    c_j = np.sqrt(max(nb.rho * float(cbar @ nb.P @ cbar), 0.0))
                    ell[lay.s[j]] += a * nb.gamma * nb.h1 * c_j
                    g_r[lay.s[j]] = c_j
                if j in lay.phi:
                    ell[lay.phi[j]] += a * nb.gamma
            if j in lay.phi:
                facts.append(_sector(d, lay.phi[j], g_r, nb.sector.h))  # type: ignore[union-attr]
        return ell, facts

    def initial_data(self, prior: Ellipsoid, y: float, gamma: float, sector: Sector | None) -> dict:
        """Step 0: x̂₀ = x̂ + L(ỹ₀ − C̄x̂), error e = ρ^½Mz − L y̌₀(η) with y̌₀ the own innovation."""
        i = self.node_id
        phi = sector is not None and sector.has_phi
        pat = self.pattern(frozenset([i]) if phi else frozenset(), False, predict=False)
        lay = pat.lay
        Mi = np.sqrt(prior.rho) * _chol(prior.P)
        pi0 = np.zeros((1, NA, lay.dim))
        pi0[0][:, lay.z] = Mi
        innov = float(y - self._own_cbar @ prior.xhat)
        me = NeighbourState(prior.xhat, prior.P, prior.rho, gamma, innov, sector)
        ell, facts = self._innovations(lay, pat.balls, {i: me}, Mi, {i: 1.0})
        return {"pi0": list(pi0), "ell": ell, "facts": facts, "x_pred": prior.xhat.copy(), "innov_sum": innov,
                "Mi": Mi, "lay": lay, "key": (frozenset([i]) if phi else frozenset(), False, False), "sector": sector}  # fmt: skip

    # ------------------------------------------------------------------ one step

    def step(self, prev: Ellipsoid, inp: StepInput) -> StepResult:
        sector, reading = self._own_range(prev, inp)
        data = self.step_data(prev, inp, sector, reading)
        alpha = np.asarray(inp.alpha, dtype=float)
        res = self._solve_certify(data, prev.rho, alpha, self._wh)
        if res is not None:
            return self._bank(res, data, prev.rho, alpha)
        P_fb = fallback_shape(data, data["own_meas"], data["gamma"], self.W, inp.alpha, self.model) / prev.rho
        return self._fallback(data["x_pred"].copy(), P_fb, data, sector)

    def first(self, prior: Ellipsoid, y: float, gamma: float) -> StepResult:
        """Step 0: the prior updated by ỹ₀, certified like every step; ``fallback``: the prior itself."""
        sector = self.initial_sector(prior, y, gamma)
        data = self.initial_data(prior, y, gamma, sector)
        res = self._solve_certify(data, prior.rho, np.ones(1), self._wh)
        if res is not None:
            return self._bank(res, data, prior.rho, np.ones(1))
        return self._fallback(prior.xhat.copy(), prior.P.copy(), data, sector)

    def _fallback(self, xhat: np.ndarray, P: np.ndarray, data: dict, sector: Sector | None) -> StepResult:
        """The guaranteed set when the solver gave no certificate; FallbackUnavailable if even it is not publishable."""
        if not publishable(xhat, P):
            raise FallbackUnavailable(f"node {self.node_id}: the fallback ellipsoid is not finite and positive definite")
        return StepResult(xhat, P, "fallback", np.nan, data["solve_ms"], data["solver_status"], sector=sector)

    def _bank(self, res: StepResult, data: dict, rho: float, alpha: np.ndarray) -> StepResult:
        """Objective ``bank``: add the fault-weighted set of the same step data as the one to publish."""
        if self._wh_pub is None:
            return res
        solve_ms = data["solve_ms"]
        pub = self._solve_certify(data, rho, alpha, self._wh_pub)
        res.solve_ms = solve_ms + data["solve_ms"]
        if pub is not None:
            pub.solve_ms = res.solve_ms
            res.published = pub
        return res

    def _solve_certify(self, data: dict, rho: float, alpha: np.ndarray, wh: np.ndarray | None) -> StepResult | None:
        """Solve the step's problem for the objective trace(D P), D^½ = diag(wh) (None: trace P), and
        certify the answer; None if there is no certificate."""
        pat = self._patterns[data["key"]]
        t0 = time.perf_counter()
        sol = pat.solver.solve(self._weighted(data, wh) if wh is not None else data, rho)  # type: ignore[attr-defined]
        data["solve_ms"] = 1e3 * (time.perf_counter() - t0)
        data["solver_status"] = sol.status
        self.last_iterations = sol.iterations
        if sol.P is None:
            return None
        if wh is not None:  # back from P' = D^½ P D^½, L' = D^½ L
            wi = 1.0 / wh
            sol = Solution(wi[:, None] * sol.P * wi[None, :], [wi[:, None] * L for L in sol.L], sol.tau, sol.status, sol.iterations)
        if len(sol.L) == 1:
            L, tau, pi0 = sol.L[0], sol.tau[0], data["pi0"][0]
        else:
            L = sum(a * v for a, v in zip(alpha, sol.L))
            tau = sum(a * v for a, v in zip(alpha, sol.tau))
            pi0 = sum(a * p for a, p in zip(alpha, data["pi0"]))
        pi = pi0 - L @ data["ell"][None, :]
        rho_c = certify(sol.P, pi, tau, data["facts"])
        if rho_c is None:
            return None
        P_pub = 0.5 * (sol.P + sol.P.T) * rho_c / rho
        xhat_new = data["x_pred"] + L[:, 0] * data["innov_sum"]
        if not publishable(xhat_new, P_pub):  # a certified set nobody can use: treated as no certificate
            return None
        return StepResult(xhat_new, P_pub, "ok", rho_c, data["solve_ms"], sol.status, L, data["sector"])

    @staticmethod
    def _weighted(data: dict, wh: np.ndarray) -> dict:
        """The step's data for the objective trace(D P), D^½ = diag(wh): Π₀ and the P-row scaling by D^½."""
        wh = wh[:, None]
        return {**data, "pi0": [wh * p for p in data["pi0"]], "Mi": wh * data["Mi"]}


@dataclass
class Solution:
    """A backend's answer in the terms of the LMI: P, and per rule L_ℓ (3×1) and τ_ℓ (one per fact)."""

    P: np.ndarray | None
    L: list[np.ndarray]
    tau: list[np.ndarray]
    status: str
    iterations: int = 0


class _CvxpySolver:
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
        assert self.problem.is_dcp(dpp=True)

    def solve(self, data: dict, rho: float) -> Solution:
        cp = self.cp
        for r in range(self.n_lmi):
            self.p_pi0[r].value = data["pi0"][r]
        self.p_ell.value = data["ell"][None, :]
        for q, Q in enumerate(data["facts"]):
            self.p_q[q].value = Q
        self.p_rho.value = rho
        try:
            with warnings.catch_warnings():  # "inaccurate" answers are certified below, not trusted
                warnings.simplefilter("ignore", UserWarning)
                self.problem.solve(solver=cp.CLARABEL)
            status = str(self.problem.status)
        except cp.error.SolverError as exc:
            return Solution(None, [], [], f"error: {exc}")
        if self.v_P.value is None or status not in ("optimal", "optimal_inaccurate"):
            return Solution(None, [], [], status)
        return Solution(self.v_P.value, [v.value for v in self.v_L], [v.value for v in self.v_tau], status)


def certify(P: np.ndarray, pi: np.ndarray, tau: np.ndarray, facts: list[np.ndarray]) -> float | None:
    """Smallest ρ' (up to rounding) with Πᵀ P⁻¹ Π + Σ τ_m Q_m ⪯ ρ' e₁e₁ᵀ, or None if there is none.

    This is the S-procedure condition itself, checked in floating point on the solver's answer: then
    for the truth eᵀP⁻¹e ≤ ρ' and the published shape P·ρ'/ρ_i satisfies eᵀ(·)⁻¹e ≤ ρ_i.  The
    multipliers are nudged up by the smallest ε in 1e-10, 1e-9, … (relative) that makes the lower block
    strictly negative: every η slot other than the first has a strictly negative diagonal in some Q_m,
    so a solver answer that is feasible up to its tolerance becomes strictly feasible there, at a cost
    of O(ε) in ρ'.
    """
    if not all(np.all(np.isfinite(v)) for v in (P, pi, tau, *facts)):
        return None  # a NaN passes Cholesky silently
    P = 0.5 * (P + P.T)
    try:
        chol = np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        return None
    x = np.linalg.solve(chol, pi)  # Πᵀ P⁻¹ Π = xᵀx
    base = x.T @ x
    tau = np.maximum(tau, 0.0)
    scale = max(1.0, float(np.max(tau)))
    Q = np.asarray(facts)
    K0 = base + np.tensordot(tau, Q, axes=1)
    Qsum = Q.sum(axis=0)
    for eps in scale * 10.0 ** np.arange(-10.0, -2.0):
        K = K0 + eps * Qsum
        K = 0.5 * (K + K.T)
        k11, k, K22 = K[0, 0], K[1:, 0], K[1:, 1:]
        try:
            c22 = np.linalg.cholesky(-K22)
            break
        except np.linalg.LinAlgError:
            continue
    else:
        return None
    y = np.linalg.solve(c22, k)
    rho_c = float(k11 + y @ y)  # Schur complement: K − ρ' e₁e₁ᵀ ⪯ 0 ⇔ K22 ≺ 0 and ρ' ≥ k11 − kᵀK22⁻¹k
    rho_c = rho_c * (1 + 1e-9) + 1e-12
    for _ in range(60):  # confirm with eigenvalues; widen by a hair if rounding says otherwise
        Kc = K.copy()
        Kc[0, 0] -= rho_c
        if np.linalg.eigvalsh(Kc)[-1] <= 0.0:
            return rho_c if rho_c > 0 else None
        rho_c *= 1 + 1e-6
    return None


COND_MAX = 1e13  # largest eigenvalue ratio of a published shape: beyond it E = eᵀP⁻¹e is rounding noise
FALLBACK_INFLATE = 1e-9  # relative: makes a rank-deficient Minkowski bound positive definite


class FallbackUnavailable(ArithmeticError):
    """Even the guaranteed fallback ellipsoid is not representable (the profile's magnitudes are out of range)."""


def publishable(xhat: np.ndarray, P: np.ndarray) -> bool:
    """A centre and shape a node may publish: finite, symmetric positive definite, not degenerate."""
    if not (np.all(np.isfinite(xhat)) and np.all(np.isfinite(P))) or not np.array_equal(P, P.T):
        return False
    try:
        np.linalg.cholesky(P)
        eig = np.linalg.eigvalsh(P)
    except np.linalg.LinAlgError:
        return False
    return bool(eig[0] > 0 and eig[-1] <= COND_MAX * eig[0])


def fallback_shape(data: dict, own: Sensor, gamma_new: float, W: float, alpha: np.ndarray, model: TSModel) -> np.ndarray:
    """A guaranteed shape without the solver: L = 0 and an outer ellipsoid of a Minkowski sum.

    e⁺ = T Ā ρ^½ M z + T D̄ w − G Dv v⁺ − G γ⁺ φ⁺ with |z| ≤ 1, |w| ≤ √W, |v⁺| ≤ √R and, under the sector
    assumption |C̄ x̄⁺| ≤ r_max/h1, |φ⁺| ≤ (1 − h1) r_max.  For terms F_k ξ_k with |ξ_k| ≤ 1 the sum lies
    in {e: eᵀ(Σ F_kF_kᵀ/p_k)⁻¹e ≤ 1} for any p_k > 0 with Σ p_k = 1; p_k ∝ ‖F_k‖_F minimises the trace.

    Computed scale-free (each term divided by its largest entry before squaring) so that magnitudes up to
    the schema's limits neither overflow nor underflow; raises :class:`FallbackUnavailable` when an input
    or the result is not finite (a profile outside those limits) — never a silently wrong shape.
    """
    T, G, Mi = data["T"], data["G"], data["Mi"]
    a, _, d = model.blend(alpha)
    abar = np.zeros((NA, NA))
    abar[:NX, :NX] = a
    dbar = np.r_[d[:, 0], 0.0]
    terms = [T @ abar @ Mi, (T @ dbar * np.sqrt(W))[:, None], G * own.Dv * np.sqrt(own.R)]
    if own.saturated:
        terms.append(G * gamma_new * (1.0 - own.h1) * own.r_max)
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


__all__ = [
    "LocalEstimator", "NeighbourState", "StepInput", "Ellipsoid", "StepResult", "OBJECTIVES", "Objective", "Solution",
    "certify", "fallback_shape", "publishable", "FallbackUnavailable", "BACKENDS",
]  # fmt: skip
