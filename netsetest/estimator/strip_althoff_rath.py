"""Strip-based zonotopic observer of Althoff & Rath's comparison ([Althoff-Rath], Sec. 2.4 and 3.1) for one
node's [β, r, f_i].

Reference: M. Althoff, J. J. Rath, "Comparison of guaranteed state estimators for linear time-invariant
systems", Automatica 2021 ([Althoff-Rath]): prediction S_p = A S ⊕ B u ⊕ W, then the intersection with the
measurement strip {|C x − y| ≤ σ} over-approximated by a zonotope with a gain (their (4)–(6); the
F-radius-minimising gain of Le et al. [38], 003 Sec. 3.1), and order reduction.  Derivation:
docs/estimators/strip_althoff_rath.md.

003's observers are for a state-space model, so the fault needs a model: the augmented state
x̄ = [x; f] follows x̄⁺ = [Ā 0; 0 1] x̄ + [B̄; 0] u + [D̄ w; δ s], |s| ≤ 1, with the node's declared fault
rate δ (a random walk; with only a size F declared, f⁺ ∈ [−F, F]), and the declared |f| ≤ F is a
second strip.  Every node using this observer therefore relies on its declared fault bound.  The
measurement strip is C̄ x̄ ∈ [lo, hi] (the measured interval; one side open at saturation, then the
strip is first clipped to the set's own extent).  The initial set is the box of the prior ellipsoid.
It ignores the neighbours' sets; a reference sensor's reading of the same step is one more strip
(docs/network.md).  A strip that does not cut the set (the set is flat along it) leaves it unchanged.
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass

import numpy as np

from netsetest.config.schema import NodeConfig, Scenario
from netsetest.estimator.base import BASE_ASSUMPTIONS, Assumption, EstimatorError, NeighbourSet, SetEstimator, ReadingSlabs, StepInput
from netsetest.estimator.zonotope_w_radius import NEGLIGIBLE_CUT, frobenius_gain, reduce_order
from netsetest.models.sensor import NA, NX
from netsetest.sets import Zonotope

DEFAULT_ORDER = 20  # generators kept by ↓q (003 compares orders of this size; each step adds 2–3)
_E3 = np.eye(NA)[2]
_NO_PRIOR = np.zeros((NA, 0))


@dataclass(frozen=True)
class AugmentedStep:
    """x̄⁺ = A x̄ + shift + gens·b, ‖b‖∞ ≤ 1: the augmented model of one step (module doc)."""

    A: np.ndarray
    shift: np.ndarray
    gens: np.ndarray


def fault_model_required(node: NodeConfig) -> None:
    if node.fault_rate is None and node.fault_size is None:
        raise EstimatorError(f"node {node.id}: this observer needs a fault model; declare a [fault_bound] rate or size")


def augmented_step(scenario: Scenario, node: NodeConfig, u: float, vx: float) -> AugmentedStep:
    """The random-walk augmented model of step k → k+1 with u_k, Vx_k."""
    a, b, d = scenario.model.blend(scenario.model.weights(vx))
    A = np.zeros((NA, NA))
    A[:NX, :NX] = a
    if node.fault_rate is not None:
        A[2, 2] = 1.0
        fault_gen = node.fault_rate
    else:
        fault_gen = node.fault_size  # type: ignore[assignment]  # fault_model_required checked it
    e_gens = np.vstack([scenario.mismatch_generators, np.zeros((1, scenario.mismatch_generators.shape[1]))])
    gens = np.column_stack([np.r_[d[:, 0] * np.sqrt(scenario.W), 0.0], e_gens, fault_gen * _E3])
    return AugmentedStep(A, np.r_[b[:, 0] * u, 0.0], gens)


def prior_box(node: NodeConfig) -> Zonotope:
    """The interval hull of the prior ellipsoid as a zonotope."""
    return Zonotope(node.x0_hat.copy(), np.diag(np.sqrt(node.rho * np.diag(node.P0))))


def intersect_strip(z: Zonotope, a: np.ndarray, lo: float, hi: float) -> Zonotope:
    """Z ∩ {lo ≤ aᵀx ≤ hi} ⊆ (I − λaᵀ)Z ⊕ λ[lo', hi'] for any λ (003 (6), 001 Theorem 1), λ the
    F-radius-minimising gain; [lo', hi'] is the strip clipped to Z's own extent."""
    spread = float(np.abs(a @ z.generators).sum())
    top, bottom = float(a @ z.center) + spread, float(a @ z.center) - spread
    lo, hi = max(lo, bottom), min(hi, top)
    if hi < lo:
        raise EstimatorError("the measurement is inconsistent with the set (an assumption broke)")
    if (lo - bottom) + (top - hi) <= NEGLIGIBLE_CUT * max(1.0, top - bottom):
        return z  # the strip does not cut the set (e.g. the set is flat along a): nothing to intersect
    mid, sigma = (lo + hi) / 2, (hi - lo) / 2
    lam = frobenius_gain(z.generators, _NO_PRIOR, a, sigma)
    proj = np.eye(len(a)) - np.outer(lam, a)
    return Zonotope(proj @ z.center + lam * mid, np.hstack([proj @ z.generators, (sigma * lam)[:, None]]))


class RandomWalkObserver(SetEstimator):
    """What 003's single-sensor observers here share: the random-walk augmented model (its fault bound
    required), the prior box at step 0, order reduction, and their assumptions."""

    uses_neighbours = False

    def __init__(self, scenario: Scenario, node_id: int, order: int | None = DEFAULT_ORDER) -> None:
        self.sc, self.node = scenario, scenario.node(node_id)
        self.reading_slabs = ReadingSlabs.of(scenario, node_id)  # built once: the references and the k-of-N model
        fault_model_required(self.node)
        self.order = order
        self.set: Zonotope | None = None

    @property
    def assumptions(self) -> tuple[Assumption, ...]:
        return BASE_ASSUMPTIONS + ("fault_bound",)

    def _predicted(self, inp: StepInput) -> Zonotope:
        """The prior box at step 0, else the previous set through :meth:`_propagate`."""
        if self.set is None:
            return prior_box(self.node)
        if inp.u_prev is None or inp.vx_prev is None:
            raise EstimatorError("a step after step 0 needs u and Vx of the previous step")
        return self._propagate(self.set, inp.u_prev, inp.vx_prev)

    @abstractmethod
    def _propagate(self, s: Zonotope, u: float, vx: float) -> Zonotope:
        """The previous set ``s`` through one step with input ``u`` and speed ``vx``."""

    def _reduced(self, z: Zonotope) -> Zonotope:
        return z if self.order is None else Zonotope(z.center, reduce_order(z.generators, self.order, np.eye(NA)))


class StripObserver(RandomWalkObserver):
    """003's strip-based zonotopic observer on the random-walk augmented model."""

    name = "strip"
    uses_readings = True  # a reference's reading is one more strip of the same step

    def step(self, inp: StepInput, neighbours: tuple[NeighbourSet, ...] = ()) -> Zonotope:
        """The step's set; without a reading (``inp.y`` None) the prediction cut by the declared |f| ≤ F alone."""
        z = self._predicted(inp)
        if inp.y is not None:
            z = intersect_strip(z, self.node.sensor.Cbar, *self.node.sensor.measured_interval(inp.y, inp.gamma, outward=True))
            for slab in self.reading_slabs.slabs((inp.y, inp.gamma), inp.readings, lambda a: (-z.support(-a), z.support(a))):
                z = intersect_strip(z, slab.a, slab.lo, slab.hi)
        if self.node.fault_size is not None:
            z = intersect_strip(z, _E3, -self.node.fault_size, self.node.fault_size)
        self.set = self._reduced(z)
        return self.set

    def _propagate(self, s: Zonotope, u: float, vx: float) -> Zonotope:
        """The open-loop step of the augmented model: A S ⊕ B u ⊕ W."""
        m = augmented_step(self.sc, self.node, u, vx)
        return Zonotope(m.A @ s.center + m.shift, np.hstack([m.A @ s.generators, m.gens]))
