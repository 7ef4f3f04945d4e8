"""Set-propagation zonotopic observer of Althoff & Rath's comparison ([Althoff-Rath], Sec. 2.5 and 3.2, their
eq. (8) with the FRad-C gain) for one node's [β, r, f_i].

Reference: M. Althoff, J. J. Rath, "Comparison of guaranteed state estimators for linear time-invariant
systems", Automatica 2021 ([Althoff-Rath]): S_k+1 = (A − L C) S_k ⊕ B u_k ⊕ L y_k ⊕ (−L) V ⊕ W, guaranteed
for any gain L, here L_k = A G Gᵀ Cᵀ (C G Gᵀ Cᵀ + F Fᵀ)⁻¹ minimising the F-radius (Combastel [22]),
recomputed every step; order reduction ↓q.  Derivation: docs/estimators/set_propagation_althoff_rath.md.

The augmented random-walk model of strip_althoff_rath (the declared fault rate, or f⁺ ∈ [−F, F] with
only a size declared) gives A, B, W.  The measurement is C̄ x̄ ∈ [lo, hi]: y = the interval's midpoint,
V = [−σ, σ] its half-width.  (8) is a one-step predictor: the set published at step k uses ỹ up to
k − 1 (003, Sec. 2.7: it is ready before y_k arrives); step 0 publishes the prior box.  A step without a
reading is one without its measurement: the step after it takes L = 0.  Where a
saturated measurement is one-sided, L = 0 on that step (the measurement is not used).  The declared
|f| ≤ F is not used (no intersection in this form).  It ignores the neighbours' sets.
"""

from __future__ import annotations

import numpy as np

from netsetest.config.schema import Scenario
from netsetest.estimator.base import NeighbourSet, StepInput
from netsetest.estimator.strip_althoff_rath import DEFAULT_ORDER, RandomWalkObserver, augmented_step
from netsetest.models.sensor import NA
from netsetest.sets import Zonotope


class SetPropagationObserver(RandomWalkObserver):
    """003's set-propagation observer (8) with the F-radius gain, on the random-walk augmented model."""

    name = "setprop"

    def __init__(self, scenario: Scenario, node_id: int, order: int | None = DEFAULT_ORDER) -> None:
        super().__init__(scenario, node_id, order)
        self.last_interval: tuple[float, float] = (-np.inf, np.inf)  # C̄ x̄ of the previous step

    def step(self, inp: StepInput, neighbours: tuple[NeighbourSet, ...] = ()) -> Zonotope:
        z = self._predicted(inp)
        # without a reading (``inp.y`` None) the next step gains nothing from this one: L = 0 there
        self.last_interval = (-np.inf, np.inf) if inp.y is None else self.node.sensor.measured_interval(inp.y, inp.gamma, outward=True)
        self.set = z
        return z

    def _propagate(self, s: Zonotope, u: float, vx: float) -> Zonotope:
        """(8): (A − L C̄) S ⊕ B u ⊕ L y ⊕ (−L) V ⊕ W with y, V the previous measurement's midpoint and
        half-width (module doc)."""
        m = augmented_step(self.sc, self.node, u, vx)
        c_bar = self.node.sensor.Cbar
        lo, hi = self.last_interval
        if np.isfinite(lo) and np.isfinite(hi):
            mid, sigma = (lo + hi) / 2, (hi - lo) / 2
            gg = s.generators @ s.generators.T
            gain = m.A @ gg @ c_bar / (c_bar @ gg @ c_bar + sigma**2)
        else:
            mid, sigma, gain = 0.0, 0.0, np.zeros(NA)
        closed = m.A - np.outer(gain, c_bar)
        center = closed @ s.center + m.shift + gain * mid
        return self._reduced(Zonotope(center, np.hstack([closed @ s.generators, (gain * sigma)[:, None], m.gens])))
