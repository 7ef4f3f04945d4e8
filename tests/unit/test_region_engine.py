"""The region engine every estimator family uses (estimator/region_engine.py): the move, the cut by slabs, the cut by
the own measurement and the fault over the region each keep every point their hypotheses allow (Hypothesis, point by
point, the extreme points among them), and each check fails on a result 5 % narrower (so it sees a lost point).  And
the one measurement interval (Sensor.measured_interval, rounded outward) holds every r its reading allows."""

from __future__ import annotations

import itertools
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.estimator import region_engine
from netsetest.estimator.region_engine import Blend
from netsetest.estimator.sector import Interval, measurement_interval
from netsetest.models.sensor import Sensor
from netsetest.models.uncertainty import ModelUncertainty
from netsetest.polygon import Polygon
from netsetest.sets import Slab

NARROWER = 0.05  # a result this much narrower (about its centre) must lose one of the points


def _within(region: Polygon, x: np.ndarray) -> np.ndarray:
    """(n,) whether each point of x (n, 2) lies in the region: every supporting line of its vertices' hull, both ways
    (tests/unit/test_region_cuts.py's rule), within a rounding of the coordinates (10⁻¹² of their size: an edge point
    interpolated here rounds too; the engine's own margins are 10⁻⁹ and more, and 5 % is far beyond)."""
    v = region.vertices
    slack = 1e-12 * (1.0 + float(np.abs(v).max()))
    e = np.roll(v, -1, axis=0) - v
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)
    d = np.vstack([n, -n, e, -e, np.eye(2), -np.eye(2)])
    return np.all(x @ d.T <= (v @ d.T).max(axis=0) + slack * np.abs(d).sum(axis=1), axis=1)


def _narrowed(region: Polygon) -> Polygon:
    """The region shrunk by NARROWER about its vertices' mean."""
    v = region.vertices
    c = v.mean(axis=0)
    return Polygon(c + (1.0 - NARROWER) * (v - c))


@st.composite
def _region(draw: st.DrawFn) -> tuple[Polygon, np.random.Generator, float]:
    """A random convex polygon (points of an ellipse in angle order, at a random scale), a generator and the scale."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    scale = draw(st.sampled_from([1e-3, 1.0, 30.0]))
    angles = np.sort(rng.uniform(0.0, 2 * np.pi, size=draw(st.integers(3, 12))))
    circle = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    shape = np.diag(rng.uniform(0.2, 1.0, size=2)) @ np.linalg.qr(rng.normal(size=(2, 2)))[0]
    pts = (circle @ shape.T + rng.normal(size=2)) * scale
    return Polygon(pts), rng, scale


def _inner(region: Polygon, rng: np.random.Generator, n: int = 60) -> np.ndarray:
    """(n + vertices, 2): the region's vertices and random convex combinations of them."""
    v = region.vertices
    w = rng.dirichlet(np.ones(len(v)), size=n)
    return np.vstack([v, w @ v])


@settings(max_examples=150, deadline=None)
@given(_region(), st.floats(-2.0, 2.0), st.floats(0.0, 4.0), st.booleans())
def test_the_move_keeps_every_state_the_dynamics_allow(r: tuple[Polygon, np.random.Generator, float], u: float, W: float, mismatch: bool) -> None:
    """x⁺ = Ā x + B̄ u + D̄ w + G ζ for every x of the region (its vertices among them), |w| ≤ √W and |ζ_m| ≤ 1 (the
    extremes among them) lies in the moved region; a moved region 5 % narrower loses one of them."""
    region, rng, scale = r
    a = np.eye(2) + 0.3 * rng.normal(size=(2, 2))
    b, d = rng.normal(size=2), rng.normal(size=2) * 0.1
    blend = Blend(a, b, d, np.zeros((3, 3)), np.append(b, 0.0), np.append(d, 0.0))
    unc = ModelUncertainty("box", 0.05 * scale * np.diag(rng.uniform(0.1, 1.0, size=2))) if mismatch else None
    moved = region_engine.moved(region, blend, u, W, unc)
    g = unc.G if unc is not None else np.zeros((2, 2))
    xs = _inner(region, rng)
    ends = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))  # w/√W, ζ₁, ζ₂ at their bounds
    pts = [(a @ x + b * u)[None, :] + np.outer(e[:, 0], d * math.sqrt(W)) + e[:, 1:] @ g.T for x in xs for e in (ends, rng.uniform(-1, 1, size=(4, 3)))]
    after = np.vstack(pts)
    assert _within(moved, after).all()
    assert not _within(_narrowed(moved), after).all()


def _edge_points(region: Polygon, c: np.ndarray, level: float) -> list[np.ndarray]:
    """The points of the region's edges where cᵀx = level."""
    v = region.vertices
    out = []
    for p, q in zip(v, np.roll(v, -1, axis=0)):
        cp, cq = float(c @ p), float(c @ q)
        if (cp - level) * (cq - level) <= 0.0 and cp != cq:
            t = (level - cp) / (cq - cp)
            out.append(p + t * (q - p))
    return out


@settings(max_examples=150, deadline=None)
@given(_region(), st.floats(0.05, 0.95), st.floats(0.05, 0.95), st.floats(-1.0, 1.0), st.booleans())
def test_the_cut_by_slabs_keeps_every_state_of_the_region_in_the_slab(
    r: tuple[Polygon, np.random.Generator, float], p: float, q: float, fault_part: float, open_side: bool
) -> None:
    """Every x of the region with lo ≤ aᵀ(x, f) ≤ hi (a over x̄ = (x, f), its fault part left out of the region: that
    is the fault range's) stays, the slab's edge points among them; a slab of f alone leaves the region as it is; the
    result 5 % narrower loses one of them."""
    region, rng, _ = r
    c = rng.normal(size=2)
    lo_r, hi_r = region.interval(c)
    lo, hi = sorted((lo_r + p * (hi_r - lo_r), lo_r + q * (hi_r - lo_r)))
    hi = max(hi, lo + 1e-3 * (hi_r - lo_r))
    if open_side:
        hi = math.inf
    cut = _cut(region, [Slab(np.array([0.0, 0.0, 1.0]), -1.0, 1.0), Slab(np.append(c, fault_part), lo, hi)])
    assert cut is not None
    xs = _inner(region, rng, 200)
    s = xs @ c
    kept = [*xs[(s >= lo) & (s <= hi)], *_edge_points(region, c, lo), *([] if open_side else _edge_points(region, c, hi))]
    pts = np.reshape(kept, (-1, 2))
    assert _within(cut, pts).all()
    assert not _within(_narrowed(cut), pts).all()
    assert _cut(region, [Slab(np.array([0.0, 0.0, 1.0]), -1.0, 1.0)]) is region


SENSOR = Sensor(C=np.array([0.3, 1.0]), Ds=1.0, Dv=0.01, R=1.0, saturated=True, r_max=0.5, h1=0.5, h2=1.0)
NOTHING = Interval(-math.inf, math.inf)  # a measurement that bounds nothing


def _cut(region: Polygon, slabs: list[Slab] | None = None, meas: Interval = NOTHING, size: float | None = None) -> Polygon | None:
    """The region engine's cut (one call: the slabs, then the own measurement with the fault size where given) alone."""
    facts = region_engine.cut(region, slabs or [], SENSOR, meas, size)
    return None if facts is None else facts.region


def _yaw_region(r: tuple[Polygon, np.random.Generator, float]) -> tuple[Polygon, np.random.Generator]:
    """The drawn region scaled to states of a yaw rate's size."""
    region, rng, scale = r
    return Polygon(region.vertices / scale * 0.2), rng


@settings(max_examples=150, deadline=None)
@given(_region(), st.floats(0.0, 0.2), st.floats(-0.6, 0.6), st.sampled_from([1.0, 0.7]))
def test_the_own_measurement_cut_keeps_every_state_some_allowed_fault_explains(
    r: tuple[Polygon, np.random.Generator, float], size: float, y: float, gamma: float
) -> None:
    """For a reading ỹ (saturated or not, so a side may be open): every x of the region with some |f| ≤ F such that
    C x + Ds f lies in the measurement interval stays, the cut's edge points among them; 5 % narrower loses one."""
    region, rng = _yaw_region(r)
    meas = measurement_interval(SENSOR, y, gamma)
    lo, hi = meas.lo - abs(SENSOR.Ds) * size, meas.hi + abs(SENSOR.Ds) * size
    xs = _inner(region, rng, 200)
    cx = xs @ SENSOR.C
    kept = [
        *xs[(cx >= lo) & (cx <= hi)],
        *(_edge_points(region, SENSOR.C, lo) if math.isfinite(lo) else []),
        *(_edge_points(region, SENSOR.C, hi) if math.isfinite(hi) else []),
    ]
    cut = _cut(region, meas=meas, size=size)
    if not kept:
        return
    pts = np.reshape(kept, (-1, 2))
    assert cut is not None and _within(cut, pts).all()
    assert not _within(_narrowed(cut), pts).all()


@settings(max_examples=150, deadline=None)
@given(_region(), st.floats(-0.6, 0.6), st.sampled_from([1.0, 0.7]))
def test_the_fault_over_the_region_holds_every_fault_the_reading_allows(r: tuple[Polygon, np.random.Generator, float], y: float, gamma: float) -> None:
    """Every f with C x + Ds f in the measurement interval for some x of the region lies in the fault over the region;
    where the reading is at the sensor's limit the open side stays open and the other still bounds f (what the set
    estimators lacked before the one engine); each finite end moved in by 5 % of the interval (1 where it is open)
    loses the extreme f."""
    region, rng = _yaw_region(r)
    meas = measurement_interval(SENSOR, y, gamma)
    facts = region_engine.cut(region, [], SENSOR, meas)
    assert facts is not None and facts.region is region
    fault = facts.fault
    assert fault is not None  # |y| ≤ 0.6: a reading bounds at least one side of C x + Ds f
    lo, hi = fault
    cx = _inner(region, rng, 200) @ SENSOR.C
    span = hi - lo if math.isfinite(hi - lo) else 1.0
    tol = 1e-12
    if math.isfinite(meas.lo):  # the lowest f: C x + Ds f at the interval's low end, x at the region's highest C x
        f = (meas.lo - cx) / SENSOR.Ds
        assert np.all(f >= lo - tol) and f.min() < lo + NARROWER * span
    else:
        assert lo == -math.inf
    if math.isfinite(meas.hi):
        f = (meas.hi - cx) / SENSOR.Ds
        assert np.all(f <= hi + tol) and f.max() > hi - NARROWER * span
    else:
        assert hi == math.inf


@settings(max_examples=300, deadline=None)
@given(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.sampled_from([1.0, 0.6, 0.1]))
def test_the_measurement_interval_holds_every_r_its_reading_allows(r: float, v: float, gamma: float) -> None:
    """ỹ = γσ(r) + Dv v with v² ≤ R (v at its bound too): r lies in the one measurement interval, rounded outward (what
    every estimator uses), which holds the exact interval (the exact limit's: the same open sides), and an end within
    the sensor's range is never open (only a side at the limit is)."""
    v = float(np.clip(v, -1.0, 1.0))
    y = gamma * SENSOR.sigma(r) + SENSOR.Dv * v * math.sqrt(SENSOR.R)
    lo, hi = SENSOR.measured_interval(y, gamma, outward=True)
    assert lo <= r <= hi
    assert Interval(lo, hi) == measurement_interval(SENSOR, y, gamma)
    e_lo, e_hi = SENSOR.measured_interval(y, gamma)
    assert lo <= e_lo <= e_hi <= hi and math.isfinite(lo) == math.isfinite(e_lo) and math.isfinite(hi) == math.isfinite(e_hi)
    if abs(r) < 0.4 * SENSOR.r_max and gamma == 1.0:
        assert math.isfinite(lo) and math.isfinite(hi)
