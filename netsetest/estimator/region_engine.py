"""The region engine every estimator family uses (docs/estimator.md, "The set a node proves"): a convex polygon of
x = (β, r) moved through a step, cut by the slabs the step proves, cut by the own measurement with the declared fault
bound, and the fault its own measurement proves over it.

The SDP (:mod:`netsetest.estimator.cuts`, the ``region`` cut) and the other papers' set estimators
(:class:`~netsetest.estimator.region.WithRegion`) both call these functions, so a region is moved, cut and read the
same way whichever method keeps it: the same blended model (:class:`Blend`), the same segments of the disturbance and
the declared model mismatch, the same measurement interval (:func:`~netsetest.estimator.sector.measurement_interval`,
rounded outward) and the same fault over the region, one-sided where the reading is at the sensor's limit.

Each function keeps every point of its input that its facts allow (tests/unit/test_region_engine.py): the move holds
x⁺ = Ā x + B̄ u + D̄ w + e for every x of the region, |w| ≤ √W and e in the mismatch's box; a cut holds every x with
cᵀx in the slab (widened outward by :meth:`~netsetest.polygon.Polygon.cut`'s margin).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from netsetest.estimator.sector import Interval, fault_over
from netsetest.models.sensor import NA, NX, Sensor
from netsetest.models.uncertainty import ModelUncertainty
from netsetest.models.vehicle import TSModel
from netsetest.polygon import Polygon
from netsetest.sets import Slab


@dataclass(frozen=True)
class Blend:
    """The step's blended model Σ α_ℓ (A_ℓ, B_ℓ, Dw_ℓ) (exact for the truth), computed once per step: Ā (NX, NX),
    B̄ and D̄ (NX,), and the augmented ones over x̄ = (x, f): (NA, NA), (NA,), (NA,) (the fault row and column zero)."""

    a: np.ndarray
    b: np.ndarray
    d: np.ndarray
    abar: np.ndarray
    bbar: np.ndarray
    dbar: np.ndarray

    @classmethod
    def of(cls, model: TSModel, alpha: np.ndarray) -> Blend:
        """The blend of ``model``'s rule matrices for the weights α (TSModel.blend: once per step)."""
        a, b, d = model.blend(np.asarray(alpha, dtype=float))
        abar = np.zeros((NA, NA))
        abar[:NX, :NX] = a
        return cls(a, b[:, 0], d[:, 0], abar, np.append(b[:, 0], 0.0), np.append(d[:, 0], 0.0))  # (np.r_ costs 10 µs a call)


def moved(region: Polygon, blend: Blend, u: float, W: float, uncertainty: ModelUncertainty | None) -> Polygon:
    """The states x⁺ = Ā x + B̄ u + D̄ w + e of every x in ``region``: its image, plus the disturbance's segment D̄√W and
    the declared mismatch's generators (a box around e = G ζ, |ζ_m| ≤ 1, holds it for either kind), plus the rounding
    margin (:meth:`~netsetest.polygon.Polygon.moved`)."""
    segments = [blend.d * math.sqrt(W)]
    if uncertainty is not None:
        segments += [uncertainty.G[:, m] for m in range(NX)]
    return region.moved(blend.a, blend.b * u, segments)


def cut_by_slabs(region: Polygon | None, slabs: Iterable[Slab]) -> Polygon | None:
    """The region cut by every slab lo ≤ aᵀx̄ ≤ hi over x̄ = (x, f) with a part in x (a reading's C_j x, the k-of-N uᵀx;
    a slab of f alone, the k-of-N pin, is the fault range's, not the region's); None once nothing is left."""
    for s in slabs:
        if region is None:
            return None
        if s.a[:NX].any():
            region = region.cut(s.a[:NX], s.lo, s.hi)
    return region


def cut_by_own(region: Polygon | None, own: Sensor, meas: Interval, size: float) -> Polygon | None:
    """The region cut by the own measurement with the declared fault size: C x = C̄ x̄ − Ds f with C̄ x̄ in ``meas``
    and |f| ≤ F (an open side of ``meas``, at the sensor's limit, leaves that side open)."""
    if region is None:
        return None
    slack = abs(own.Ds) * size
    return region.cut(own.C, meas.lo - slack, meas.hi + slack)


def region_fault(own: Sensor, region: Polygon, meas: Interval) -> tuple[float, float] | None:
    """f from the own measurement over the region: C x + Ds f ∈ [m_lo, m_hi] and C x ∈ [c_lo, c_hi] give
    Ds f ∈ [m_lo − c_hi, m_hi − c_lo].  A measurement at the sensor's limit (saturated) leaves one side of C x + Ds f
    open, and the other side still bounds f (one side of the result infinite); None where both are open or the
    sensor has no fault term."""
    if own.Ds == 0.0 or not (math.isfinite(meas.lo) or math.isfinite(meas.hi)):
        return None
    return fault_over(own, *region.interval(own.C), meas)


__all__ = ["Blend", "cut_by_own", "cut_by_slabs", "moved", "region_fault"]
