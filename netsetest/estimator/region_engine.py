"""The region engine every estimator family uses (docs/estimator.md, "The set a node proves"): a convex polygon of
x = (β, r) moved through a step, cut by the slabs the step proves, cut by the own measurement with the declared fault
bound, and the fault its own measurement proves over it.

The SDP (:mod:`netsetest.estimator.cuts`, the ``region`` cut) and the other papers' set estimators
(:class:`~netsetest.estimator.region.WithRegion`) both call these functions, so a region is moved, cut and read the
same way whichever method keeps it: the same blended model (:class:`Blend`), the same segments of the disturbance and
the declared model mismatch, the same measurement interval (:func:`~netsetest.estimator.sector.measurement_interval`,
rounded outward) and the same fault over the region, one-sided where the reading is at the sensor's limit.

A step enters this module twice (tests/unit/test_step_shape.py): :func:`advance` before its solve (the blend, the
neighbours' regions, the move: one polygon operation) and :func:`cut` after it (every slab, the own measurement, the
ellipsoids, the reduction, the faults over the result: one polygon operation).

Each function keeps every point of its input that its facts allow (tests/unit/test_region_engine.py): the move holds
x⁺ = Ā x + B̄ u + D̄ w + e for every x of the region, |w| ≤ √W and e in the mismatch's box; a cut holds every x with
cᵀx in the slab (widened outward by :meth:`~netsetest.polygon.Polygon.cut`'s margin).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

import netsetest.polygon as polygon
from netsetest.estimator.health import Others
from netsetest.estimator.sector import Interval
from netsetest.models.sensor import NA, NX, Sensor
from netsetest.models.uncertainty import ModelUncertainty
from netsetest.models.vehicle import TSModel
from netsetest.polygon import Ellipse, PlaneSlab, Polygon
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


def _segments(blend: Blend, W: float, uncertainty: ModelUncertainty | None) -> list[np.ndarray]:
    """The step's segments: the disturbance's D̄√W and the declared mismatch's generators (a box around e = G ζ,
    |ζ_m| ≤ 1, holds it for either kind)."""
    segments = [blend.d * math.sqrt(W)]
    if uncertainty is not None:
        segments += [uncertainty.G[:, m] for m in range(NX)]
    return segments


def moved(region: Polygon, blend: Blend, u: float, W: float, uncertainty: ModelUncertainty | None) -> Polygon:
    """The states x⁺ = Ā x + B̄ u + D̄ w + e of every x in ``region``: its image, plus the disturbance's segment D̄√W and
    the declared mismatch's generators, plus the rounding margin (:meth:`~netsetest.polygon.Polygon.moved`)."""
    return region.moved(blend.a, blend.b * u, _segments(blend, W, uncertainty))


@dataclass(frozen=True)
class Moved:
    """A region through one step (:func:`advance`): the step's blend, the moved region, the in-neighbours whose
    published region cut it before the move, and its interval of dᵀx along the direction asked for (None: none)."""

    blend: Blend
    region: Polygon
    sets: frozenset[int]
    span: tuple[float, float] | None


def advance(
    model: TSModel,
    alpha: np.ndarray,
    region: Polygon,
    others: Mapping[int, Polygon],
    u: float,
    W: float,
    uncertainty: ModelUncertainty | None,
    direction: np.ndarray | None = None,
) -> Moved:
    """The region of a step before its solve, in one call: the step's blend (:meth:`Blend.of`), ``region`` cut by the
    in-neighbours' published regions of step k (``others``: each holds x_k wherever that neighbour's set holds the
    truth) and moved through the step (:func:`moved`: exact for the truth), and the moved region's interval along
    ``direction`` (the k-of-N uᵀx⁺)."""
    blend = Blend.of(model, alpha)
    keys = list(others)
    out = polygon.advance(region, [others[j] for j in keys], blend.a, blend.b * u, _segments(blend, W, uncertainty), () if direction is None else (direction,))
    return Moved(blend, out.polygon, frozenset(keys[k] for k in out.used), out.spans[0] if out.spans else None)


def _plane(slabs: Iterable[Slab]) -> list[PlaneSlab]:
    """The slabs lo ≤ aᵀx̄ ≤ hi over x̄ = (x, f) with a part in x, as lo ≤ a_β β + a_r r ≤ hi (a reading's C_j x, the k-of-N
    uᵀx); a slab of f alone, the k-of-N pin, is the fault range's, not the region's."""
    return [(float(s.a[0]), float(s.a[1]), s.lo, s.hi) for s in slabs if s.a[:NX].any()]


def _own_slab(own: Sensor, meas: Interval, size: float) -> PlaneSlab:
    """The own measurement with the declared fault size: C x = C̄ x̄ − Ds f with C̄ x̄ in ``meas`` and |f| ≤ F (an open
    side of ``meas``, at the sensor's limit, leaves that side open)."""
    slack = abs(own.Ds) * size
    return float(own.C[0]), float(own.C[1]), meas.lo - slack, meas.hi + slack


def fault_over(own: Sensor, c_lo: float, c_hi: float, meas: Interval) -> tuple[float, float]:
    """f from the own measurement where C x ∈ [c_lo, c_hi]: C x + Ds f ∈ [m_lo, m_hi] gives Ds f ∈ [m_lo − c_hi,
    m_hi − c_lo] (an open side of the measurement, at the sensor's limit, leaves that side of the result open); the
    sensor has a fault term (Ds ≠ 0)."""
    finite_lo, finite_hi = math.isfinite(meas.lo), math.isfinite(meas.hi)
    a = (meas.lo - c_hi) / own.Ds if finite_lo else -math.inf * own.Ds  # (an open side stays open, whatever Ds's sign)
    b = (meas.hi - c_lo) / own.Ds if finite_hi else math.inf * own.Ds
    return (a, b) if own.Ds > 0.0 else (b, a)


def _fault(own: Sensor, span: tuple[float, float], meas: Interval) -> tuple[float, float] | None:
    """f from the own measurement where C x lies in ``span`` (a region's): None where both sides of the measurement are
    open or the sensor has no fault term; one side infinite where the reading is at the sensor's limit."""
    if own.Ds == 0.0 or not (math.isfinite(meas.lo) or math.isfinite(meas.hi)):
        return None
    return fault_over(own, span[0], span[1], meas)


def health_fault(own: Sensor, others: Others, extent: tuple[float, float], meas: Interval, floor: float) -> tuple[float, float]:
    """Under k-of-N, the own fault where uᵀx lies in ``extent`` (a region's) and ``meas`` holds C x + Ds f: the own
    sensor is healthy (|f| ≤ ``floor``, at least τ) or uᵀx lies where the others agree (:meth:`Others.agree`), and
    there the measurement bounds f (C = s uᵀ: C x = s uᵀx); the hull of the two.  The sensor has a fault term."""
    agree = others.agree(extent)
    if agree is None:  # the others agree nowhere: the own sensor is healthy (the pin)
        return -floor, floor
    s = float(own.C @ others.u)
    a, b = fault_over(own, min(s * agree[0], s * agree[1]), max(s * agree[0], s * agree[1]), meas)
    return min(a, -floor), max(b, floor)


@dataclass(frozen=True)
class RegionFacts:
    """What a step's region cut proves (:func:`cut`): the reduced region, its interval hull (β lo, r lo, β hi, r hi), the
    fault its own measurement proves over it (:func:`_fault`; None: none) and, under k-of-N, the own fault where
    the own sensor is healthy or the others agree (:func:`health_fault`; None: not asked)."""

    region: Polygon
    box: tuple[float, float, float, float]
    fault: tuple[float, float] | None
    health: tuple[float, float] | None = None


def cut(
    region: Polygon,
    slabs: Iterable[Slab],
    own: Sensor,
    meas: Interval,
    size: float | None = None,
    after: Iterable[Slab] = (),
    ellipses: Sequence[Ellipse] = (),
    others: Others | None = None,
    floor: float = 0.0,
) -> RegionFacts | None:
    """A step's region cuts in one call (one polygon operation, :func:`~netsetest.polygon.cut_all`): by every slab
    (:func:`_plane`), by the own measurement with the declared fault size (``size``; None: not), by the slabs
    ``after``, by every ellipse's octagon, reduced; then the fault over it and, with ``others`` (k-of-N, a sensor with
    a fault term), :func:`health_fault` at ``floor``.  None where nothing is left (an assumption broke)."""
    plane = _plane(slabs)
    if size is not None:
        plane.append(_own_slab(own, meas, size))
    plane += _plane(after)
    directions = (own.C,) if others is None else (own.C, others.u)
    out = polygon.cut_all(region, plane, ellipses, directions)
    if out is None:
        return None
    health = health_fault(own, others, out.spans[1], meas, floor) if others is not None else None
    return RegionFacts(out.polygon, out.box, _fault(own, out.spans[0], meas), health)


__all__ = ["Blend", "Moved", "RegionFacts", "advance", "cut", "fault_over", "health_fault", "moved"]
