"""The cuts of the SDP step (estimator/cuts.py): the seed from an ellipsoid and the cut by an ellipsoid's slabs keep
every point of their input that the ellipsoid holds, so the published set ellipsoid ∩ region never loses a point of
the ellipsoid that the region held; and every declared cut keeps every point of its input sets that satisfies its
facts (Hypothesis, point by point)."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np
from fuzzing import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.config.schema import load_topology
from netsetest.estimator.cuts import HEALTH_FAULT, PIN_FLOOR, STEP_CUTS, NodeSet, Rests, StepContext, StepFigures, StepResult, StepSet, seed
from netsetest.estimator.health import HEALTH_KEY, HealthAssessment, Others
from netsetest.estimator.sdp import LocalEstimator, UpdateInput
from netsetest.estimator.sector import Interval, Sector
from netsetest.models.sensor import Sensor
from netsetest.polygon import Polygon
from netsetest.sets import Slab

ROOT = Path(__file__).resolve().parents[2]


@st.composite
def _ellipsoid(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """A random ellipsoid {(x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ} over (β, r, f) and points inside it (on its boundary too)."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    scale = draw(st.sampled_from([1e-3, 1.0, 30.0]))
    m = rng.normal(size=(3, 3)) * scale
    P = m @ m.T + 1e-6 * scale**2 * np.eye(3)
    xhat, rho = rng.normal(size=3) * scale, float(draw(st.sampled_from([0.5, 1.0, 2.0])))
    u = rng.normal(size=(80, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u *= rng.uniform(0.0, 1.0, size=(80, 1)) ** (1 / 3)
    u[:10] /= np.linalg.norm(u[:10], axis=1, keepdims=True)  # on the boundary
    pts = xhat + np.sqrt(rho) * u @ np.linalg.cholesky(P).T
    return xhat, P, rho, pts


@settings(max_examples=examples(150), deadline=None)
@given(_ellipsoid())
def test_the_seed_holds_every_point_of_the_ellipsoid(e: tuple[np.ndarray, np.ndarray, float, np.ndarray]) -> None:
    xhat, P, rho, pts = e
    region = seed(NodeSet(xhat, P, rho))
    assert _within(region, pts[:, :2]).all()


@settings(max_examples=examples(150), deadline=None)
@given(_ellipsoid(), st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_the_ellipse_cut_keeps_every_point_of_the_region_the_ellipsoid_holds(e: tuple[np.ndarray, np.ndarray, float, np.ndarray], a: float, b: float) -> None:
    """A region that holds part of the ellipsoid (a box through its centre, offset by a and b of its extent): the cut
    keeps every point of that part, and nothing outside the region's own box."""
    xhat, P, rho, pts = e
    half = np.sqrt(rho * np.diag(P))[:2]
    lo = xhat[:2] - half * (1.0 + a)
    hi = xhat[:2] + half * b
    region = Polygon.box(lo, hi)
    held = [p for p in pts if np.all(p[:2] >= lo) and np.all(p[:2] <= hi)]
    cut = region.ellipse_cut(xhat, P, rho)
    if cut is None:
        assert not held
        return
    assert _within(cut, np.reshape(held, (-1, 3))[:, :2]).all()
    v = cut.vertices
    assert np.all(v >= lo - 1e-6 * (1 + np.abs(lo))) and np.all(v <= hi + 1e-6 * (1 + np.abs(hi)))


# ---------------------------------------------------------------- every declared cut of the step (estimator/cuts.py)

TOLERANCE = 0.05  # the k-of-N tolerance τ of the drawn contexts (paper6's is 0: the pin's floor alone)
RTOL = 1e-7  # relative: a point on a set's boundary may round out by this (ρ of the ellipsoids, the fault range)


def _inside(res: StepResult, x: np.ndarray, rho: float) -> np.ndarray:
    """(n, 2): whether each point x̄ (n, 3) lies in the set the node continues from (ellipsoid ∩ region) and in the
    published one (ellipsoid ∩ fault range ∩ region), with the rounding allowance RTOL."""

    def member(s: StepSet) -> np.ndarray:
        e = x - s.xhat
        ok = np.einsum("ij,ij->i", e, np.linalg.solve(s.P, e.T).T) <= rho * (1 + RTOL)
        if s.fault_range is not None:
            slack = RTOL * (1 + abs(s.fault_range[0]) + abs(s.fault_range[1]))
            ok &= (s.fault_range[0] - slack <= x[:, 2]) & (x[:, 2] <= s.fault_range[1] + slack)
        if res.region is not None:  # in it, or within RTOL of its extent from it (a point on a cut face)
            ok &= _within(res.region, x[:, :2], RTOL * (1 + float(np.abs(res.region.vertices).max())))
        return ok

    return np.stack([member(res.continued), member(res.published)], axis=1)


def _within(region: Polygon, x: np.ndarray, slack: float = 0.0) -> np.ndarray:
    """(n,) whether each point of x (n, 2) lies within ``slack`` (∞-norm) of the region: dᵀx ≤ max_j dᵀv_j + slack·|d|₁
    for each side's normal and direction, both ways, and the axes (Polygon.contains's rule, for every point at once:
    the supporting lines of the vertices' hull, whatever their order)."""
    v = region.vertices
    e = np.roll(v, -1, axis=0) - v
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)
    d = np.vstack([n, -n, e, -e, np.eye(2), -np.eye(2)])
    return np.all(x @ d.T <= (v @ d.T).max(axis=0) + slack * np.abs(d).sum(axis=1), axis=1)


@st.composite
def _step(draw: st.DrawFn, kofn: bool = False) -> tuple[StepContext, StepResult, np.ndarray]:
    """A step's sets and context, at random: the continued ellipsoid, a published one (a bank-like reshape of it, or
    itself), a fault range or none, the moved region (a box around part of the ellipsoid's x-projection), the own
    measurement (finite, or open on one side: saturated), a reading's slab, the sector's basis and the k-of-N pin;
    and points of every input set (their intersection: the truth lies in all of them).  ``kofn``: always a k-of-N
    assessment and a region (what the health-fault cut needs to act)."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    own = _context().statics.own
    m = rng.normal(size=(3, 3)) * np.array([0.02, 0.05, 0.1])
    P = m @ m.T + 1e-5 * np.eye(3)
    xhat, rho = rng.normal(size=3) * np.array([0.01, 0.05, 0.1]), float(rng.uniform(0.5, 2.0))
    half = np.sqrt(rho * np.diag(P))
    published = None
    if draw(st.booleans()):  # a published ellipsoid of its own, through the same centre
        q = rng.normal(size=(3, 3)) * 0.3 + np.eye(3)
        published = StepSet(xhat + 0.1 * half * rng.normal(size=3), 1.3 * q @ P @ q.T, rho)
    fault_range = None
    if draw(st.booleans()):
        fault_range = (float(xhat[2] - half[2] * rng.uniform(0.2, 1.2)), float(xhat[2] + half[2] * rng.uniform(0.2, 1.2)))
        published = dataclasses.replace(published or StepSet(xhat, P, rho), fault_range=fault_range)
    basis = draw(st.sampled_from(["fault-bound", "measurement", "assumed"]))
    continued = StepSet(xhat, P, rho)
    res = StepResult(continued, published or continued, StepFigures("ok", 0.0, "solved"), sector=Sector(0.8, 0.2, basis))
    inner = draw(st.booleans())  # a region and a measurement well inside the ellipsoids: their faces bind, not its
    reach = (0.05, 0.4) if inner else (0.3, 1.5)
    moved = Polygon.box(xhat[:2] - half[:2] * rng.uniform(*reach, 2), xhat[:2] + half[:2] * rng.uniform(*reach, 2))
    pts = xhat + np.sqrt(rho) * _ball(rng, 600) @ np.linalg.cholesky(P).T
    r = pts[:, :2] @ own.C + own.Ds * pts[:, 2]  # the own measurement's combination C̄ x̄
    lo, hi = np.quantile(r, sorted(rng.uniform(0.35, 0.65, 2) if inner else rng.uniform(0.0, 1.0, 2)))
    meas = Interval(float(lo) if draw(st.booleans()) else -np.inf, float(hi) if draw(st.booleans()) else np.inf)
    c = np.r_[rng.normal(size=2), 0.0]
    cv = pts @ c
    slabs = {7: Slab(c, *np.quantile(cv, sorted(rng.uniform(0.0, 1.0, 2))))} if draw(st.booleans()) else {}
    c2 = np.r_[rng.normal(size=2), 0.0]  # a bounded reading's slab (it cuts the region alone), one side open or not
    ends = np.quantile(pts @ c2, sorted(rng.uniform(0.0, 1.0, 2)))
    region_slabs = {8: Slab(c2, float(ends[0]) if draw(st.booleans()) else -np.inf, float(ends[1]))} if draw(st.booleans()) else {}
    health = _health(draw, rng, pts, own) if kofn or draw(st.booleans()) else None
    if kofn or draw(st.booleans()):  # the region the step's region cut left (what the health-fault cut reads)
        res = dataclasses.replace(res, region=moved)
    statics = dataclasses.replace(_context().statics, own_bound=draw(st.booleans()))  # other nodes rely on its bound, or not
    ctx = dataclasses.replace(
        _context(),
        statics=statics,
        rho=rho,
        meas=meas,
        sector=res.sector,
        moved=moved,
        slabs=slabs,
        health=health,
        region_slabs=region_slabs,
        sets=frozenset({2}),
    )
    pts = np.vstack([pts, _extremes(moved, meas, own, rng, health)])
    pts = pts[_inside(res, pts, rho).all(axis=1)]
    held = pts[_within(moved, pts[:, :2])]
    return ctx, res, held


def _health(draw: st.DrawFn, rng: np.random.Generator, pts: np.ndarray, own: Sensor) -> HealthAssessment:
    """A k-of-N assessment at random: the pin or not, and five other sensors' spans of t = uᵀx (between quantiles of
    the points' t, all below a drawn one so that they may agree on one side only; or (−∞, ∞): a reading not here),
    two of which must agree."""
    u = own.C / np.linalg.norm(own.C)
    t = pts[:, :2] @ u
    top = draw(st.sampled_from([0.4, 0.7, 1.0]))
    spans = tuple(
        (float(a), float(b)) if draw(st.integers(0, 4)) else (-np.inf, np.inf) for a, b in (np.quantile(t, sorted(rng.uniform(0.0, top, 2))) for _ in range(5))
    )
    return HealthAssessment(None, draw(st.booleans()), Others(u, spans, 2))


def _extremes(moved: Polygon, meas: Interval, own: Sensor, rng: np.random.Generator, health: HealthAssessment | None) -> np.ndarray:
    """Points where a cut's faces meet: at the region's vertices and on its sides, and where it meets the lines
    uᵀx = an end of a k-of-N span; the fault at the own measurement's ends (C x + Ds f = m_lo, m_hi), at ±F and at
    ±(the pin): the extreme points of what the cuts keep, which random points of the ellipsoid almost never reach."""
    v = moved.vertices
    x = np.vstack([v, v + rng.uniform(0.0, 1.0, (len(v), 1)) * (np.roll(v, -1, axis=0) - v)])
    if health is not None:  # u = (0, 1) for a yaw-rate sensor: the points of the box's sides at t = a span's end
        (b_lo, t_lo), (b_hi, t_hi) = v.min(axis=0), v.max(axis=0)
        ends = [e for sp in health.others.spans for e in sp if t_lo <= e <= t_hi]
        x = np.vstack([x, *([[b_lo, e], [b_hi, e]] for e in ends)])
    faults = [np.full(len(x), f) for f in (-0.2, 0.2, -0.05, 0.05, -PIN_FLOOR, PIN_FLOOR)]
    faults += [(m - x @ own.C) / own.Ds for m in (meas.lo, meas.hi) if np.isfinite(m)]
    if health is not None:  # the ends of the faults at x that both the measurement and the pin allow (Ds > 0)
        floor = max(TOLERANCE, PIN_FLOOR)
        faults += [np.maximum((meas.lo - x @ own.C) / own.Ds, -floor), np.minimum((meas.hi - x @ own.C) / own.Ds, floor)]
    return np.vstack([np.column_stack([x, f]) for f in faults])


def _ball(rng: np.random.Generator, n: int) -> np.ndarray:
    """n points of the unit ball in R³, a fifth of them on its sphere."""
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u * np.where(np.arange(n)[:, None] < n // 5, 1.0, rng.uniform(0.0, 1.0, size=(n, 1)) ** (1 / 3))


def _facts(name: str, ctx: StepContext, res: StepResult, x: np.ndarray) -> np.ndarray:
    """(n,) whether each point x̄ of x (n, 3) satisfies what cut ``name`` rests on (its slabs)."""
    st_ = ctx.statics
    every = np.ones(len(x), dtype=bool)
    readings = every.copy()
    for sl in ctx.slabs.values():
        readings &= (sl.lo <= x @ sl.a) & (x @ sl.a <= sl.hi)
    bounded_readings = every.copy()
    for sl in ctx.region_slabs.values():
        bounded_readings &= (sl.lo <= x @ sl.a) & (x @ sl.a <= sl.hi)
    size = st_.fault_bound.size
    relied = st_.own_bound or (res.sector is not None and res.sector.basis == "fault-bound")  # the declared size, where the step rests on it
    bounded = every if size is None or not relied else np.abs(x[:, 2]) <= size
    healthy = np.abs(x[:, 2]) <= max(st_.health_tolerance or 0.0, PIN_FLOOR)
    pinned = every if ctx.health is None or not ctx.health.pinned else healthy
    m = x[:, :2] @ st_.own.C + st_.own.Ds * x[:, 2]
    measured = (ctx.meas.lo <= m) & (m <= ctx.meas.hi)
    others = ctx.health.others if ctx.health is not None else None
    if others is None:
        agreeing = ~every
    else:
        t = x[:, :2] @ others.u
        agreeing = sum(((lo <= t) & (t <= hi)).astype(int) for lo, hi in others.spans) >= others.need
    in_region = every if res.region is None else _within(res.region, x[:, :2])
    return {
        "readings": readings,
        "fault-size": bounded,
        "region": readings & bounded_readings & bounded & measured & _within(ctx.moved, x[:, :2]),
        "health-pin": pinned,
        "health-fault": every if ctx.health is None else measured & in_region & (healthy | agreeing),
    }[name]


@functools.cache
def _context() -> StepContext:
    """A real step context (paper6 SAIM, node 1, from its prior), whose fields the draws replace; k-of-N tolerance
    set so that the pin cut has one."""
    sc = load_topology(ROOT / "topologies" / "paper6.toml", "saim", 5)
    est = LocalEstimator.for_node(sc, 1)
    n = sc.node(1)
    inp = UpdateInput(sc.model.weights(sc.vx(0)), (sc.steer_low + sc.steer_high) / 2, 0.03, 1.0, {})
    ctx = est.context(NodeSet(n.x0_hat, n.P0, n.rho), inp)
    return dataclasses.replace(ctx, statics=dataclasses.replace(ctx.statics, health_tolerance=TOLERANCE))


@settings(max_examples=examples(80), deadline=None)
@given(_step(), st.sampled_from([c.name for c in STEP_CUTS]))
def test_every_cut_keeps_every_point_of_its_input_that_satisfies_its_slab(step: tuple[StepContext, StepResult, np.ndarray], name: str) -> None:
    """Each declared cut (readings, fault-size, region, health-pin, health-fault), on random sets and contexts: every point of its
    input sets (the truth lies in all of them) that satisfies the cut's facts lies in both sets it returns (the one
    the node continues from and the published one)."""
    ctx, res, held = step
    cut = next(c for c in STEP_CUTS if c.name == name)
    out = cut.apply(ctx, res)
    kept = held[_facts(name, ctx, res, held)]
    inside = _inside(out, kept, ctx.rho)
    assert inside.all(), (name, kept[~inside.all(axis=1)])


@settings(max_examples=examples(60), deadline=None)
@given(_step(kofn=True))
def test_the_health_fault_cut_keeps_every_point_of_its_input_that_a_hypothesis_allows(step: tuple[StepContext, StepResult, np.ndarray]) -> None:
    """The health-fault cut, on every draw with a k-of-N assessment and a region: every point of its input sets in
    the region and its own measurement whose fault is within the pin, or whose t = uᵀx at least ``need`` of the
    other sensors' spans hold, lies in both sets it returns."""
    ctx, res, held = step
    out = HEALTH_FAULT.apply(ctx, res)
    kept = held[_facts("health-fault", ctx, res, held)]
    inside = _inside(out, kept, ctx.rho)
    assert inside.all(), kept[~inside.all(axis=1)]


def test_a_step_rests_on_the_readings_its_sets_were_cut_by() -> None:
    """What the node lists (StepResult.rests_on): the readings of both sets, the published one's and the continued
    one's, as node ids, and whether the k-of-N facts are among them (the estimator's key for them is no node)."""
    pub = StepSet(np.zeros(3), np.eye(3), 1.0, reading_keys=frozenset({3, HEALTH_KEY}))
    res = StepResult(StepSet(np.zeros(3), np.eye(3), 1.0, reading_keys=frozenset({4})), pub, StepFigures("ok", 0.0, "solved"))
    assert res.rests_on == Rests(frozenset({3, 4}), True)
    assert dataclasses.replace(res, published=res.continued).rests_on == Rests(frozenset({4}), False)


def test_the_region_cut_rests_on_the_bounded_readings_and_the_neighbours_sets_it_used() -> None:
    """A region cut by a bounded reading's slab and moved from a neighbour's set names both (the node lists them)."""
    ctx = _context()
    res = StepResult.of(StepSet(np.zeros(3), 1e-4 * np.eye(3), 1.0), StepFigures("ok", 0.0, "solved"))
    c = np.array([0.0, 1.0, 0.0])
    out = next(x for x in STEP_CUTS if x.name == "region").apply(
        dataclasses.replace(
            ctx, moved=Polygon.box(np.array([-0.01, -0.01]), np.array([0.01, 0.01])), region_slabs={5: Slab(c, -0.005, np.inf)}, sets=frozenset({2})
        ),
        res,
    )
    assert out.region is not None and out.region.interval(c[:2])[0] >= -0.005 - 1e-8  # (the cut's margin)
    assert 5 in out.rests_on.readings and out.rests_on.sets == {2}


# ---------------------------------------------------------------- a region cut the readings leave empty (cuts._region_without_readings)


def _contradicting(ctx: StepContext, gap: float) -> dict[int, Slab]:
    """A reading's slab beyond the moved region by ``gap`` (of the region's extent along it): it leaves nothing."""
    c = np.array([0.0, 1.0, 0.0])
    top = float(ctx.moved.vertices[:, 1].max())
    extent = float(np.ptp(ctx.moved.vertices[:, 1]))
    return {7: Slab(c, top + gap * extent + 1e-6, top + (gap + 1.0) * extent + 1e-6)}


@settings(max_examples=examples(80), deadline=None)
@given(_step(), st.sampled_from([0.05, 0.5, 3.0]))
def test_a_region_the_readings_leave_empty_is_the_own_datas(step: tuple[StepContext, StepResult, np.ndarray], gap: float) -> None:
    """A step whose reading (a reference's slab) misses the moved region: the region is the moved one cut by the own
    data alone (the own measurement with the fault bound where the step rests on it, the step's ellipsoids), so it holds
    every point of the step's sets that those allow; it rests on no reading of the step (the published set rests on
    none either), and the step's result says the readings contradicted the node's own data.  The region is kept, so the
    next step's cuts work again (tests/inmemory/test_network_value.py, the gross false reference reading)."""
    ctx, res, held = step
    ctx = dataclasses.replace(ctx, slabs=_contradicting(ctx, gap))
    region = next(c for c in STEP_CUTS if c.name == "region")
    out = region.apply(ctx, res)
    own = dataclasses.replace(ctx, slabs={}, region_slabs={})
    kept = held[_facts("region", own, res, held)]  # what the own data allow of the step's sets
    inside = _inside(out, kept, ctx.rho)
    assert inside.all(), kept[~inside.all(axis=1)]
    assert out.contradicted is not None
    if out.contradicted.by == "readings":
        assert out.region is not None and out.contradicted.readings == {7, *ctx.region_slabs}
        assert not out.rests_on.readings and out.rests_on.sets == ctx.sets  # the moved region's in-neighbours only
    else:  # the own data leave nothing either: no region of the step's (its input's stays), nothing the own data allow
        assert out.region is res.region and out.published is res.published and not len(kept)


def test_a_region_the_readings_leave_empty_keeps_no_more_than_the_own_data_allow() -> None:
    """The region kept without the readings is the own data's: its C x is the own measurement's interval widened by
    |Ds| F (C x = C̄ x̄ − Ds f, |f| ≤ F), not the moved region's; at the first step the readings contradict it starts
    from the step's own set, after that from the moved region; a region the own data leave empty too is none, named
    so; a step whose readings fit names nothing."""
    ctx = _context()
    size = 0.01
    statics = dataclasses.replace(ctx.statics, fault_bound=dataclasses.replace(ctx.statics.fault_bound, size=size))
    moved = Polygon.box(np.array([-0.01, -0.5]), np.array([0.01, 0.5]))
    res = StepResult.of(StepSet(np.zeros(3), np.eye(3), 1.0), StepFigures("ok", 0.0, "solved"), Sector(0.8, 0.2, "fault-bound"))
    cut = next(c for c in STEP_CUTS if c.name == "region").apply
    own = ctx.statics.own
    ctx = dataclasses.replace(ctx, statics=statics, moved=moved, sector=res.sector, region_slabs={}, sets=frozenset(), meas=Interval(-0.01, 0.01))
    ctx = dataclasses.replace(ctx, slabs=_contradicting(ctx, 0.5))
    out = cut(ctx, res)
    assert out.contradicted is not None and out.contradicted.by == "readings" and out.contradicted.readings == {7} and out.region is not None
    lo, hi = out.region.interval(own.C)
    slack = abs(own.Ds) * size
    # the own measurement's (out by the cut's margin), not ±0.06
    assert -0.01 - slack - 1e-8 <= lo <= -0.01 - slack and 0.01 + slack <= hi <= 0.01 + slack + 1e-8
    # the first step they contradict: from the box of the step's own set (|β| ≤ 1); while they go on contradicting it,
    # from the moved region (|β| ≤ 0.01): its memory since rests on none of them
    assert out.region.interval(np.array([1.0, 0.0]))[1] > 0.9
    streak = cut(dataclasses.replace(ctx, region_without=frozenset({7})), res)
    assert streak.region is not None and streak.region.interval(np.array([1.0, 0.0]))[1] <= 0.01 + 1e-8
    gone = cut(dataclasses.replace(ctx, meas=Interval(0.5, 0.6)), res)  # the own reading beyond the moved region too
    assert gone.contradicted is not None and gone.contradicted.by == "own-data" and gone.region is None
    assert cut(dataclasses.replace(ctx, slabs={}), res).contradicted is None
