"""A region of x = (β, r) for the set estimators (zonotope, interval, strip, setprop): what they publish is their
own set cut by it, the kind of region the SDP keeps (docs/estimator.md, "The set a node proves").

:class:`WithRegion` wraps one node's set estimator.  Per step the region is

- seeded (step 0, or after a step whose cuts left nothing: an assumption broke) from the interval hull of the
  method's own set over (β, r);
- moved through the step's blended dynamics (exact for the truth), plus the disturbance's segment D̄√W, the declared
  model mismatch's generators and the rounding margin (:meth:`netsetest.polygon.Polygon.moved`);
- cut by what the step proves of x: the readings the method uses (a reference's C_j x, the k-of-N interval of uᵀx),
  the own measurement with the declared fault bound where the method rests on it (C x = C̄ x̄ − Ds f with |f| ≤ F),
  and the method's own set along β, r and the own sensor's C (its support: sound wherever the set holds the truth).

The published set is :class:`~netsetest.sets.RegionSet`: the method's set ∩ the region × ℝ ∩ the fault range, that
range being the method's own fault interval cut by what the own measurement proves over the region (C x + Ds f in
the measured interval, C x in the region's: Ds f ∈ [m_lo − c_hi, m_hi − c_lo]; only where the measurement is
two-sided), by |f| ≤ F where the method rests on the declared bound, and under k-of-N by the pin and by what the own
measurement proves where the other readings alone agree (:meth:`~netsetest.estimator.health.Others.fault`).  The method's own
recursion is untouched: its next step starts from its own set, as its paper defines it; the region is a second
recursion beside it, resting on the same assumptions (the prior, the noise, the disturbance and mismatch bounds,
and the fault bound and readings exactly where the method itself uses them), so the node's dependency cone is
unchanged.  ``netsetest compare`` shows each method with the region (``zonotope``) and without it
(``zonotope-noregion``, the method as its paper defines it).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from netsetest.config.schema import Scenario
from netsetest.estimator.base import Assumption, EstimatorError, GuaranteedSet, NeighbourSet, ReadingSlabs, SetEstimator, StepInput
from netsetest.estimator import region_engine
from netsetest.estimator.region_engine import Blend
from netsetest.estimator.sector import Interval, measurement_interval
from netsetest.models.sensor import NX
from netsetest.polygon import Polygon
from netsetest.sets import CutName, RegionSet, Slab

if TYPE_CHECKING:
    from netsetest.estimator.health import HealthAssessment


class WithRegion(SetEstimator):
    """One node's set estimator ``inner`` with a region of x (module doc)."""

    def __init__(self, inner: SetEstimator, scenario: Scenario, node_id: int) -> None:
        self.inner, self.sc, self.node = inner, scenario, scenario.node(node_id)
        self.name = inner.name
        self.uses_neighbours, self.uses_readings = inner.uses_neighbours, inner.uses_readings
        self.reading_slabs = ReadingSlabs.of(scenario, node_id)
        self.rests_on_bound = "fault_bound" in inner.assumptions
        sensor = self.node.sensor
        self.C, self.Ds = sensor.Cbar[:NX], float(sensor.Cbar[NX])  # C̄ x̄ = C x + Ds f
        self.c_dir = np.r_[self.C, 0.0]  # the own set's C x: a cut of the region beside its β, r hull
        self.axes = np.eye(NX + 1)[:NX]  # β and r over x̄ = (x, f)
        self.region: Polygon | None = None

    @property
    def assumptions(self) -> tuple[Assumption, ...]:
        return self.inner.assumptions

    def step(self, inp: StepInput, neighbours: tuple[NeighbourSet, ...] = ()) -> GuaranteedSet:
        try:
            s = self.inner.step(inp, neighbours)
        except EstimatorError:
            self.region = None  # the node publishes its last set; the region restarts from the next one
            raise
        assert not isinstance(s, RegionSet)  # a method's own set (a WithRegion never wraps another)
        s_lo, s_hi = s.bounds()
        # the own measurement's interval (none without a reading: both sides open, so it cuts nothing)
        meas = Interval(-math.inf, math.inf) if inp.y is None else measurement_interval(self.node.sensor, inp.y, inp.gamma)
        region = self._moved(s_lo, s_hi, inp)
        fault = _FaultRange(float(s_lo[NX]), float(s_hi[NX]))
        slabs, health = self._readings(s, inp, fault)
        own_size = self._fault_size(inp, fault)
        hull = [Slab(self.axes[m], float(s_lo[m]), float(s_hi[m])) for m in range(NX)]  # the own set's interval hull
        model = self.reading_slabs.health
        others = health.others if health is not None and model is not None and self.Ds != 0.0 else None  # (cuts.py's health-fault)
        # the readings' C_j x and k-of-N uᵀx (no fault term), the own measurement, the own set's hull and C x; reduced
        facts = region_engine.cut(
            region,
            slabs,
            self.node.sensor,
            meas,
            own_size,
            after=[*hull, Slab(self.c_dir, -s.support(-self.c_dir), s.support(self.c_dir))],
            others=others,
            floor=0.0 if model is None else model.tolerance,
        )
        if facts is None:
            self.region = None  # nothing left (an assumption broke): the method's set alone, the region reseeded
            return s
        self.region = region = facts.region
        if facts.fault is not None:  # one-sided where the reading is at the limit
            fault.cut("region", *facts.fault)
        if facts.health is not None:  # the own sensor healthy, or the others agree
            fault.cut("health-fault", *facts.health)
        if fault.lo > fault.hi:
            return s  # (an assumption broke: the own set alone is what is left to publish)
        r_lo, r_hi = facts.box[:NX], facts.box[NX:]
        xs: tuple[tuple[CutName, ...], ...] = tuple(("region",) if r_lo[m] > s_lo[m] or r_hi[m] < s_hi[m] else () for m in range(NX))
        return RegionSet(s, region, (fault.lo, fault.hi), (xs[0], xs[1], tuple(fault.names)))

    def _readings(self, s: GuaranteedSet, inp: StepInput, fault: _FaultRange) -> tuple[list[Slab], HealthAssessment | None]:
        """The readings' slabs the method uses and their health assessment (none without the own reading); the
        k-of-N pin |f| ≤ τ among them cuts ``fault``."""
        if not self.uses_readings or inp.y is None:
            return [], None
        slabs, health = self.reading_slabs.assessed((inp.y, inp.gamma), inp.readings, lambda a: (-s.support(-a), s.support(a)))
        for slab in slabs:
            if not slab.a[:NX].any():  # |f| ≤ τ (the k-of-N pin)
                fault.cut("health-pin", slab.lo / slab.a[NX], slab.hi / slab.a[NX])
        return slabs, health

    def _fault_size(self, inp: StepInput, fault: _FaultRange) -> float | None:
        """The declared fault bound F cuts ``fault`` where the method rests on it (and on a step without a reading);
        F for the own measurement's cut (C x = C̄ x̄ − Ds f, |f| ≤ F) where it has a reading, else None."""
        size = self.node.fault_size
        if (self.rests_on_bound or inp.y is None and inp.step > 0) and size is not None:  # (a step without a reading rests on it)
            fault.cut("fault-size", -size, size)
            return size if inp.y is not None else None
        return None

    def _moved(self, s_lo: np.ndarray, s_hi: np.ndarray, inp: StepInput) -> Polygon:
        """The last region through the step's blended dynamics, the disturbance and the mismatch bound (step 0, or
        without one: the interval hull s_lo..s_hi of the own set's x)."""
        if self.region is None or inp.u_prev is None or inp.vx_prev is None:
            return Polygon.box(s_lo[:NX], s_hi[:NX])
        blend = Blend.of(self.sc.model, self.sc.model.weights(inp.vx_prev))  # x⁺ = Ā x + B̄ u + D̄ w + e
        return region_engine.moved(self.region, blend, inp.u_prev, self.sc.W, self.sc.uncertainty)


class _FaultRange:
    """The fault range of one step as its cuts narrow it, with the names of those that did."""

    def __init__(self, lo: float, hi: float) -> None:
        self.lo, self.hi, self.names = lo, hi, list[CutName]()

    def cut(self, name: CutName, lo: float, hi: float) -> None:
        if lo > self.lo or hi < self.hi:
            self.lo, self.hi = max(self.lo, lo), min(self.hi, hi)
            self.names.append(name)


__all__ = ["WithRegion"]
