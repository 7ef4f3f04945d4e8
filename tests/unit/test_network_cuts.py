"""What a node takes from its network (issue 44, docs/network.md): its region cut by an in-neighbour's published region
(Polygon.within, LocalEstimator's moved region) and by a bounded reading's slab (LocalEstimator._bounded_slabs) keeps
every point their hypotheses allow (Hypothesis, point by point), and the same tests fail on a cut narrowed by 5 %:
they could catch an unsound one."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from fuzzing import examples
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from netsetest.config.schema import load_topology
from netsetest.estimator.cuts import NodeSet, StepFigures, StepResult, StepSet
from netsetest.estimator.sdp import LocalEstimator, NeighbourState, UpdateInput
from netsetest.estimator.sector import Interval, measurement_interval
from netsetest.models.sensor import NA
from netsetest.polygon import SLIVER, Polygon
from netsetest.sets import Slab

ROOT = Path(__file__).resolve().parents[2]
NARROWED = 0.05  # the deliberately unsound cut: 5 % narrower than the one under test
RTOL = 1e-9  # relative to the coordinates: a point on a cut face may round out by this


def _hull(points: np.ndarray) -> Polygon:
    """The convex hull of ``points`` (n, 2), counter-clockwise (Andrew's monotone chain)."""
    pts = sorted(map(tuple, points.tolist()))

    def chain(ps: list) -> list:
        out: list = []
        for p in ps:
            while len(out) >= 2 and (out[-1][0] - out[-2][0]) * (p[1] - out[-2][1]) - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0]) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = chain(pts), chain(pts[::-1])
    return Polygon(np.array(lower[:-1] + upper[:-1], dtype=float))


def _narrowed(poly: Polygon | None) -> Polygon | None:
    """``poly`` shrunk by NARROWED about its vertices' mean."""
    if poly is None:
        return None
    c = poly.vertices.mean(axis=0)
    return Polygon(c + (1.0 - NARROWED) * (poly.vertices - c))


def _near(poly: Polygon | None, x: np.ndarray, rtol: float = RTOL) -> bool:
    """x in the polygon widened by ``rtol`` of its extent: within that distance of every side's supporting line (the
    support over every vertex along the side's unit outward normal: a point on a cut face; the drawn polygons are
    never flat)."""
    if poly is None:
        return False
    v = poly.vertices
    e = np.roll(v, -1, axis=0) - v
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)
    length = np.linalg.norm(n, axis=1)
    d = n[length > 0] / length[length > 0, None]
    return bool(np.all(d @ x <= (v @ d.T).max(axis=0) + rtol * (1.0 + float(np.abs(v).max()))))


def _inside(poly: Polygon, x: np.ndarray) -> np.ndarray:
    """(n,): whether each point of x (n, 2) lies in the convex polygon (its sides' supporting half-planes)."""
    v = poly.vertices
    e = np.roll(v, -1, axis=0) - v
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)
    return np.all(x @ n.T <= (v @ n.T).max(axis=0), axis=1)


@st.composite
def _two_regions(draw: st.DrawFn) -> tuple[Polygon, Polygon, np.ndarray]:
    """Two random convex polygons that overlap (around a common point, at every scale the state takes) and points of
    their intersection: random ones, the vertices of each inside the other, and points on each side's crossing."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    scale = draw(st.sampled_from([1e-3, 0.05, 1.0]))
    centre = rng.normal(size=2) * scale
    a = _hull(centre + rng.normal(size=(draw(st.integers(3, 16)), 2)) * scale * rng.uniform(0.2, 2.0, 2))
    b = _hull(centre + rng.normal(size=(draw(st.integers(3, 16)), 2)) * scale * rng.uniform(0.2, 2.0, 2) + rng.normal(size=2) * scale * 0.5)
    box = np.vstack([a.vertices, b.vertices])
    lo, hi = box.min(axis=0), box.max(axis=0)
    pts = np.vstack([lo + rng.uniform(size=(200, 2)) * (hi - lo), a.vertices, b.vertices, _crossings(a, b)])
    return a, b, pts[_inside(a, pts) & _inside(b, pts)]


def _crossings(a: Polygon, b: Polygon) -> np.ndarray:
    """Where the sides of ``a`` cross the sides of ``b``: the intersection's vertices that are no polygon's."""
    p, r = a.vertices[:, None, :], b.vertices[None, :, :]
    d, e = np.roll(a.vertices, -1, axis=0)[:, None, :] - p, np.roll(b.vertices, -1, axis=0)[None, :, :] - r
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((r - p)[..., 0] * e[..., 1] - (r - p)[..., 1] * e[..., 0]) / den
        u = ((r - p)[..., 0] * d[..., 1] - (r - p)[..., 1] * d[..., 0]) / den
    ok = (den != 0) & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
    return (p + t[..., None] * d)[ok].reshape(-1, 2)


def _keeps_the_intersection(within: Callable[[Polygon, Polygon], Polygon | None], regions: tuple[Polygon, Polygon, np.ndarray]) -> None:
    a, b, both = regions
    cut = within(a, b)
    assert all(_near(cut, p) for p in both), "a point of both regions was cut"


@settings(max_examples=examples(100), deadline=None)
@given(_two_regions())
def test_a_region_cut_by_a_neighbours_keeps_every_point_of_both(regions: tuple[Polygon, Polygon, np.ndarray]) -> None:
    """Polygon.within: every point both regions hold (the truth, where both sets held it) is kept."""
    _keeps_the_intersection(Polygon.within, regions)
    a, b, _ = regions
    cut = a.within(b)
    if cut is not None:  # and it is the intersection: nothing outside a (to the cuts' margins), nothing outside b
        assert all(_near(a, v, 10 * RTOL) for v in cut.vertices)  # beyond the slivers within leaves uncut
        assert _beyond_slivers(a, b, cut) <= 10 * RTOL * (1.0 + float(np.abs(b.vertices).max()))


def _beyond_slivers(a: Polygon, b: Polygon, cut: Polygon) -> float:
    """How far ``cut`` (a.within(b)) lies beyond a side of b (along its unit outward normal) past what Polygon.within
    leaves uncut by design: a side a lies beyond by at most SLIVER of a's width along its normal (found by the thorough
    profile at 10 000 examples: a vertex of a 1.5·10⁻⁷ beyond b, 4·10⁻⁵ of a's width, failed the plain 10⁻⁸ bound)."""
    w = b.vertices
    e = np.roll(w, -1, axis=0) - w
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)
    length = np.linalg.norm(n, axis=1)
    d = n[length > 0] / length[length > 0, None]
    mine = a.vertices @ d.T
    allowed = (w @ d.T).max(axis=0) + SLIVER * (mine.max(axis=0) - mine.min(axis=0))
    return float(((cut.vertices @ d.T) - allowed).max())


def test_the_region_test_fails_on_a_cut_narrowed_by_5_percent() -> None:
    @settings(
        max_examples=150, deadline=None, suppress_health_check=list(HealthCheck), database=None, phases=[Phase.generate]
    )  # a failure is the point: no shrinking
    @given(_two_regions())
    def narrowed(regions: tuple[Polygon, Polygon, np.ndarray]) -> None:
        _keeps_the_intersection(lambda a, b: _narrowed(a.within(b)), regions)

    with pytest.raises(AssertionError, match="a point of both regions was cut"):
        narrowed()


# ---------------------------------------------------------------- the moved region: the prior's ∩ the neighbours', through the step


@functools.cache
def _estimator() -> tuple[LocalEstimator, object]:
    sc = load_topology(ROOT / "topologies" / "paper6.toml", "saim", 5)
    return LocalEstimator.for_node(sc, 1), sc


@settings(max_examples=examples(60), deadline=None)
@given(_two_regions(), st.floats(0.0, 1.0), st.integers(0, 2**32 - 1))
def test_the_moved_region_holds_every_successor_of_a_point_of_the_prior_and_the_neighbours_sets(
    regions: tuple[Polygon, Polygon, np.ndarray], speed: float, seed: int
) -> None:
    """x_k in node 1's region and in its in-neighbour 2's published region: every x_k+1 = Ā x_k + B̄ u + D̄ w with
    |w| ≤ √W lies in the moved region, which names neighbour 2 where its region cut."""
    _, sc = _estimator()
    est = LocalEstimator.for_node(dataclasses.replace(sc, reading_scope="neighbours"), 1)  # (reading everyone, it would not cut by sets)
    assert est.neighbour_sets
    a, b, both = regions
    rng = np.random.default_rng(seed)
    alpha = sc.model.weights(sc.model.params.vx_min + speed * (sc.model.params.vx_max - sc.model.params.vx_min))
    u = float(rng.uniform(sc.steer_low, sc.steer_high))
    nb = NeighbourState(np.zeros(NA), np.eye(NA), 1.0, 1.0, 0.0, None, b)
    prev = NodeSet(np.r_[a.vertices.mean(axis=0), 0.0], np.eye(NA), 1.0, a)
    step = est._moved_region(prev, UpdateInput(alpha, u, 0.0, 1.0, {2: nb}))
    blend, moved, sets = step.blend, step.region, step.sets
    w = rng.uniform(-1.0, 1.0, (len(both), 1)) * math.sqrt(est.W)
    w[::5] = np.sign(w[::5]) * math.sqrt(est.W)  # the bound itself
    nxt = both @ blend.a.T + blend.b * u + w * blend.d
    assert all(_near(moved, p) for p in nxt)
    cut = a.within(b)
    assert sets <= {2} and (sets == {2}) == (cut is not None and cut is not a)


# ---------------------------------------------------------------- a bounded reading's slab


@st.composite
def _reading(draw: st.DrawFn) -> tuple[UpdateInput, int, np.ndarray]:
    """A bounded reading of sensor j (paper6 SAIM: saturating) and truths it allows: x⁺, f_j⁺ within its declared size F
    and within δ of an f_j in the fault interval j published at k, and a noise within its bound; the reading is one
    truth's measurement, the others are every truth with the same measured interval (the hypotheses the slab rests on)."""
    est, sc = _estimator()
    j = draw(st.sampled_from(sorted(est.bounded)))
    sensor, bound = est.bounded[j]
    assert bound.size is not None and bound.rate is not None
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    f_prev = np.sort(rng.uniform(-bound.size, bound.size, 2)) if draw(st.booleans()) else None  # j's published fault interval, or no state of j
    n = 400
    x = rng.normal(size=(n, 2)) * np.array([0.01, 0.05]) * draw(st.sampled_from([0.2, 1.0, 5.0]))
    lo_f, hi_f = (-bound.size, bound.size) if f_prev is None else (max(-bound.size, f_prev[0] - bound.rate), min(bound.size, f_prev[1] + bound.rate))
    f = rng.uniform(lo_f, hi_f, n)
    f[::4] = np.where(rng.uniform(size=len(f[::4])) < 0.5, lo_f, hi_f)  # at the bounds themselves
    gamma = float(rng.uniform(*sc.node(j).gamma_range))
    r = x @ sensor.C + sensor.Ds * f
    sat = np.sign(r) * np.minimum(abs(r), sensor.r_max)
    half = abs(sensor.Dv) * math.sqrt(sensor.R)
    y = float(gamma * sat[0] + rng.uniform(-half, half))
    iv = sensor.measured_interval(y, gamma)
    allowed = (iv[0] <= r) & (r <= iv[1])  # every truth this reading is the measurement of
    neigh = {} if f_prev is None else {j: NeighbourState(np.zeros(NA), np.eye(NA), 1.0, gamma, 0.0, None, None, (float(f_prev[0]), float(f_prev[1])))}
    inp = UpdateInput(sc.model.weights(sc.vx(0)), 0.03, 0.0, 1.0, neigh, {j: (y, gamma)})
    return inp, j, x[allowed]


def _measured(est: LocalEstimator, inp: UpdateInput) -> dict[int, Interval]:
    """The bounded readings' measurement intervals (what sector.step_ranges gives the step)."""
    return {j: measurement_interval(est.bounded[j][0], *r) for j, r in inp.readings.items() if j in est.bounded}


def _slab_keeps(slabs: Callable[[UpdateInput], dict], reading: tuple[UpdateInput, int, np.ndarray]) -> None:
    inp, j, xs = reading
    out = slabs(inp)
    if j not in out:
        return  # no slab: nothing cut
    iv = out[j]
    v = xs @ iv.a[:2]
    slack = RTOL * (1.0 + np.abs(v).max(initial=0.0))
    assert np.all((iv.lo - slack <= v) & (v <= iv.hi + slack)), "a truth the reading allows was cut"


@settings(max_examples=examples(150), deadline=None)
@given(_reading())
def test_a_bounded_readings_slab_keeps_every_state_its_hypotheses_allow(reading: tuple[UpdateInput, int, np.ndarray]) -> None:
    """C_j x⁺ of every truth whose measurement is the reading, with f_j⁺ within the declared size and rate of j's
    published fault interval, lies in the slab; it rests on that set where the rate narrowed it."""
    est, _ = _estimator()
    _slab_keeps(lambda inp: est._bounded_slabs(inp, _measured(est, inp))[0], reading)
    inp, j, _ = reading
    _, rate_from = est._bounded_slabs(inp, _measured(est, inp))
    assert rate_from <= {j} and (not rate_from or j in inp.neigh)


def test_the_slab_test_fails_on_a_slab_narrowed_by_5_percent() -> None:
    est, _ = _estimator()

    def narrowed(inp: UpdateInput) -> dict:
        out = {}
        for key, iv in est._bounded_slabs(inp, _measured(est, inp))[0].items():
            w = (
                NARROWED * (iv.hi - iv.lo) / 2
                if math.isfinite(iv.hi - iv.lo)
                else NARROWED * max(abs(iv.lo), abs(iv.hi))
                if math.isfinite(iv.lo) or math.isfinite(iv.hi)
                else 0.0
            )
            out[key] = Slab(iv.a, iv.lo + w, iv.hi - w)
        return out

    @settings(
        max_examples=150, deadline=None, suppress_health_check=list(HealthCheck), database=None, phases=[Phase.generate]
    )  # a failure is the point: no shrinking
    @given(_reading())
    def test(reading: tuple[UpdateInput, int, np.ndarray]) -> None:
        _slab_keeps(narrowed, reading)

    with pytest.raises(AssertionError, match="a truth the reading allows was cut"):
        test()


def test_a_step_rests_on_the_neighbours_whose_sets_cut_it() -> None:
    """What the node lists (StepResult.rests_on): the neighbours' sets of both sets, the published one's and the continued one's."""
    pub = StepSet(np.zeros(3), np.eye(3), 1.0, set_keys=frozenset({2}))
    res = StepResult(StepSet(np.zeros(3), np.eye(3), 1.0, set_keys=frozenset({6})), pub, StepFigures("ok", 0.0, "solved"))
    assert res.rests_on.sets == {2, 6} and dataclasses.replace(res, published=res.continued).rests_on.sets == {6}
