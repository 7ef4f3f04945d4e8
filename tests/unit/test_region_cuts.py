"""The region's cuts in the SDP step (estimator/sdp.py): the seed from an ellipsoid and the cut by an ellipsoid's slabs
keep every point of their input that the ellipsoid holds (Hypothesis, point by point), so the published set
ellipsoid ∩ region never loses a point of the ellipsoid that the region held."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.estimator.cuts import NodeSet, ellipse_cut, seed
from netsetest.polygon import Polygon


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


@settings(max_examples=150, deadline=None)
@given(_ellipsoid())
def test_the_seed_holds_every_point_of_the_ellipsoid(e: tuple[np.ndarray, np.ndarray, float, np.ndarray]) -> None:
    xhat, P, rho, pts = e
    region = seed(NodeSet(xhat, P, rho))
    assert all(region.contains(p[:2]) for p in pts)


@settings(max_examples=150, deadline=None)
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
    cut = ellipse_cut(region, xhat, P, rho)
    if cut is None:
        assert not held
        return
    assert all(cut.contains(p[:2]) for p in held)
    v = cut.vertices
    assert np.all(v >= lo - 1e-6 * (1 + np.abs(lo))) and np.all(v <= hi + 1e-6 * (1 + np.abs(hi)))
