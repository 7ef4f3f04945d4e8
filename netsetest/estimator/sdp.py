"""Local ellipsoidal set-membership estimator of node i (paper (16), (22), corrected as in docs/design.md §2).

One step k → k+1 at node i, with everything a real node has:

    x̂⁺ = T Ā x̂ + T B̄ u + G ỹ⁺ + L Σ_j a_ij y̌_j                                                 (16)

where Ā, B̄, D̄ are the α_k-blend of the rule matrices (variant ``scheduled``), or, in the paper's
variant ``per-rule``, one gain L_ℓ per rule and the estimate blended with α_k.  The error is exactly

    e⁺ = Π(L) η,   η = [1, z_i, s_j (j ∈ N_i∖i), w, v_j (j ∈ N_i), v⁺, φ_j (saturating j), φ⁺]

    Π(L) = Π₀ − L ℓᵀ,  Π₀ η = T Ā ρ_i^½ M_i z_i + T D̄ w − G Dv_i v⁺ − G γ⁺ φ⁺,
    ℓᵀ η = Σ_j a_ij y̌_j(η),  y̌_j = (γ_j h1_j − 1) C̄_j x̂_j + γ_j h1_j C̄_j ρ_j^½ M_j z_j + γ_j φ_j + Dv_j v_j.

For a neighbour j ≠ i, z_j only enters through the scalar C̄_j M_j z_j = c_j s_j with
c_j = (C̄_j P_j C̄_jᵀ)^½ and |s_j| ≤ 1 — an exact reduction (docs/design.md §2).  The truth satisfies the
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
used as the measurement instead of the φ⁺ sector fact, and where that sector rests on the declared
fault bound the published set is cut by |f⁺| ≤ F (:mod:`netsetest.estimator.slab`).  Step 0 updates the prior with ỹ₀
(:meth:`LocalEstimator.first`).  The objective is trace(D P) (a congruence of the LMI); ``bank`` recurs on the
trace-optimal set and weights the fault in what it reshapes for publishing (the cuts).

A step is the prediction (the model part: Π₀, the L-free centre, the own φ⁺ fact; :meth:`LocalEstimator._predict`)
and the update (the neighbours' innovations ℓ and facts, :meth:`LocalEstimator._innovations`; then the
solve and the certificate, :meth:`LocalEstimator._update`), the way filterpy's KalmanFilter keeps
``predict`` and ``update`` apart.  Their data meet in a :class:`~netsetest.estimator.problem.StepData`, part of the
step's context (:meth:`LocalEstimator.context`, every quantity of the step computed once); after the solve come the
declared cuts of :mod:`netsetest.estimator.cuts`, each with the assumption it rests on.

Two backends solve it.  ``clarabel`` (the default, :mod:`netsetest.estimator.conic`) assembles an
exactly equivalent, smaller conic problem for Clarabel directly from the step data (Π₀, ℓ, Q_m) and
maps its answer back to (P, L, τ) of the LMI above; ``cvxpy`` (:mod:`netsetest.estimator.lmi_cvxpy`)
builds the LMI as written once from cvxpy Parameters and re-solves it every step (cvxpy is imported
only when this backend is chosen).  Either way every answer is verified in floating point against the
LMI above (:func:`~netsetest.estimator.certificate.certify`) before it is published; if that fails,
:func:`~netsetest.estimator.certificate.fallback_shape` gives a guaranteed (looser) ellipsoid and the
step is flagged.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

import netsetest.linalg as linalg

from netsetest.config.schema import Scenario
from netsetest.estimator.certificate import FactStack, FallbackUnavailable, certified, fallback_shape, publishable
from netsetest.estimator.conic.closed_form import clarabel_backend
from netsetest.estimator.cuts import (
    FALLBACK_CUTS,
    FIRST_CUTS,
    STEP_CUTS,
    Cut,
    CutStatics,
    NodeSet,
    Slabs,
    StepContext,
    StepFigures,
    StepResult,
    StepSet,
    apply_cuts,
    seed,
)
from netsetest.estimator.health import HEALTH_KEY, HealthAssessment, HealthModel
from netsetest.estimator.lmi_cvxpy import CvxpySolver
from netsetest.estimator.objective import BANK_FAULT_WEIGHT, DEFAULT_OBJECTIVE, FAULT_WEIGHT, OBJECTIVES, Objective
from netsetest.estimator.problem import EtaLayout, OwnUpdate, PatternKey, ProblemSolver, Solution, StepData
from netsetest.estimator import region_engine
from netsetest.estimator.region_engine import Blend, Moved
from netsetest.estimator.sector import (
    FaultBound,
    Interval,
    ReadingRanges,
    Reads,
    Sector,
    StepRanges,
    derive_sector,
    Propagation,
    measurement_interval,
    prior_interval,
    reading_ranges,
    step_ranges,
)
from netsetest.extras import require
from netsetest.models.sensor import NA, NX, Sensor
from netsetest.models.uncertainty import ModelUncertainty
from netsetest.polygon import Polygon
from netsetest.sets import Slab
from netsetest.models.vehicle import N_RULES, TSModel

Variant = Literal["scheduled", "per-rule"]
Backend = Literal["clarabel", "cvxpy"]
BACKENDS = ("clarabel", "cvxpy")


@dataclass(frozen=True)
class NeighbourState:
    """What node i uses of neighbour j's step-k message (static sensor data comes from the topology)."""

    xhat: np.ndarray  # x̂_j (3,)
    P: np.ndarray  # P_j (3, 3)
    rho: float
    gamma: float  # γ_j,k
    innov: float  # y̌_j,k = ỹ_j,k − C̄_j x̂_j,k
    sector: Sector | None = None  # j's sector of step k (None: j models no saturation)
    region: Polygon | None = None  # j's published region of step k (None: none sent): [network] neighbour_sets
    fault: tuple[float, float] | None = None  # j's published fault interval of step k (ProvenSet.bounds): a bounded reading's rate

    @property
    def h1(self) -> float:
        return self.sector.h1 if self.sector is not None else 1.0

    @property
    def has_phi(self) -> bool:
        return self.sector is not None and self.sector.has_phi


@dataclass(frozen=True)
class UpdateInput:
    """What node i has for step k → k+1 besides its own ellipsoid of step k."""

    alpha: np.ndarray  # α(Vx_k)
    u: float  # u_k
    y: float  # ỹ_i,k+1
    gamma: float  # γ_i,k+1
    neigh: dict[int, NeighbourState]  # step-k messages of the in-neighbours that arrived (and i's own)
    readings: dict[int, tuple[float, float]] = field(default_factory=dict)  # reference j → (ỹ_j,k+1, γ_j,k+1) of this step


def _read_only(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


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


@dataclass
class _Pattern:
    """η layout, static ball facts and solver of one φ-slot pattern (which sensors saturate this step)."""

    lay: EtaLayout
    balls: list[np.ndarray]  # (d, d) Q of each ball fact, read-only
    solver: ProblemSolver
    stack: FactStack | None = None  # the balls stacked, once (LocalEstimator._facts)


StepObserver = Callable[["LocalEstimator", "NodeSet", "UpdateInput", "StepResult", float], None]
"""Called after every step with the estimator, its prior, its input, its result and the step's ms."""


class LocalEstimator:
    """The per-node SDP of one node: static data prepared once, solved every step by a backend.

    Which sensors have a φ slot changes from step to step (a sector derived per step may prove that a
    sensor does not saturate): one η layout and solver per pattern, built when first needed.

    Shapes: NA = 3 (the augmented state [β, r, f_i]), NX = 2, d = the η dimension of a pattern
    (``pattern(...).lay.dim``), n_rules = N_RULES.  Static: ``_abar`` (n_rules, NA, NA) Ā_ℓ,
    ``_dbar`` (n_rules, NA) D̄_ℓ (the per-rule variant's), ``_cbar[j]`` (NA,) C̄_j.  Per step: :meth:`context`
    (:class:`~netsetest.estimator.cuts.StepContext`, with the step's :class:`Blend`),
    :meth:`step_data` → :class:`~netsetest.estimator.problem.StepData` (Π₀ (NA, d) per LMI, ℓ (d,),
    Q_m (d, d)), :meth:`step` → :class:`StepResult` (two StepSets: x̂ (NA,), P (NA, NA), L (NA, 1)).
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
        uncertainty: ModelUncertainty | None = None,
        references: dict[int, Sensor] | None = None,
        health: HealthModel | None = None,
        bounded: dict[int, tuple[Sensor, FaultBound]] | None = None,
        neighbour_sets: bool = False,
        own_bound: bool = False,
    ) -> None:
        """``references``: the reference sensors (declared fault-free, j ≠ i) whose same-step readings
        a step may use (UpdateInput.readings; docs/network.md); ``health``: the k-of-N assumption
        (``[network] max_faulty``) under which every node's reading of the step bounds the state; ``bounded``: the
        sensors j ≠ i whose same-step readings cut the region with their declared fault bound (``[network]
        bounded_readings``); ``neighbour_sets``: the region is cut by the in-neighbours' published regions of the
        step before (``[network] neighbour_sets``); ``own_bound``: other nodes use this node's reading with its declared
        fault bound, so its own sets rest on that bound at every step as well (the ``fault-size`` cut, the region's own
        measurement)."""
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
        self.uncertainty = uncertainty  # declared model mismatch e = G ζ (docs/plant.md); None: e = 0
        self.observer: StepObserver | None = None  # a recorder of every step (bench, tests); never changes a result
        self.sensors = neighbours
        self.weights = weights
        self.references = dict(references or {})
        self.health = health
        self.bounded = dict(bounded or {})
        self._bounded_c = {j: _read_only(np.append(sensor.C, 0.0)) for j, (sensor, _) in self.bounded.items()}  # c̄_j = [C_j, 0], once
        self._reference_c = {j: _read_only(np.append(sensor.C, 0.0)) for j, sensor in self.references.items()}  # likewise
        self.neighbour_sets = neighbour_sets
        # a sensor of uᵀx alone (no fault, no saturation): what Propagation.interval needs for the prediction of uᵀx⁺
        self._u_sensor = dataclasses.replace(own, C=health.u, Ds=0.0, saturated=False) if health is not None else own
        read = {**self.references, **{j: sensor for j, (sensor, _) in self.bounded.items()}, **(health.sensors if health is not None else {})}
        self._reads = Reads(read, self.references, self._u_sensor if health is not None else None)  # whose readings a step uses
        self.n_lmi = N_RULES if variant == "per-rule" else 1
        # static data, prepared once: augmented rule matrices Ā_ℓ, B̄_ℓ, D̄_ℓ
        nr = model.A.shape[0]
        self._abar = np.zeros((nr, NA, NA))
        self._abar[:, :NX, :NX] = model.A
        self._dbar = np.zeros((nr, NA))
        self._dbar[:, :NX] = model.Dw[:, :, 0]
        self._ebar = np.zeros((NA, NX))  # [G; 0]: e enters the state rows only
        if uncertainty is not None:
            self._ebar[:NX] = uncertainty.G
        self._cbar = {j: s.Cbar for j, s in neighbours.items()} | {node_id: own.Cbar}
        self._cbar_f = {j: tuple(c.tolist()) for j, c in self._cbar.items()}  # the same as plain floats
        self._own_cbar = own.Cbar
        self._gains: dict[tuple[float, float], tuple[np.ndarray, np.ndarray]] = {}
        self._patterns: dict[PatternKey, _Pattern] = {}
        self.last_iterations = 0  # of the last solve (bench)
        # objective weight: trace(D P) is trace(P') for P' = D^½ P D^½ (a congruence of the LMI)
        self._wh = np.sqrt(np.array([1.0, 1.0, FAULT_WEIGHT])) if objective == "fault" else None
        self._wh_pub = np.sqrt(np.array([1.0, 1.0, BANK_FAULT_WEIGHT])) if objective == "bank" else None
        self.statics = CutStatics(node_id, own, fault_bound, None if health is None else health.tolerance, self._wh, self._wh_pub, own_bound)
        self._wh_published = self.statics.wh_published  # (the published set's objective weights, once)
        self.cuts: tuple[Cut, ...] = STEP_CUTS  # the cuts after every step's solve, in order (a test may leave one out)

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
            lay = EtaLayout(self.node_id, sens, own, self.W, predict, self.uncertainty)
            balls = []
            for f in lay.facts:
                if f.kind == "ball":
                    q = _ball(lay.dim, list(f.slots), f.bound)
                    q.flags.writeable = False
                    balls.append(q)
            n_lmi = self.n_lmi if predict else 1
            solver: ProblemSolver
            if self.backend == "clarabel":
                solver = clarabel_backend(lay, n_lmi)
            else:
                solver = CvxpySolver(lay.dim, lay.n_facts, n_lmi)
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

    def own_sector(self, prev: NodeSet, inp: UpdateInput) -> Sector | None:
        """The own sensor's sector of step k+1 (docs/estimator.md, "Adaptive sector")."""
        return self.context(prev, inp).sector

    def initial_sector(self, prior: NodeSet, y: float, gamma: float) -> Sector | None:
        """The own sensor's sector of step 0: the prior (Assumption 1), |f₀| ≤ F and the measurement."""
        if not self.own.saturated:
            return None
        meas = measurement_interval(self.own, y, gamma)
        return derive_sector(self.own, self.fault_bound, meas, prior_interval(self.own, self.fault_bound, prior.xhat, prior.P, prior.rho))

    def step_data(
        self,
        prev: NodeSet,
        inp: UpdateInput,
        sector: Sector | None,
        reading: Interval | None = None,
        blend: Blend | None = None,
        phi_from: frozenset[int] | None = None,
    ) -> StepData:
        """The LMI data of step k → k+1: the prediction (Π₀, x̂ part, own facts) and the neighbours' update (ℓ).

        ``reading``: a proven interval [lo, hi] ∋ r⁺ used as the own measurement instead of the sector:
        r⁺ = m + Dv' v with m its centre, Dv' = (hi − lo)/(2√R) and v² ≤ R (so Θ = [E; C̄], no φ⁺).
        ``blend``: the step's blended model (:meth:`context` passes its own; None: blended here); ``phi_from``: the
        in-neighbours whose published sector has a φ slot (:meth:`context` passes the step's; None: read here).
        """
        blend = blend if blend is not None else Blend.of(self.model, inp.alpha)
        neigh = inp.neigh
        if phi_from is None:
            phi_from = frozenset(j for j in self.sensors if j in neigh and neigh[j].has_phi)
        phi_new = sector is not None and sector.has_phi and reading is None
        key: PatternKey = (phi_from, phi_new, True)
        pat = self.pattern(*key)
        own = self._own_update(inp, sector, reading, phi_new)
        Mi = linalg.covering_factor(prev.P, prev.rho)  # ρ_i^½ M_i, M_i M_iᵀ ⪰ P_i exactly
        pi0, x_pred, own_fact = self._predict(pat.lay, prev, inp, blend, own, Mi, sector)
        ell, facts = self._innovations(pat.lay, pat.balls, neigh, Mi)
        if own_fact is not None:
            facts.append(own_fact)
        innov_sum = sum(self.weights[j] * neigh[j].innov for j in pat.lay.neigh if j in neigh)  # Σ_j a_ij y̌_j
        return StepData(tuple(pi0), ell, tuple(facts), x_pred, float(innov_sum), Mi, pat.lay, key, sector, own)

    def _reading_slabs(self, ranges: ReadingRanges, health: HealthAssessment | None) -> Slabs:
        """What the step's readings prove, as slabs lo ≤ c̄ᵀx̄⁺ ≤ hi (c̄ (NA,)), keyed by the reference's id, and
        by :data:`~netsetest.estimator.health.HEALTH_KEY` for the k-of-N interval of every reading (the
        hypotheses pruned by the node's own prediction of uᵀx⁺).

        A reference j (fault declared 0): C̄_j x̄_j = C_j x.  A reading at the sensor's limit bounds one
        side only: the other comes from the node's own set propagated through the step (both hold
        wherever the step's cone does; ``ranges.closed``); a reading that still leaves a side open is left out."""
        out: Slabs = {j: Slab(self._reference_c[j], iv.lo, iv.hi) for j, iv in ranges.closed.items()}
        if self.health is not None and health is not None and health.interval is not None:
            out[HEALTH_KEY] = Slab(np.append(self.health.u, 0.0), health.interval.lo, health.interval.hi)
        return out

    def _assess_health(self, ranges: ReadingRanges, base: StepBase) -> HealthAssessment:
        """The step's k-of-N interval of uᵀx⁺ and whether the own fault is pinned, once per step (both the
        readings' update and the pin use it).  Hypotheses are pruned by uᵀx⁺ over the node's own set through
        the step: a majority that agrees only outside it is none."""
        assert self.health is not None and ranges.u_pred is not None and base.span is not None
        pred, (a, b) = ranges.u_pred, base.span  # and over the moved region (both hold uᵀx⁺ wherever
        lo, hi = max(pred.lo, a), min(pred.hi, b)  # the prior does; disjoint: one broke)
        within = (lo, hi) if lo <= hi else (pred.lo, pred.hi)
        measured = {j: (iv.lo, iv.hi) for j, iv in ranges.measured.items()} | {self.node_id: (base.meas.lo, base.meas.hi)}
        return self.health.assess(self.node_id, measured, within, pin=True)

    def _own_update(self, inp: UpdateInput, sector: Sector | None, reading: Interval | None, phi_new: bool) -> OwnUpdate:
        """How step k+1 uses the own measurement: ỹ⁺ (or the reading's centre), its γ⁺, h1, Dv and T, G."""
        own = self.own
        y_new, gamma_new, dv_new = inp.y, inp.gamma, own.Dv
        h1_new = sector.h1 if sector is not None else own.h1
        if reading is not None:  # r⁺ = m + Dv' v: the centre m, Dv' = (hi − lo)/(2√R)
            y_new, gamma_new, h1_new = 0.5 * (reading.lo + reading.hi), 1.0, 1.0
            dv_new = 0.5 * (reading.hi - reading.lo) / np.sqrt(own.R)
        T, G = self.descriptor_gains(gamma_new, h1_new)
        same = (dv_new, phi_new, h1_new) == (own.Dv, own.saturated, own.h1)  # (most steps: no copy to make)
        return OwnUpdate(T, G, own if same else dataclasses.replace(own, Dv=dv_new, saturated=phi_new, h1=h1_new), y_new, gamma_new)

    def _predict(
        self, lay: EtaLayout, prev: NodeSet, inp: UpdateInput, blend: Blend, own: OwnUpdate, Mi: np.ndarray, sector: Sector | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The model part of step k → k+1: Π₀ (n_rules, NA, d), the L-free centre x̂ (NA,) and the own
        sensor's φ⁺ sector fact (d, d) (None without φ⁺)."""
        d, T, g = lay.dim, own.T, own.G[:, 0]
        TA = T @ blend.abar  # the blended Ā, B̄, D̄ (exact for the truth)
        Td = T @ blend.dbar
        y_new, dv_new, gamma_new = own.y, own.sensor.Dv, own.gamma
        if self.variant == "scheduled":
            pi0 = np.zeros((1, NA, d))
            pi0[0][:, lay.z] = TA @ Mi  # T Ā ρ_i^½ M_i z_i
            pi0[0][:, lay.w] = Td  # T D̄ w
        else:
            pi0 = np.zeros((N_RULES, NA, d))
            pi0[:, :, lay.z] = T @ self._abar @ Mi  # per rule ℓ: T Ā_ℓ ρ_i^½ M_i z_i
            pi0[:, :, lay.w] = self._dbar @ T.T  # T D̄_ℓ w
        if lay.e:
            pi0[:, :, lay.e] = T @ self._ebar  # T [G; 0] ζ: the model mismatch e (every rule: e is of the blend)
        pi0[:, :, lay.v_new] = -g * dv_new  # − G Dv_i v⁺
        if lay.phi_new is not None:
            pi0[:, :, lay.phi_new] = -g * gamma_new  # − G γ⁺ φ⁺
        # L-free part of the centre; the blended matrices are exact for the truth in both variants
        x_pred = TA @ prev.xhat + (T @ blend.bbar) * inp.u + g * y_new  # (16): T Ā x̂ + T B̄ u + G ỹ⁺
        if lay.phi_new is None:
            return pi0, x_pred, None
        cbar = self._own_cbar
        cg = float(cbar @ g)
        g_new = np.zeros(d)  # r⁺ = C̄ x̄⁺ of the truth, with the blended model in every rule
        g_new[0] = cbar @ x_pred
        g_new[lay.z] = cbar @ TA @ Mi
        g_new[lay.w] = cbar @ Td
        if lay.e:
            g_new[lay.e] = cbar @ T @ self._ebar
        g_new[lay.v_new] = -cg * dv_new
        g_new[lay.phi_new] = -cg * gamma_new
        assert sector is not None  # a φ⁺ slot exists only with a sector
        return pi0, x_pred, _sector(d, lay.phi_new, g_new, sector.h)  # φ⁺ (h r⁺ − φ⁺) ≥ 0

    def _innovations(
        self, lay: EtaLayout, balls: list[np.ndarray], neigh: dict[int, NeighbourState], Mi: np.ndarray, weights: dict[int, float] | None = None
    ) -> tuple[np.ndarray, list[np.ndarray]]:
        """The update's data: ℓ (d,) with ℓᵀη = Σ_j a_ij y̌_j(η), and the facts (d, d): the balls and each
        neighbour's φ_j sector fact.

        A missing neighbour's slots stay zero (its facts then hold with η-slot 0).
        """
        weights = weights or self.weights
        d = lay.dim
        ell = [0.0] * d  # (plain floats: a handful of scalars per neighbour, cheaper than numpy's per-call set-up)
        facts: list[np.ndarray] = list(balls)
        for j in lay.neigh:
            sj, nb = (self.own if j == self.node_id else self.sensors[j]), neigh.get(j)
            phi = lay.phi.get(j)
            g_r = np.zeros(d) if phi is not None else None  # r_j = gᵀη (for the sector fact)
            if nb is not None:
                # y̌_j = (γ_j h1_j − 1) C̄_j x̂_j + γ_j h1_j C̄_j ρ_j^½ M_j z_j + γ_j φ_j + Dv_j v_j
                a, gh = weights[j], nb.gamma * nb.h1
                c0, c1, c2 = self._cbar_f[j]
                x0, x1, x2 = nb.xhat.tolist()
                cx = c0 * x0 + c1 * x1 + c2 * x2
                ell[0] += a * (gh - 1.0) * cx
                ell[lay.v[j]] += a * sj.Dv
                if j == self.node_id:
                    row = self._cbar[j] @ Mi  # the node's own z_i
                    for k, r in zip(lay.z, row.tolist()):
                        ell[k] += a * gh * r
                    if g_r is not None:
                        g_r[lay.z] = row
                else:  # C̄_j M_j z_j = c_j s_j, c_j = (ρ_j C̄_j P_j C̄_jᵀ)^½
                    (p00, p01, p02), (p10, p11, p12), (p20, p21, p22) = nb.P.tolist()
                    q = c0 * (p00 * c0 + p01 * c1 + p02 * c2) + c1 * (p10 * c0 + p11 * c1 + p12 * c2) + c2 * (p20 * c0 + p21 * c1 + p22 * c2)
                    c_j = math.sqrt(max(nb.rho * q, 0.0))
                    ell[lay.s[j]] += a * gh * c_j
                    if g_r is not None:
                        g_r[lay.s[j]] = c_j
                if g_r is not None:
                    g_r[0] = cx
                    ell[phi] += a * nb.gamma  # type: ignore[index]  # phi is set where g_r is
            if phi is not None:  # φ_j (h_j r_j − φ_j) ≥ 0
                facts.append(_sector(d, phi, g_r, nb.sector.h))  # type: ignore[union-attr,arg-type]  # j has a φ slot only with a published sector
        return np.array(ell), facts

    def initial_data(self, prior: NodeSet, y: float, gamma: float, sector: Sector | None) -> StepData:
        """Step 0: x̂₀ = x̂ + L(ỹ₀ − C̄x̂), error e = ρ^½Mz − L y̌₀(η) with y̌₀ the own innovation."""
        i = self.node_id
        phi = sector is not None and sector.has_phi
        key: PatternKey = (frozenset([i]) if phi else frozenset(), False, False)
        pat = self.pattern(*key)
        lay = pat.lay
        Mi = linalg.covering_factor(prior.P, prior.rho)  # ρ^½ M, M Mᵀ ⪰ P exactly
        pi0 = np.zeros((1, NA, lay.dim))
        pi0[0][:, lay.z] = Mi  # e = ρ^½ M z − L y̌₀(η)
        innov = float(y - self._own_cbar @ prior.xhat)  # y̌₀ = ỹ₀ − C̄ x̂
        me = NeighbourState(prior.xhat, prior.P, prior.rho, gamma, innov, sector)
        ell, facts = self._innovations(lay, pat.balls, {i: me}, Mi, {i: 1.0})
        return StepData(tuple(pi0), ell, tuple(facts), prior.xhat.copy(), innov, Mi, lay, key, sector)

    # ------------------------------------------------------------------ one step

    @classmethod
    def for_node(
        cls,
        scenario: Scenario,
        node_id: int,
        variant: Variant = "scheduled",
        objective: Objective = DEFAULT_OBJECTIVE,
        backend: Backend = "clarabel",
    ) -> LocalEstimator:
        """The estimator of node ``node_id`` as the node runs it: its sensor, its in-neighbours' sensors and
        weights, the scenario's model and wind bound, and its declared fault bound.  The node, the
        benchmark and the tests all build it here (a hand-built copy without the fault bound once solved
        another SAIM problem than the nodes did)."""
        n = scenario.node(node_id)
        return cls(
            node_id,
            n.sensor,
            {j: scenario.node(j).sensor for j in n.in_weights},
            n.in_weights,
            scenario.model,
            scenario.W,
            variant,
            backend,
            FaultBound(n.fault_rate, n.fault_size),
            objective,
            scenario.uncertainty,
            {j: scenario.node(j).sensor for j in scenario.references() if j != node_id},
            HealthModel.of(scenario, node_id),
            {j: (scenario.node(j).sensor, FaultBound(scenario.node(j).fault_rate, scenario.node(j).fault_size)) for j in scenario.bounded_sources(node_id)},
            scenario.neighbour_sets and not scenario.reads_everyone(node_id),
            scenario.bound_relied(node_id),
        )

    def step(self, prev: NodeSet, inp: UpdateInput, prepared: Prepared | None = None) -> StepResult:
        """Step k → k+1: the step's context, the solve, then the declared cuts (:mod:`netsetest.estimator.cuts`);
        the fallback without a certificate.  ``prepared``: what :meth:`prepare` computed of this step before its
        readings came (the same ``prev`` and the same input but for the readings); the result is the same
        with or without it.  ``observer`` (if set) sees every step: the estimator, its inputs, its result and
        its time (a prepared step's: both parts)."""
        if self.observer is None:
            return self._step(prev, inp, prepared)
        t0 = time.perf_counter()
        res = self._step(prev, inp, prepared)
        self.observer(self, prev, inp, res, 1e3 * (time.perf_counter() - t0) + (prepared.ms if prepared is not None else 0.0))
        return res

    def prepare(self, prev: NodeSet, inp: UpdateInput) -> Prepared:
        """The part of step k → k+1 its readings do not enter: the context before them and the solve of the set
        the node recurs on.  A node computes it while the step's readings are on their way (the same-step
        exchange, docs/network.md) and hands it to :meth:`step` with them; ``inp.readings`` is not read."""
        t0 = time.perf_counter()
        base = self._base(prev, inp)
        first = self._solve_certify(base.data, prev.rho, np.asarray(inp.alpha, dtype=float), self._wh, self._facts(base.data))
        return Prepared(prev, inp, base, first, 1e3 * (time.perf_counter() - t0))

    def _step(self, prev: NodeSet, inp: UpdateInput, prepared: Prepared | None = None) -> StepResult:
        """The step read top to bottom: its context (built once), the solve, the cuts."""
        if prepared is not None:
            assert prepared.of(prev, inp), "a prepared step of another prior or input"
        base = prepared.base if prepared is not None else self._base(prev, inp, inp.readings)
        ctx = self._context(prev, inp, base)
        res = self._solve_step(ctx, inp, prepared.first if prepared is not None else None)
        if res.figures.status == "fallback":  # no certificate: the region of the own measurement alone (no reading listed)
            return apply_cuts(FALLBACK_CUTS, dataclasses.replace(ctx, slabs={}, region_slabs={}), res)
        return apply_cuts(self.cuts, ctx, res)

    def context(self, prev: NodeSet, inp: UpdateInput) -> StepContext:
        """What step k → k+1 knows before its solve, each quantity computed once: the blended model, the own
        sector and measurement interval, the LMI data, the moved region, the k-of-N assessment and the readings'
        slabs."""
        return self._context(prev, inp, self._base(prev, inp, inp.readings))

    def _base(self, prev: NodeSet, inp: UpdateInput, readings: dict[int, tuple[float, float]] | None = None) -> StepBase:
        """The context's part the step's readings do not enter, and what the readings prove where they are here
        (``readings``; None: not read, :meth:`prepare`): the region through the step (one call into the region engine),
        the sectors and intervals (one call into :mod:`~netsetest.estimator.sector`), the LMI data."""
        moved = self._moved_region(prev, inp)
        blend = moved.blend
        prop = Propagation(prev.xhat, prev.P, prev.rho, blend.a, blend.b, blend.d, inp.u, self.W, self.uncertainty)  # the step's one
        neighbours = {j: inp.neigh[j].sector for j in self.sensors if j in inp.neigh}
        ranges = step_ranges(self.own, self.fault_bound, inp.y, inp.gamma, prop, neighbours, readings, self._reads)
        data = self.step_data(prev, inp, ranges.sector, ranges.reading, blend, ranges.phi_from)
        return StepBase(blend, ranges.meas, ranges.sector, data, moved.region, prop, moved.sets, ranges, moved.span)

    def _context(self, prev: NodeSet, inp: UpdateInput, base: StepBase) -> StepContext:
        """The step's context from its ``base`` and its readings: the k-of-N assessment and the readings' slabs (the
        references' and the k-of-N interval; the bounded readings', which cut the region alone)."""
        ranges = base.ranges.readings if base.ranges.readings is not None else reading_ranges(base.prop, inp.readings, self._reads)
        health = self._assess_health(ranges, base) if self.health is not None and inp.readings else None
        slabs = self._reading_slabs(ranges, health)
        region_slabs, rate_from = self._bounded_slabs(inp, ranges.measured)
        return StepContext(
            self.statics,
            prev.rho,
            inp.y,
            inp.gamma,
            base.meas,
            base.sector,
            base.data,
            base.moved,
            slabs,
            health,
            blend=base.blend,
            region_slabs=region_slabs,
            sets=base.sets | rate_from,
            region_without=prev.region_without,
        )

    def _bounded_slabs(self, inp: UpdateInput, measured: Mapping[int, Interval]) -> tuple[Slabs, frozenset[int]]:
        """What the step's bounded readings prove of x⁺ (docs/network.md, *What a node takes from its network*): sensor j's reading
        gives C̄_j x̄_j⁺ = C_j x⁺ + Ds_j f_j⁺ in its measurement interval (a side at the sensor's limit open), and its
        declared bound f_j⁺ ∈ [−F_j, F_j], and ∈ j's published fault interval of step k widened by δ_j where its state of
        step k is in (the rate bound), so C_j x⁺ ∈ [lo − max Ds_j f_j⁺, hi − min Ds_j f_j⁺]; keyed by j.  The nodes whose
        published set the rate used (their state then names the set: it must hold the truth)."""
        out: Slabs = {}
        rate_from: set[int] = set()
        for j in inp.readings:
            src = self.bounded.get(j)
            if src is None:
                continue
            sensor, bound = src
            f_lo, f_hi = (-bound.size, bound.size) if bound.size is not None else (-math.inf, math.inf)
            nb = inp.neigh.get(j)
            if bound.rate is not None and nb is not None and nb.fault is not None:
                lo, hi = nb.fault[0] - bound.rate, nb.fault[1] + bound.rate
                if lo > f_lo or hi < f_hi:
                    f_lo, f_hi = max(f_lo, lo), min(f_hi, hi)
                    rate_from.add(j)
            if not (math.isfinite(f_lo) and math.isfinite(f_hi)) or f_lo > f_hi:
                continue  # no bound on f_j⁺ (or an empty one: an assumption broke), so nothing on C_j x⁺
            iv = measured[j]  # (every bounded reading's measurement interval: sector.step_ranges)
            ds_lo, ds_hi = sorted((sensor.Ds * f_lo, sensor.Ds * f_hi))
            lo, hi = iv.lo - ds_hi, iv.hi - ds_lo
            if math.isfinite(lo) or math.isfinite(hi):
                out[j] = Slab(self._bounded_c[j], lo, hi)
        return out, frozenset(rate_from & set(out))

    def _solve_step(self, ctx: StepContext, inp: UpdateInput, first: tuple[StepResult | None, _Solve] | None = None) -> StepResult:
        """The certified set the node continues from and publishes (the cuts may make another to publish; the readings
        cut both, :data:`~netsetest.estimator.cuts.READINGS` and the region); the fallback where it has no certificate.
        One solve: a second one of the readings alone, published where smaller in the published objective, made every
        published coordinate the same or wider on every reading topology (issue 45, docs/network.md).
        ``first``: the solve's outcome, computed before the readings came (:meth:`prepare`)."""
        data, rho, alpha = ctx.data, ctx.rho, np.asarray(inp.alpha, dtype=float)
        res, solve = first if first is not None else self._solve_certify(data, rho, alpha, self._wh, self._facts(data))  # the set the node recurs on
        if res is None:
            assert data.own is not None  # a predicting step always has its own update
            assert ctx.blend is not None  # a predicting step's context has its blend
            P_fb = fallback_shape(data.Mi, data.own, self.W, ctx.blend.abar, ctx.blend.dbar, self.uncertainty) / rho
            return self._fallback(data.x_pred.copy(), P_fb, solve, ctx.sector)
        return res

    def _moved_region(self, prev: NodeSet, inp: UpdateInput) -> Moved:
        """The states x⁺ the prior allows: its region (else the box of its ellipsoid), cut by the in-neighbours'
        published regions of the same step k (``neighbour_sets``: each holds x_k wherever that neighbour's set holds
        the truth), through the step's blended dynamics (exact for the truth), plus the disturbance's and the declared
        model mismatch's bounds (a box around e = G ζ holds it for either kind); the neighbours whose region cut it, the
        step's blend and, under k-of-N, the moved region's interval of uᵀx⁺ (:func:`~netsetest.estimator.region_engine.advance`)."""
        region = prev.region if prev.region is not None else seed(prev)
        others = {j: nb.region for j, nb in inp.neigh.items() if j != self.node_id and nb.region is not None} if self.neighbour_sets else {}
        u = None if self.health is None else self.health.u
        return region_engine.advance(self.model, inp.alpha, region, others, inp.u, self.W, self.uncertainty, u)

    def first(self, prior: NodeSet, y: float, gamma: float) -> StepResult:
        """Step 0: the prior updated by ỹ₀, certified like every step (``fallback``: the prior itself), then
        :data:`~netsetest.estimator.cuts.FIRST_CUTS` (the region starts from the prior: Assumption 1)."""
        sector = self.initial_sector(prior, y, gamma)
        data = self.initial_data(prior, y, gamma, sector)
        res, solve = self._update(data, prior.rho, np.ones(1))
        if res is None:
            res = self._fallback(prior.xhat.copy(), prior.P.copy(), solve, sector)
        meas = measurement_interval(self.own, y, gamma)
        ctx = StepContext(self.statics, prior.rho, y, gamma, meas, sector, data, seed(prior), {}, None, listed=False)
        return apply_cuts(FIRST_CUTS, ctx, res)

    def _fallback(self, xhat: np.ndarray, P: np.ndarray, solve: _Solve, sector: Sector | None) -> StepResult:
        """The guaranteed set when the solver gave no certificate; FallbackUnavailable if even it is not publishable."""
        if not publishable(xhat, P):
            raise FallbackUnavailable(f"node {self.node_id}: the fallback ellipsoid is not finite and positive definite")
        s = StepSet(xhat, P, np.nan, np.zeros((NA, 1)))
        return StepResult(s, s, StepFigures("fallback", solve.ms, solve.status), sector)

    def _update(self, data: StepData, rho: float, alpha: np.ndarray) -> tuple[StepResult | None, _Solve]:
        """The certified set of the step's data (None: no certificate) and the solve's figures."""
        return self._solve_certify(data, rho, alpha, self._wh, self._facts(data))

    def _solve_certify(
        self, data: StepData, rho: float, alpha: np.ndarray, wh: np.ndarray | None, facts: FactStack | tuple[np.ndarray, ...]
    ) -> tuple[StepResult | None, _Solve]:
        """Solve the step's problem for the objective trace(D P), D^½ = diag(wh) (None: trace P), and
        certify the answer; None if there is no certificate."""
        answer, solve = self._solve(data, alpha, wh, rho)
        if answer is None:
            return None, solve
        s = self._certify(answer, data, rho, facts)
        return (None if s is None else StepResult(s, s, StepFigures("ok", solve.ms, answer.status), data.sector)), solve

    def _solve(self, data: StepData, alpha: np.ndarray, wh: np.ndarray | None, rho: float) -> tuple[_Answer | None, _Solve]:
        """The backend's answer to the step's problem for the objective trace(D P), D^½ = diag(wh) (None:
        trace P), mapped back to the unweighted problem and blended over the rules (not yet certified)."""
        pat = self._patterns[data.key]
        t0 = time.perf_counter()
        sol = pat.solver.solve(_weighted(data, wh) if wh is not None else data, rho)
        solve = _Solve(1e3 * (time.perf_counter() - t0), sol.status)
        self.last_iterations = sol.iterations
        if sol.P is None:
            return None, solve
        if wh is not None:  # back from P' = D^½ P D^½, L' = D^½ L
            wi = 1.0 / wh
            sol = Solution(wi[:, None] * sol.P * wi[None, :], [wi[:, None] * L for L in sol.L], sol.tau, sol.status, sol.iterations)
        assert sol.P is not None  # checked above: a Solution without P is no answer
        if len(sol.L) == 1:
            return _Answer(sol.P, sol.L[0], sol.tau[0], data.pi0[0], sol.status), solve
        # per-rule: L = Σ_ℓ α_ℓ L_ℓ (and τ, Π₀ alike)
        L = sum(a * v for a, v in zip(alpha, sol.L))
        tau = sum(a * v for a, v in zip(alpha, sol.tau))
        pi0 = sum(a * p for a, p in zip(alpha, data.pi0))
        return _Answer(sol.P, L, tau, pi0, sol.status), solve

    def _facts(self, data: StepData) -> FactStack | tuple[np.ndarray, ...]:
        """The step's facts: a pattern whose facts are all its static balls (no φ slot: every NSNIM step) stacks them
        once (:class:`~netsetest.estimator.certificate.FactStack`); else they are stacked by the certificate."""
        pat = self._patterns[data.key]
        if len(data.facts) != len(pat.balls):  # (per-step sector facts after the balls)
            return data.facts
        if pat.stack is None:
            pat.stack = FactStack.of(pat.balls)
        return pat.stack

    def _certify(self, answer: _Answer, data: StepData, rho: float, facts: FactStack | tuple[np.ndarray, ...]) -> StepSet | None:
        """The set of an answer where the certificate holds and the set is publishable (one call into the
        certificate); else None."""
        L = answer.L
        gain = bool(L.any())  # (L = 0: Π₀ and x̂_pred as they are, the same floats)
        pi = answer.pi0 - L @ data.ell[None, :] if gain else answer.pi0  # Π(L) = Π₀ − L ℓᵀ
        xhat_new = data.x_pred + L[:, 0] * data.innov_sum if gain else data.x_pred.copy()  # (16): x̂⁺ = x̂_pred + L Σ_j a_ij y̌_j
        out = certified(answer.P, pi, answer.tau, facts, xhat_new, rho)  # P published = P_solver·ρ'/ρ_i
        return None if out is None else StepSet(xhat_new, out[1], out[0], L)


@dataclass(frozen=True)
class StepBase:
    """The part of a step's context (:class:`~netsetest.estimator.cuts.StepContext`) its readings do not enter."""

    blend: Blend
    meas: Interval
    sector: Sector | None
    data: StepData
    moved: Polygon
    prop: Propagation  # the node's set of step k through the step: what it proves of any sensor's r⁺
    sets: frozenset[int]  # the in-neighbours whose published region cut the moved one
    ranges: StepRanges  # what the step needs of sector.py (its readings' part None where computed before them)
    span: tuple[float, float] | None  # under k-of-N: the moved region's interval of uᵀx⁺


@dataclass(frozen=True)
class Prepared:
    """A step computed up to its readings (:meth:`LocalEstimator.prepare`): the prior and the input it was
    computed for (:meth:`of` checks them), its context's base, the first solve's outcome and its time [ms]."""

    prev: NodeSet
    inp: UpdateInput
    base: StepBase
    first: tuple[StepResult | None, _Solve]
    ms: float

    def of(self, prev: NodeSet, inp: UpdateInput) -> bool:
        """Whether it was computed for this prior and this input, whatever the input's readings (the
        neighbours' states: the very same messages)."""
        p, q = self.prev, self.inp
        return (
            all(a is b or np.array_equal(a, b) for a, b in ((p.xhat, prev.xhat), (p.P, prev.P), (q.alpha, inp.alpha)))
            and p.rho == prev.rho
            and p.region is prev.region
            and (q.u, q.y, q.gamma) == (inp.u, inp.y, inp.gamma)
            and q.neigh.keys() == inp.neigh.keys()
            and all(q.neigh[j] is inp.neigh[j] for j in q.neigh)
        )


@dataclass(frozen=True)
class _Answer:
    """A backend's answer to one step, mapped back and blended over the rules: P (NA, NA), L (NA, 1),
    τ (the facts' multipliers) and Π₀ (NA, d) of the truth's model; to be certified."""

    P: np.ndarray
    L: np.ndarray
    tau: np.ndarray
    pi0: np.ndarray
    status: str


@dataclass(frozen=True)
class _Solve:
    """The figures of one backend call: its wall time and status."""

    ms: float
    status: str


def _weighted(data: StepData, wh: np.ndarray) -> StepData:
    """The step's data for the objective trace(D P), D^½ = diag(wh): Π₀ and the P-row scaling by D^½."""
    w = wh[:, None]
    return dataclasses.replace(data, pi0=tuple(w * p for p in data.pi0), Mi=w * data.Mi)


__all__ = [
    "BACKENDS",
    "Backend",
    "Blend",
    "NodeSet",
    "LocalEstimator",
    "NeighbourState",
    "Objective",
    "UpdateInput",
    "StepData",
    "StepFigures",
    "StepResult",
    "StepSet",
    "Variant",
]
