"""The plain-float polygon code (issue 28's speed-up, issue 45's plain floats end to end) keeps every set:
on adversarial polygons (tests/unit/test_polygon_exact.py's: near-collinear, near-axis, flat, slivers, rotated, at 10⁻¹² to 10¹², here also clockwise and with repeated
vertices) and segments (axis-aligned, parallel to a side: directions that tie exactly), every operation returns
what the numpy code before it returned (tests/polygon_reference.py), to the roundings of the operation
(polygon_reference.bound: a few ulps of the coordinates' size, far below any margin), in both directions: the fast
set holds the numpy one shrunk by that bound (soundness) and is no larger than it grown by it.  Not bit for bit:
numpy's products go through OpenBLAS, whose kernel (picked by the CPU, ``OPENBLAS_CORETYPE``) rounds a 2-vector
product with a fused multiply-add or without, so the ellipse cut's slab ends differ in the last bits on a CPU with
AVX-512 (the SkylakeX kernel) and not on one with AVX2 (Haswell).  Whole runs:
tests/inmemory/test_polygon_runs_same.py.  The long run: ``NETSETEST_FUZZ_EXAMPLES=10000 pytest -n 0 -q --timeout 0
tests/unit/test_polygon_same.py``."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import polygon_reference as ref
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_polygon_exact import FUZZ, car_like, matrices, polygons, segment_lists, slabs

from netsetest import polygon
from netsetest.polygon import Polygon

pytestmark = [
    pytest.mark.blas,  # (.ci/run runs it under every OpenBLAS kernel the CPU runs)
    pytest.mark.usefixtures("polygon_backend"),  # both backends: compiled (numba) and plain Python
]


def _check(name: str, v: np.ndarray, got: Polygon | None, want: ref.Polygon | None, *args: Any) -> None:
    why = ref.differs(got, want, ref.bound(name, v, *args))
    assert why is None, f"{name}: {why}"


@st.composite
def any_polygons(draw: st.DrawFn) -> np.ndarray:
    """polygons(), sometimes clockwise, sometimes with a vertex repeated (a zero edge)."""
    v = draw(polygons())
    if draw(st.booleans()):
        v = v[::-1].copy()
    if len(v) and draw(st.booleans()):
        i = draw(st.integers(0, len(v) - 1))
        v = np.insert(v, i, v[i], axis=0)
    return v


@FUZZ
@given(st.data())
def test_the_sum_and_the_move_are_the_numpy_codes(data: st.DataObject) -> None:
    v = data.draw(any_polygons())
    segments = data.draw(segment_lists(v))
    _check("plus_segments", v, Polygon(v).plus_segments(segments), ref.Polygon(v).plus_segments(segments), segments)
    A = data.draw(st.one_of(matrices, car_like))
    t = np.array(data.draw(st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)))) * float(np.abs(v).max())
    _check("moved", v, Polygon(v).moved(A, t, segments), ref.Polygon(v).moved(A, t, segments), A, t, segments)


@FUZZ
@given(st.data())
def test_the_cut_is_the_numpy_codes(data: st.DataObject) -> None:
    v = data.draw(any_polygons())
    c, lo, hi = data.draw(slabs(v))
    _check("cut", v, Polygon(v).cut(c, lo, hi), ref.Polygon(v).cut(c, lo, hi))


@FUZZ
@given(st.data())
def test_the_reduction_is_the_numpy_codes(data: st.DataObject) -> None:
    v = data.draw(any_polygons())
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    grown = ref.Polygon(v).plus_segments(list(rng.normal(size=(data.draw(st.integers(0, 12)), 2)) * float(np.abs(v).max())))
    limit = data.draw(st.integers(3, 24))
    _check("reduced", grown.vertices, Polygon(grown.vertices).reduced(limit), grown.reduced(limit))


@FUZZ
@given(st.data())
def test_the_ellipse_cut_is_the_numpy_codes(data: st.DataObject) -> None:
    v = data.draw(any_polygons())
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    size = float(np.abs(v).max())
    root = rng.normal(size=(3, 3)) * size * 10.0 ** data.draw(st.integers(-2, 1))
    P = root @ root.T + (np.diag([0.0, 0.0, 1.0]) if data.draw(st.booleans()) else 0.0)  # (sometimes a flat x-projection)
    xhat = rng.normal(size=3) * size
    coordinates = data.draw(st.booleans())
    got, want = Polygon(v).ellipse_cut(xhat, P, 1.0, coordinates), ref.ellipse_cut(ref.Polygon(v), xhat, P, 1.0, coordinates)
    _check("ellipse_cut", v, got, want, xhat, P, 1.0, coordinates)


@FUZZ
@given(st.data())
def test_the_ellipse_cut_at_the_edge_of_its_shortcut_is_the_numpy_codes(data: st.DataObject) -> None:
    """A region whose farthest vertex is a hair (10⁻¹² … 10⁻²) inside or outside the ellipse, and ellipses up to
    and beyond the shortcut's condition bound: where ``_well_inside`` returns the region at once, the four slab
    cuts return it too (the numpy code's set)."""
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    cond = 10.0 ** data.draw(st.floats(0.0, 10.0))
    angle = data.draw(st.floats(0.0, math.pi))
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    scale = 10.0 ** data.draw(st.integers(-6, 3))
    pxx = scale * rot @ np.diag([1.0, 1.0 / cond]) @ rot.T
    P = np.eye(3)
    P[:2, :2] = pxx
    xhat = np.array([*rng.normal(size=2) * 10.0 ** data.draw(st.integers(-3, 3)), 0.0])
    theta = rng.uniform(0.0, 2.0 * math.pi, size=data.draw(st.integers(0, 24)))
    points = [np.stack([np.cos(theta), np.sin(theta)], axis=1) @ np.linalg.cholesky(pxx).T]  # on the ellipse, ρ = 1
    for d in [*np.eye(2), *rot.T]:  # where the slabs touch it: the points the cuts would cut first
        touch = pxx @ d / math.sqrt(float(d @ pxx @ d))
        points.append(np.stack([touch, -touch]))
    edge = 1.0 + data.draw(st.sampled_from([-1.0, 1.0])) * 10.0 ** data.draw(st.floats(-12.0, -2.0))
    v = np.asarray(Polygon(xhat[:2] + np.concatenate(points) * edge).plus_segments([]).vertices)  # (counter-clockwise)
    rho = data.draw(st.sampled_from([1.0, 1.0 - 1e-6, 1.0 + 1e-6]))
    _check("ellipse_cut", v, Polygon(v).ellipse_cut(xhat, P, rho), ref.ellipse_cut(ref.Polygon(v), xhat, P, rho), xhat, P, rho)


def test_the_ellipse_cut_returns_a_region_well_inside_at_once() -> None:
    """The shortcut is taken (no eigen decomposition) where the region is well inside a well-conditioned ellipse,
    and not where a vertex is outside."""
    P = np.diag([2.0, 0.5, 1.0])
    xhat = np.array([0.3, -0.1, 0.0])
    inside = Polygon(np.array([[0.3, -0.2], [0.5, -0.1], [0.3, 0.0], [0.1, -0.1]]))
    outside = Polygon(inside.vertices * 10.0)
    assert polygon._well_inside(inside.points, 0.3, -0.1, 2.0, 0.0, 0.5, 1.0)
    assert inside.ellipse_cut(xhat, P, 1.0) is inside
    assert not polygon._well_inside(outside.points, 0.3, -0.1, 2.0, 0.0, 0.5, 1.0)
    assert not polygon._well_inside(inside.points, 0.3, -0.1, 1.0, 0.0, 1e-12, 1.0)  # beyond the condition bound: the full cut
