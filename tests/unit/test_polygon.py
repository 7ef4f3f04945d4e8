"""netsetest/polygon.py: every operation keeps every point it held (the region's guarantee rests on it),
checked point by point on random polygons (Hypothesis) as a step applies them (the move, whose margin covers
the cuts after it, then the cuts), and the cut and the reduction give what they say."""

from __future__ import annotations

import numpy as np
import pytest
from fuzzing import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.polygon import MARGIN, MAX_VERTICES, Polygon, _box_inside, cut_all

pytestmark = pytest.mark.usefixtures("polygon_backend")  # both backends: compiled (numba) and plain Python

finite = st.floats(-1.0, 1.0, allow_nan=False)


@st.composite
def _cloud(draw: st.DrawFn) -> tuple[Polygon, np.ndarray]:
    """A random convex polygon (the hull of random points, grown by a random segment so that it is never flat)
    and points inside it (convex combinations of its vertices)."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(draw(st.integers(3, 40)), 2)) * draw(st.sampled_from([1e-3, 1.0, 50.0]))
    poly = Polygon.box(pts.min(axis=0), pts.max(axis=0))
    for p in pts:
        poly = poly.plus_segments([0.01 * p])
    w = rng.dirichlet(np.ones(len(poly.vertices)), size=60)
    inside = np.vstack([w @ poly.vertices, poly.vertices])
    return poly, inside


@settings(max_examples=examples(150), deadline=None)
@given(_cloud(), finite, finite, finite, finite, finite, finite)
def test_affine_and_segment_keep_every_point(cloud: tuple[Polygon, np.ndarray], a: float, b: float, c: float, d: float, gx: float, gy: float) -> None:
    poly, pts = cloud
    A = np.array([[1.0 + a, b], [c, 0.5 + d]])
    if abs(np.linalg.det(A)) < 1e-3:
        A = A + np.eye(2)
    t = np.array([gx, gy])
    moved = poly.moved(A, t, [np.array([gy, gx])])
    rng = np.random.default_rng(0)
    s = rng.uniform(-1.0, 1.0, size=(len(pts), 1))
    for x in pts @ A.T + t + s * np.array([gy, gx]):
        assert moved.contains(x)


@settings(max_examples=examples(150), deadline=None)
@given(_cloud(), finite, finite, st.floats(0.05, 0.95), st.floats(0.05, 0.95))
def test_the_cut_keeps_the_points_in_the_slab_and_drops_the_rest(cloud: tuple[Polygon, np.ndarray], cx: float, cy: float, q1: float, q2: float) -> None:
    poly, pts = cloud
    c = np.array([cx, cy]) if abs(cx) + abs(cy) > 1e-3 else np.array([1.0, 0.0])
    vals = pts @ c
    lo, hi = np.quantile(vals, sorted((q1, q2)))
    cut = poly.moved(np.eye(2), np.zeros(2), []).cut(c, lo, hi)  # as in a step: the move's margin covers the cut's rounding
    inside = pts[(vals >= lo) & (vals <= hi)]
    if len(inside):
        assert cut is not None
        for x in inside:
            assert cut.contains(x)
    if cut is not None:
        v_lo, v_hi = cut.interval(c)
        pad = 1e-6 * (1.0 + np.abs(pts @ c).max())
        assert v_lo >= lo - pad and v_hi <= hi + pad  # nothing of it outside the slab but the margin


@settings(max_examples=examples(150), deadline=None)
@given(
    _cloud(),
    st.lists(
        st.tuples(finite, finite, st.integers(-2, 2), st.integers(-2, 2), st.sampled_from([0.0, 0.0, 0.2]), st.sampled_from([0.0, 0.0, 0.2])),
        min_size=1,
        max_size=8,
    ),
)
def test_the_slabs_skipped_by_their_box_are_the_cuts_that_keep_the_polygon(cloud: tuple[Polygon, np.ndarray], planes: list) -> None:
    """cut_all skips a slab the region's box lies inside (issue 45): only where Polygon.cut would keep the polygon
    itself, so cut_all's polygon is the slabs' cuts in turn, float for float.  Slabs at the vertices' own extremes
    along c, each side moved by a few ulps either way, so that the corners' rounding decides, or a side a fifth inward."""
    poly = cloud[0]
    slabs = []
    for cx, cy, dlo, dhi, in_lo, in_hi in planes:
        s = [cx * x + cy * y for x, y in poly.points]
        lo, hi = min(s), max(s)
        lo, hi = lo + in_lo * (hi - lo), hi - in_hi * (hi - lo)
        slabs.append((cx, cy, lo + dlo * np.spacing(lo), hi + dhi * np.spacing(hi)))
    out: Polygon | None = poly
    for cx, cy, lo, hi in slabs:
        pts = out.points
        box = (min(p[0] for p in pts), min(p[1] for p in pts), max(p[0] for p in pts), max(p[1] for p in pts))
        cut = out.cut((cx, cy), lo, hi)
        if _box_inside(box, cx, cy, lo, hi):
            assert cut is out
        out = cut
        if out is None:
            break
    got = cut_all(poly, slabs, max_vertices=10**6)
    if out is None or len(out) < 3:
        assert got is None
    else:
        assert got is not None and got.polygon.points == out.reduced(10**6).points


@settings(max_examples=examples(100), deadline=None)
@given(_cloud(), st.integers(4, MAX_VERTICES))
def test_the_reduction_keeps_every_point_within_its_vertex_count(cloud: tuple[Polygon, np.ndarray], limit: int) -> None:
    poly, pts = cloud
    grown = poly
    for g in ([1.0, 0.3], [-0.2, 1.0], [0.7, -0.7], [0.1, 0.05]):
        grown = grown.plus_segments([np.array(g) * 0.01])
    small = grown.reduced(limit)
    assert len(small.vertices) <= max(limit, 4)
    for x in pts:
        assert small.contains(x)


def test_a_cut_that_misses_the_polygon_is_empty() -> None:
    square = Polygon.box(np.zeros(2), np.ones(2))
    assert square.cut(np.array([1.0, 0.0]), 2.0, 3.0) is None
    cut = square.cut(np.array([0.0, 1.0]), 0.25, 0.5)
    assert cut is not None
    pad = MARGIN * 2.0  # outward by the margin, relative to the extent (1)
    assert cut.interval(np.array([0.0, 1.0])) == (0.25 - pad, 0.5 + pad) and cut.interval(np.array([1.0, 0.0])) == (0.0, 1.0)


def test_a_side_a_rounding_made_reflex_does_not_shift_the_sum() -> None:
    """Issue 32's reproduction: a vertex 1 ulp above the bottom side made that side's second half point at an angle
    just below 2π; sorted by the rounded angle it went last and the walk lost a segment's length of the sum."""
    v = np.array([[0.0, 0.3], [1.0, 0.1 + 0.2], [2.0, 0.3], [2.0, 1.0], [0.0, 1.0]])
    total = Polygon(v).plus_segments([np.array([0.5, 0.0])])
    assert total.interval(np.array([1.0, 0.0])) == (-0.5, 2.5)
    assert total.interval(np.array([0.0, 1.0])) == (0.3, 1.0)
    for x in ([2.5, 1.0], [-0.5, 0.3], [2.5, 0.3], [-0.5, 1.0]):
        assert total.contains(np.array(x))


def test_the_direction_order_falls_back_to_the_exact_one_where_a_rounded_angle_ties() -> None:
    """b is a hair clockwise of a, below arctan2's resolution: the rounded angles tie, the float sort keeps the
    input order (a first), the exact check of the neighbours rejects it and the exact sort puts b first;
    directions the rounded angle does order stay as the float sort put them."""
    from netsetest.polygon import _ordered

    a, b = (-0.7364540870016669, -0.16290994799305278), (-0.7364540870016669, -0.16290994799305272)
    assert np.arctan2(a[1], a[0]) == np.arctan2(b[1], b[0])
    assert _ordered([a, b]) == ([1, 0], [-1])
    d = [(0.0, -1.0), (1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (1.0, -1e-17)]
    assert _ordered(d)[0] == [1, 3, 2, 0, 4]


def test_the_vertices_stay_plain_floats_whatever_numpy_scalars_come_in() -> None:
    """Every operation builds its vertices from plain floats (a numpy scalar bound or matrix would otherwise make them
    numpy's: slower arithmetic, and a published region that decode refuses as not numbers)."""
    poly = Polygon.box(np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
    A, t = np.array([[0.9, 0.1], [-0.2, 0.8]]), np.array([0.01, -0.02])
    out = poly.moved(A, t, [np.array([0.1, 0.05])]).reduced(6).cut(np.array([1.0, 0.5]), np.float64(-0.5), np.float64(0.25))
    assert out is not None and len(out) >= 3
    assert all(type(x) is float for x in out.flat())
    assert Polygon.from_flat(out.flat()) == out and Polygon(out.vertices) == out


@settings(max_examples=examples(60), deadline=None)
@given(_cloud())
def test_the_bounds_are_the_interval_hull(cloud: tuple[Polygon, np.ndarray]) -> None:
    """Each coordinate's bounds are its lowest and highest vertex, exactly: every vertex lies within them, each is
    attained, and each is the support along its axis (what the published set's bounds are cut by, proven.py and sets.py)."""
    poly, _ = cloud
    lo, hi = poly.bounds()
    v = poly.vertices
    assert lo.shape == hi.shape == (2,)
    assert np.all(v >= lo) and np.all(v <= hi) and np.all(np.any(v == lo, axis=0)) and np.all(np.any(v == hi, axis=0))
    for axis in range(2):
        e = np.eye(2)[axis]
        assert poly.interval(e) == (lo[axis], hi[axis])
