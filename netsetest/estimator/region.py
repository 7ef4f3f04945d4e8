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

import numpy as np

from netsetest.config.schema import Scenario
from netsetest.estimator.base import Assumption, EstimatorError, GuaranteedSet, NeighbourSet, ReadingSlabs, SetEstimator, StepInput
from netsetest.estimator.sector import Interval
from netsetest.models.sensor import NX
from netsetest.polygon import MIN_VERTICES, Polygon
from netsetest.sets import RegionSet


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
        lo, hi = (-np.inf, np.inf) if inp.y is None else self.node.sensor.measured_interval(inp.y, inp.gamma)  # None: no reading
        region: Polygon | None = self._moved(s_lo, s_hi, inp)
        f_lo, f_hi = float(s_lo[NX]), float(s_hi[NX])
        health = None
        if self.uses_readings and inp.y is not None:
            slabs, health = self.reading_slabs.assessed((inp.y, inp.gamma), inp.readings, lambda a: (-s.support(-a), s.support(a)))
            for slab in slabs:
                if not slab.a[:NX].any():  # |f| ≤ τ (the k-of-N pin)
                    f_lo, f_hi = max(f_lo, slab.lo / slab.a[NX]), min(f_hi, slab.hi / slab.a[NX])
                elif region is not None:  # a reading's C_j x, the k-of-N uᵀx (no fault term)
                    region = region.cut(slab.a[:NX], slab.lo, slab.hi)
        size = self.node.fault_size
        if (self.rests_on_bound or inp.y is None and inp.step > 0) and size is not None:  # (a step without a reading rests on it)
            f_lo, f_hi = max(f_lo, -size), min(f_hi, size)
            if region is not None and inp.y is not None:  # C x = C̄ x̄ − Ds f, |f| ≤ F
                region = region.cut(self.C, lo - abs(self.Ds) * size, hi + abs(self.Ds) * size)
        for m in range(NX):  # the own set's interval hull (its support along β and r)
            if region is not None:
                region = region.cut(np.eye(NX)[m], float(s_lo[m]), float(s_hi[m]))
        if region is not None:
            region = region.cut(self.C, -s.support(-self.c_dir), s.support(self.c_dir))
        if region is None or len(region) < MIN_VERTICES:
            self.region = None  # nothing left (an assumption broke): the method's set alone, the region reseeded
            return s
        self.region = region = region.reduced()
        if self.Ds != 0.0 and np.isfinite(lo) and np.isfinite(hi):
            c_lo, c_hi = region.interval(self.C)
            a, b = sorted(((lo - c_hi) / self.Ds, (hi - c_lo) / self.Ds))
            f_lo, f_hi = max(f_lo, a), min(f_hi, b)
        model = self.reading_slabs.health
        if health is not None and model is not None and self.Ds != 0.0:  # the own sensor healthy, or the others agree (cuts.py)
            a, b = health.others.fault(self.node.sensor, region.interval(health.others.u), Interval(lo, hi), model.tolerance)
            f_lo, f_hi = max(f_lo, a), min(f_hi, b)
        if f_lo > f_hi:
            return s  # (an assumption broke: the own set alone is what is left to publish)
        return RegionSet(s, region, (f_lo, f_hi))

    def _moved(self, s_lo: np.ndarray, s_hi: np.ndarray, inp: StepInput) -> Polygon:
        """The last region through the step's blended dynamics, the disturbance and the mismatch bound (step 0, or
        without one: the interval hull s_lo..s_hi of the own set's x)."""
        if self.region is None or inp.u_prev is None or inp.vx_prev is None:
            return Polygon.box(s_lo[:NX], s_hi[:NX])
        a, b, d = self.sc.model.blend(self.sc.model.weights(inp.vx_prev))
        segments = [d[:, 0] * np.sqrt(self.sc.W), *self.sc.mismatch_generators.T]  # x⁺ = Ā x + B̄ u + D̄ w + e
        return self.region.moved(a, b[:, 0] * inp.u_prev, segments)


__all__ = ["WithRegion"]
