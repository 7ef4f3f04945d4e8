"""Zonotopic set-membership estimator with W-radius minimisation, for one node's [β, r, f_i].

Reference: S. Ifqir, V. Puig, D. Ichalal, N. Aït Oufroukh, S. Mammar, "Zonotopic set-membership
estimation for switched systems based on W_i-radius minimization: vehicle application", IFAC World
Congress 2020 ([Ifqir-zonotope]): prediction by exact Minkowski sums, a parameterised intersection with the
measurement strip (Theorem 1, gain Λ), W-radius as the size to minimise, order reduction ↓q,W
(Property 3).  Derivation and the choices made for this problem: docs/estimators/zonotope_w_radius.md.

Implements the estimator interface (estimator/base.py, name ``zonotope``); it ignores the neighbours'
sets (001 is a single-sensor observer), and takes a reference sensor's reading of the same step as one
more strip (Theorem 1; docs/network.md).  :class:`ZonotopeEstimator` steps through one node's
inputs, using only what that node has (its prior, its measurements, u, Vx), and publishes a
:class:`~netsetest.sets.SumSet` ⟨c, G⟩ ⊕ M·S, where S is the node's prior ellipsoid cut by its step-0
slabs (kept exact: an ellipsoid is not a zonotope) and ⟨c, G⟩ collects every later uncertainty.

Two constructions, chosen per node as ``netsetest exact --fault-bounds`` does:

- **free fault** (no declared bound applied): the descriptor form of [Mousavinejad] (18)–(20), which is 001's
  unknown-input decoupling P + M C = I, P E = 0 with the fault as the unknown input.  With Θ = [E; C̄]
  of full column rank, x̄⁺ = T E x̄⁺ + G C̄ x̄⁺ holds for every x̄⁺, so the step
  x̄⁺ = T_x(Ā x + B̄ u + D̄ w) + G r⁺, r⁺ = C̄ x̄⁺ ∈ [lo, hi], is an exact parameterisation of the
  consistent set: no strip is left to intersect (001's Λ term cancels, C̄ P = 0) and without reduction
  the published set is the exact local set.
- **bounded fault** (declared |f⁺ − f| ≤ δ and/or |f| ≤ F applied, needed where a saturated
  measurement leaves r one-sided): in the lifted space [x̄⁺; f_k], the descriptor step where the
  measurement is two-sided, else the dynamics with f⁺ = f + δ s (or f⁺ ∈ [−F, F]); then one strip per
  remaining fact (one-sided measurement, f⁺ − f_k ∈ [−δ, δ], |f⁺| ≤ F) intersected by 001's Theorem 1,
  X ∩ {lo ≤ aᵀx ≤ hi} ⊆ (I − λaᵀ)X ⊕ λ[lo, hi] for any λ; f_k is then projected out.

The gain λ: ``gain="frobenius"`` is the closed form minimising the Frobenius W-radius tr(Gᵀ W G) (001's
size measure in its tractable form; the optimum does not depend on W); ``gain="hull"`` (default)
minimises each coordinate's interval-hull width, the published quantity (row j of the result depends on
λ_j only).  Measured on the paper SAIM run, the hull gain is 1.001× exact on the fault where the Frobenius
gain is 2.5×.  W still weights the order reduction ↓q,W.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from netsetest.config.schema import FaultBoundsMode, NodeConfig, Scenario
from netsetest.estimator.base import BASE_ASSUMPTIONS, Assumption, EstimatorError, NeighbourSet, SetEstimator, ReadingSlabs, StepInput
from netsetest.models.sensor import E_DESCRIPTOR, NA, NX
from netsetest.sets import Ellipsoid, SlicedEllipsoid, Slab, SumSet, Zonotope

_E3 = np.eye(NA)[2]
NEGLIGIBLE_CUT = 1e-12  # a strip narrower than the set by less than this (relative) carries no information
_TIE = 1e-9  # relative width difference below which two gains count as equally good
_KINK_FLOOR = 1e-9  # generators with |aᵀg| below this (relative) give no usable kink
Gain = Literal["hull", "frobenius"]


def reduce_order(G: np.ndarray, order: int, W: np.ndarray) -> np.ndarray:
    """↓q,W of 001 Property 3: keep the q − n largest generators in ‖·‖_W, box the others (interval hull)."""
    n, m = G.shape
    if order < n:
        raise ValueError(f"reduction order q = {order} must be at least the dimension n = {n}")
    if m <= order:
        return G
    norms = np.einsum("ij,ik,kj->j", G, W, G)
    idx = np.argsort(-norms, kind="stable")
    keep, box = G[:, idx[: order - n]], G[:, idx[order - n :]]
    return np.hstack([keep, np.diag(np.abs(box).sum(axis=1))])


def frobenius_gain(G: np.ndarray, ell: np.ndarray, a: np.ndarray, sigma: float) -> np.ndarray:
    """λ minimising the Frobenius W-radius tr(G'ᵀ W G') of the intersection (any W ≻ 0 gives the same)."""
    gamma_m = G @ G.T + ell @ ell.T
    return gamma_m @ a / (a @ gamma_m @ a + sigma**2)


def _row_width(lam: np.ndarray, G: np.ndarray, ell: np.ndarray, a: np.ndarray, sigma: float) -> np.ndarray:
    """Half-width of every row j of (I − λaᵀ)[G, ell] ⊕ λσ for the candidate gains lam (rows, candidates)."""
    g, e = a @ G, a @ ell
    zono = np.abs(G[:, None, :] - lam[:, :, None] * g[None, None, :]).sum(axis=2)
    ellip = np.linalg.norm(ell[:, None, :] - lam[:, :, None] * e[None, None, :], axis=2)
    return zono + ellip + sigma * np.abs(lam)


def _hull_gain(G: np.ndarray, ell: np.ndarray, a: np.ndarray, sigma: float) -> np.ndarray:
    """λ minimising every row's interval-hull width: row j of the result depends on λ_j only, and its
    width is convex in λ_j (piecewise linear plus the prior's smooth term).  The candidates are every
    kink G_ji/(aᵀG)_i, 0, the prior term's minimiser and the Frobenius gain; among near-ties (within
    _TIE) the one nearest the Frobenius gain wins, so a flat row keeps a moderate gain."""
    g, e = a @ G, a @ ell
    frob = frobenius_gain(G, ell, a, sigma)
    cols = [np.zeros(len(a)), frob]
    big = np.abs(g) > _KINK_FLOOR * max(1.0, float(np.abs(g).max(initial=0.0)))
    if big.any():
        cols += list((G[:, big] / g[big]).T)
    if e @ e > 0:
        cols.append(ell @ e / (e @ e))
    cand = np.stack(cols, axis=1)  # (rows, candidates)
    width = _row_width(cand, G, ell, a, sigma)
    best = width.min(axis=1, keepdims=True)
    near = width <= best * (1 + _TIE) + 1e-300
    dist = np.where(near, np.abs(cand - frob[:, None]), np.inf)
    return cand[np.arange(len(a)), dist.argmin(axis=1)]


class ZonotopeEstimator(SetEstimator):
    """One node's zonotopic estimator; :meth:`step` takes that step's data and returns the published set."""

    name = "zonotope"
    uses_readings = True  # a reference's reading is one more strip of the same step (Theorem 1)

    def __init__(
        self,
        scenario: Scenario,
        node_id: int,
        order: int | None = None,
        weight: np.ndarray | None = None,
        fault_bounds: FaultBoundsMode = "used",
        gain: Gain = "hull",
    ) -> None:
        self.sc = scenario
        self.reading_slabs = ReadingSlabs.of(scenario, node_id)  # built once: the references and the k-of-N model
        self.gain = gain
        self.node: NodeConfig = scenario.node(node_id)
        self.order = order
        self.W = np.eye(NA) if weight is None else np.asarray(weight, dtype=float)
        self.bounded = node_id in scenario.fault_bounded(fault_bounds)
        self.set: SumSet | None = None
        theta = np.vstack([E_DESCRIPTOR, self.node.sensor.Cbar[None, :]])
        pinv = np.linalg.pinv(theta)  # T E + G C̄ = I (002 (19)–(20) with γ h1 = 1: r = C̄x̄ is measured)
        self.T_x, self.G_r = pinv[:, :NX], pinv[:, NA]

    @property
    def assumptions(self) -> tuple[Assumption, ...]:
        return BASE_ASSUMPTIONS + (("fault_bound",) if self.bounded else ())

    def step(self, inp: StepInput, neighbours: tuple[NeighbourSet, ...] = ()) -> SumSet:
        s = self.advance(inp.y, inp.gamma, inp.u_prev, inp.vx_prev)
        if inp.readings and inp.u_prev is not None and inp.y is not None:  # the references' readings: one more strip each (Theorem 1)
            for slab in self.reading_slabs.slabs((inp.y, inp.gamma), inp.readings, lambda a: (-s.support(-a), s.support(a))):
                s = self._intersect(s, slab)
            self.set = s
        return s

    def _slabs(self, y: float | None, gamma: float) -> list[Slab]:
        """Step 0's: the first measurement (none without a reading: the prior alone) and the declared |f₀| ≤ F where bounded."""
        slabs = [] if y is None else [Slab(self.node.sensor.Cbar, *self.node.sensor.measured_interval(y, gamma, outward=True))]
        if self.bounded and self.node.fault_size is not None:
            slabs.append(Slab(_E3, -self.node.fault_size, self.node.fault_size))
        return slabs

    def advance(self, y: float | None, gamma: float, u_prev: float | None = None, vx_prev: float | None = None) -> SumSet:
        """Step 0 (``u_prev`` None): the prior cut by the first measurement.  Step k > 0: predict with
        u_{k−1}, Vx_{k−1}, then use ỹ_k (γ_k).  ``y`` None (no reading): the prediction alone, the fault carried by
        the declared bound (the lifted step of :meth:`_bounded_step` with no measurement)."""
        if self.set is None:
            n = self.node
            prior = SlicedEllipsoid(Ellipsoid(n.x0_hat, n.P0, n.rho), tuple(self._slabs(y, gamma)))
            self.set = SumSet(Zonotope(np.zeros(NA), np.zeros((NA, 0))), np.eye(NA), prior)
            return self.set
        if u_prev is None or vx_prev is None:
            raise EstimatorError("a step after step 0 needs u and Vx of the previous step")
        a, b, d = self.sc.model.blend(self.sc.model.weights(vx_prev))
        if y is None:
            problem = self.node.gap_problem()
            if problem:
                raise EstimatorError(problem)
            new = self._bounded_step(a, b[:, 0] * u_prev, d[:, 0], -np.inf, np.inf)
        elif self.bounded:
            new = self._bounded_step(a, b[:, 0] * u_prev, d[:, 0], *self.node.sensor.measured_interval(y, gamma, outward=True))
        else:
            new = self._free_step(a, b[:, 0] * u_prev, d[:, 0], y, gamma)
        if self.order is not None:
            new = SumSet(Zonotope(new.zonotope.center, reduce_order(new.zonotope.generators, self.order, self.W)), new.M, new.sliced)
        self.set = new
        return new

    def _free_step(self, a: np.ndarray, bu: np.ndarray, d: np.ndarray, y: float, gamma: float) -> SumSet:
        """x̄⁺ = T_x(Ā [I 0] x̄ + B̄u + D̄w) + G r⁺: exact (module doc)."""
        lo, hi = self.node.sensor.measured_interval(y, gamma, outward=True)
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise EstimatorError(
                f"node {self.node.id}: a saturated measurement leaves the fault unbounded; a declared fault bound is needed (fault_bounds 'used' or 'all')"
            )
        assert self.set is not None
        z, sq_w = self.set.zonotope, np.sqrt(self.sc.W)
        L = self.T_x @ a @ np.eye(NX, NA)
        center = L @ z.center + self.T_x @ bu + self.G_r * (lo + hi) / 2
        gens = np.hstack(
            [
                L @ z.generators,
                (self.T_x @ d * sq_w)[:, None],
                self.T_x @ self.sc.mismatch_generators,
                (self.G_r * (hi - lo) / 2)[:, None],
            ]
        )
        return SumSet(Zonotope(center, gens), L @ self.set.M, self.set.sliced)

    def _bounded_step(self, a: np.ndarray, bu: np.ndarray, d: np.ndarray, lo: float, hi: float) -> SumSet:
        """In the lifted space [x̄⁺; f_k]: the descriptor step where the measurement C̄ x̄⁺ ∈ [lo, hi] is two-sided
        (exact), else the dynamics with f⁺ = f + δ s (or f⁺ ∈ [−F, F]) cut by the one-sided measurement strip (none
        without a reading: both sides open); then the declared-bound strips, then f_k is projected out (exact for a
        zonotope)."""
        assert self.set is not None and self.set.M is not None
        z, sq_w, n = self.set.zonotope, np.sqrt(self.sc.W), self.node
        two_sided = bool(np.isfinite(lo) and np.isfinite(hi))
        lift = np.zeros((NA + 1, NA))  # [x̄⁺; f_k] = lift · x̄_k + …
        lift[NA, 2] = 1.0
        shift = np.zeros(NA + 1)
        extra: list[np.ndarray] = []
        if two_sided:
            lift[:NA] = self.T_x @ a @ np.eye(NX, NA)
            shift[:NA] = self.T_x @ bu + self.G_r * (lo + hi) / 2
            extra += [np.r_[self.T_x @ d * sq_w, 0.0], np.r_[self.G_r * (hi - lo) / 2, 0.0]]
            extra += [np.r_[self.T_x @ g, 0.0] for g in self.sc.mismatch_generators.T]
        else:
            lift[:NX, :NX] = a
            shift[:NX] = bu
            extra.append(np.r_[d * sq_w, 0.0, 0.0])
            extra += [np.r_[g, 0.0, 0.0] for g in self.sc.mismatch_generators.T]
            if n.fault_rate is not None:
                lift[2, 2] = 1.0  # f⁺ = f + δ s
                extra.append(n.fault_rate * np.eye(NA + 1)[2])
            else:
                extra.append(n.fault_size * np.eye(NA + 1)[2])  # fault_bounded: one is declared
        gens = np.hstack([lift @ z.generators, np.array(extra).T])
        out = SumSet(Zonotope(lift @ z.center + shift, gens), lift @ self.set.M, self.set.sliced)
        slabs = []
        if not two_sided and (np.isfinite(lo) or np.isfinite(hi)):
            slabs.append(Slab(np.r_[n.sensor.Cbar, 0.0], lo, hi))
        if n.fault_rate is not None and two_sided:
            slabs.append(Slab(np.array([0.0, 0.0, 1.0, -1.0]), -n.fault_rate, n.fault_rate))
        if n.fault_size is not None:
            slabs.append(Slab(np.eye(NA + 1)[2], -n.fault_size, n.fault_size))
        for slab in slabs:
            out = self._intersect(out, slab)
        zo = out.zonotope
        return SumSet(Zonotope(zo.center[:NA], zo.generators[:NA]), out.M[:NA], out.sliced)  # type: ignore[index]  # M is set in the bounded (lifted) step

    def _intersect(self, s: SumSet, slab: Slab) -> SumSet:
        """001 Theorem 1 for one strip: X ∩ {lo ≤ aᵀx ≤ hi} ⊆ (I − λaᵀ)X ⊕ λ[lo', hi'] for any λ; the
        strip is first clipped to the set's own extent (which also closes a one-sided measurement)."""
        a = slab.a
        top, bottom = s.support(a), -s.support(-a)
        lo, hi = max(slab.lo, bottom), min(slab.hi, top)
        if hi < lo:
            raise EstimatorError(f"node {self.node.id}: the measurement is inconsistent with the set (an assumption broke)")
        if (lo - bottom) + (top - hi) <= NEGLIGIBLE_CUT * max(1.0, top - bottom):
            return s
        mid, sigma = (lo + hi) / 2, (hi - lo) / 2
        G = s.zonotope.generators
        # the prior part enters the gain choice through the ellipsoid's generators-like shape √ρ M L
        ell = np.zeros((len(a), 0))
        if s.sliced is not None and s.M is not None:
            el = s.sliced.ellipsoid
            ell = np.sqrt(el.rho) * s.M @ np.linalg.cholesky(el.P)
        lam = _hull_gain(G, ell, a, sigma) if self.gain == "hull" else frobenius_gain(G, ell, a, sigma)
        proj = np.eye(len(a)) - np.outer(lam, a)
        c = s.zonotope.center
        center = proj @ c + lam * mid
        gens = np.hstack([proj @ G, (sigma * lam)[:, None]])
        return SumSet(Zonotope(center, gens), None if s.M is None else proj @ s.M, s.sliced)
