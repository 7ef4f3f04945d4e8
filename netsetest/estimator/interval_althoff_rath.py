"""Interval observer of Althoff & Rath's comparison ([Althoff-Rath], Algorithm 1, after Tang et al. [65]) for
one node's [β, r, f_i], in the descriptor form of [Mousavinejad] (18)–(20).

Reference: M. Althoff, J. J. Rath, "Comparison of guaranteed state estimators for linear time-invariant
systems", Automatica 2021 ([Althoff-Rath]), Sec. 2.6, Algorithm 1.  Derivation, and why 004's functional
interval observer does not apply to this vehicle: docs/estimators/interval_althoff_rath.md.

The observer's error dynamics are the descriptor step x̄⁺ = Φ x̄ + T_x B̄ u + G r⁺ + T_x D̄ w with
Φ = T_x Ā [I 0] (the gain that decouples the fault, 001's P + M C = I); r⁺ = C̄ x̄⁺ lies in the measured
interval.  Algorithm 1 keeps the centre x̂, the propagated initial box S_x = Φ_k…Φ_0 X_0 (a linear map
of a box) and the boxes of the propagated disturbance sets, box(Φ_k…Φ_{j+1} D_j), summed: boxing each
part separately avoids the wrapping effect.  003's system is time-invariant, so one D_k = Φ^k D_0
serves every past step; here Φ and D_j change with Vx and γ, so the last ``window`` D_j are kept and
propagated (O(window) per step) and an older one is folded into a box whose radius is propagated by
interval arithmetic, |Φ| ρ (sound; it wraps, but only after ``window`` steps of decay by Φ).
``wrapping=True`` is the classical interval observer instead, O(1): the whole box is propagated by
interval arithmetic and wraps from the start.

Where a saturated measurement is one-sided (SAIM) the fault is not decoupled at that step: the step
is the prediction x⁺ = Ā x + B̄u + D̄w, f⁺ = f + δ s (or f⁺ ∈ [−F, F]) with the declared fault bound,
and the published box is clipped to |f| ≤ F (an intersection of the published box only, as Algorithm 1
has none).  It ignores the neighbours' sets.  The readings of the same step (a reference's, or
everyone's under ``max_faulty``: :class:`ReadingSlabs`, docs/network.md) cut the published box the same
way, to the interval hull of its intersection with each slab, and then with the own measurement's slab
(a box forgets that f follows from x and ỹ); the recursion stays Algorithm 1's.
"""

from __future__ import annotations

import numpy as np

from netsetest.config.schema import NodeConfig, Scenario
from netsetest.estimator.base import BASE_ASSUMPTIONS, Assumption, EstimatorError, NeighbourSet, ReadingSlabs, SetEstimator, StepInput
from netsetest.models.sensor import E_DESCRIPTOR, NA, NX
from netsetest.sets import Box, Ellipsoid, SlicedEllipsoid, Slab, SumSet, Zonotope

_E3 = np.eye(NA)[2]
DEFAULT_WINDOW = 40  # steps a disturbance set is propagated exactly (|Φ| contracts by ≈ 0.9 per step: 0.9⁴⁰ ≈ 0.015)


def step0_set(node: NodeConfig, lo: float, hi: float, bounded: bool) -> SumSet:
    """The prior ellipsoid cut by the first measurement C̄ x̄_0 ∈ [lo, hi] (none without a reading: both sides
    infinite) and |f_0| ≤ F where bounded."""
    slabs = [Slab(node.sensor.Cbar, lo, hi)] if np.isfinite(lo) or np.isfinite(hi) else []
    if bounded and node.fault_size is not None:
        slabs.append(Slab(_E3, -node.fault_size, node.fault_size))
    prior = SlicedEllipsoid(Ellipsoid(node.x0_hat, node.P0, node.rho), tuple(slabs))
    return SumSet(Zonotope(np.zeros(NA), np.zeros((NA, 0))), np.eye(NA), prior)


def descriptor_gains(node: NodeConfig) -> tuple[np.ndarray, np.ndarray]:
    """T_x (3×2), G (3,) with T E + G C̄ = I: x̄ = T_x x + G C̄ x̄ for every x̄ (Θ = [E; C̄] full rank)."""
    pinv = np.linalg.pinv(np.vstack([E_DESCRIPTOR, node.sensor.Cbar[None, :]]))
    return pinv[:, :NX], pinv[:, NA]


class IntervalObserver(SetEstimator):
    """003's Algorithm 1 (``wrapping=False``) or the classical interval observer (``wrapping=True``)."""

    uses_neighbours = False
    uses_readings = True

    def __init__(self, scenario: Scenario, node_id: int, wrapping: bool = False, window: int | None = DEFAULT_WINDOW) -> None:
        self.sc, self.node = scenario, scenario.node(node_id)
        self.name = "interval-classical" if wrapping else "interval"
        self.wrapping = wrapping
        self.bounded = node_id in scenario.fault_bounded("used")
        self.T_x, self.G_r = descriptor_gains(self.node)
        self.center: np.ndarray | None = None
        self.init_map = np.eye(NA)  # Φ_k…Φ_0 applied to the initial box's radius
        self.init_radius = np.zeros(NA)
        self.window = window
        self.dist: list[np.ndarray] = []  # propagated disturbance generators, one (3, m) block per step
        self.radius = np.zeros(NA)  # the box propagated by interval arithmetic: all (wrapping) or the folded tail
        self.reading_slabs = ReadingSlabs.of(scenario, node_id)  # built once: the references and the k-of-N model

    @property
    def assumptions(self) -> tuple[Assumption, ...]:
        return BASE_ASSUMPTIONS + (("fault_bound",) if self.bounded else ())

    def step(self, inp: StepInput, neighbours: tuple[NeighbourSet, ...] = ()) -> Box:
        """The step's box; without a reading (``inp.y`` None) the prediction alone: the one-sided step with both
        sides open, the fault carried by the declared bound."""
        lo, hi = (-np.inf, np.inf) if inp.y is None else self.node.sensor.measured_interval(inp.y, inp.gamma, outward=True)
        two_sided = bool(np.isfinite(lo) and np.isfinite(hi))
        problem = self.node.gap_problem() if inp.y is None and self.center is not None else None
        if problem:
            raise EstimatorError(problem)
        if not two_sided and not self.bounded and inp.y is not None:
            raise EstimatorError(f"node {self.node.id}: a saturated measurement leaves the fault unbounded; a declared fault bound is needed")
        if self.center is None:
            blo, bhi = step0_set(self.node, lo, hi, self.bounded).bounds()
            self.center, self.init_radius = (blo + bhi) / 2, (bhi - blo) / 2
            if self.wrapping:
                self.radius = self.init_radius.copy()
            return self._publish(inp)
        if inp.u_prev is None or inp.vx_prev is None:
            raise EstimatorError("a step after step 0 needs u and Vx of the previous step")
        phi, shift, gens = self._step_matrices(inp.u_prev, inp.vx_prev, lo, hi, two_sided)
        self.center = phi @ self.center + shift
        if self.wrapping:
            self.radius = np.abs(phi) @ self.radius + np.abs(gens).sum(axis=1)
        else:
            self.init_map = phi @ self.init_map
            self.radius = np.abs(phi) @ self.radius
            self.dist = [phi @ d for d in self.dist] + [gens]
            if self.window is not None and len(self.dist) > self.window:
                self.radius = self.radius + np.abs(self.dist.pop(0)).sum(axis=1)
        return self._publish(inp)

    def _step_matrices(self, u: float, vx: float, lo: float, hi: float, two_sided: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Φ, the known shift and the disturbance generators of one step (module doc)."""
        a, b, d = self.sc.model.blend(self.sc.model.weights(vx))
        sq_w = np.sqrt(self.sc.W)
        if two_sided:
            phi = self.T_x @ a @ np.eye(NX, NA)
            shift = self.T_x @ b[:, 0] * u + self.G_r * (lo + hi) / 2
            gens = np.column_stack([self.T_x @ d[:, 0] * sq_w, self.T_x @ self.sc.mismatch_generators, self.G_r * (hi - lo) / 2])
            return phi, shift, gens
        n = self.node
        phi = np.zeros((NA, NA))
        phi[:NX, :NX] = a
        shift = np.r_[b[:, 0] * u, 0.0]
        if n.fault_rate is not None:
            phi[2, 2] = 1.0  # f⁺ = f + δ s
            fault_gen = n.fault_rate
        else:
            fault_gen = n.fault_size  # type: ignore[assignment]  # bounded: one is declared
        e_gens = np.vstack([self.sc.mismatch_generators, np.zeros((1, self.sc.mismatch_generators.shape[1]))])
        gens = np.column_stack([np.r_[d[:, 0] * sq_w, 0.0], e_gens, fault_gen * _E3])
        return phi, shift, gens

    def _publish(self, inp: StepInput) -> Box:
        """The observer's box, clipped to the declared |f| ≤ F and cut by the step's readings (module doc)."""
        assert self.center is not None
        if self.wrapping:
            radius = self.radius
        else:
            radius = np.abs(self.init_map) @ self.init_radius + self.radius
            for d in self.dist:
                radius = radius + np.abs(d).sum(axis=1)
        lo, hi = self.center - radius, self.center + radius
        if (self.bounded or inp.y is None and inp.step > 0) and self.node.fault_size is not None:  # (a step without a reading rests on it)
            lo[2], hi[2] = max(lo[2], -self.node.fault_size), min(hi[2], self.node.fault_size)
        box = Box(lo, hi)
        if inp.y is None:
            return box  # no measurement, no reading: the prediction alone
        slabs = self.reading_slabs.slabs((inp.y, inp.gamma), inp.readings, lambda a: (-box.support(-a), box.support(a)))
        for slab in slabs:
            box = box.cut(slab)
        if slabs:  # a box keeps no tie between x and f: the own measurement C̄ x̄ ∈ [lo, hi] carries the cut to f
            box = box.cut(Slab(self.node.sensor.Cbar, *self.node.sensor.measured_interval(inp.y, inp.gamma, outward=True)))
        return box
