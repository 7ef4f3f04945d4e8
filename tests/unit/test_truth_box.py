"""A recorded drive's truth is a box (docs/your-log.md): ProvenSet.relation calls a box inside only when the set holds
all of it, disjoint only when no point of it is in the set (never a false miss), and the judge counts an overlap as
undecided, never contained.  Checked against points drawn in the box, over random sets (Hypothesis)."""

from __future__ import annotations

import os

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.proven import ProvenSet, box_min_E

EXAMPLES = int(os.environ.get("NETSETEST_FUZZ_EXAMPLES", "30"))


@st.composite
def set_and_box(draw: st.DrawFn) -> tuple[ProvenSet, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    a = rng.normal(size=(3, 3))
    P = a @ a.T + 0.05 * np.eye(3)
    xhat = rng.normal(size=3)
    fault = None
    if draw(st.booleans()):
        f0 = float(xhat[2] + rng.normal())
        fault = [f0 - abs(rng.normal()), f0]
    region = None
    if draw(st.booleans()):  # a square region of x around a point near the centre
        c, h = xhat[:2] + 0.5 * rng.normal(size=2), 0.2 + abs(rng.normal())
        region = [c[0] - h, c[1] - h, c[0] + h, c[1] - h, c[0] + h, c[1] + h, c[0] - h, c[1] + h]
    s = ProvenSet(xhat=xhat.tolist(), P=P.ravel().tolist(), rho=1.0, fault=fault, region=region)
    centre = xhat + rng.normal(size=3) * draw(st.sampled_from([0.3, 1.0, 3.0]))
    half = np.abs(rng.normal(size=3)) * draw(st.sampled_from([0.0, 0.05, 0.5]))
    return s, centre - half, centre + half


@settings(max_examples=EXAMPLES, deadline=None, derandomize=True)
@given(set_and_box())
def test_inside_and_disjoint_are_proven(case: tuple[ProvenSet, np.ndarray, np.ndarray]) -> None:
    s, lo, hi = case
    rel = s.relation(lo, hi)
    rng = np.random.default_rng(0)
    points = lo + (hi - lo) * rng.random((200, 3))
    inside = [s.contains(p) for p in points]
    if rel == "inside":
        assert all(inside)
    elif rel == "disjoint":
        assert not any(inside)
    if np.array_equal(lo, hi):  # a point truth (a reference of accuracy 0): exactly the model's run's rule
        assert rel == ("inside" if s.contains(lo) else "disjoint")


@settings(max_examples=EXAMPLES, deadline=None, derandomize=True)
@given(st.integers(0, 2**32 - 1))
def test_the_box_minimum_of_e_is_the_least_over_the_box(seed: int) -> None:
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(3, 3))
    P = a @ a.T + 0.05 * np.eye(3)
    c = rng.normal(size=3)
    lo = rng.normal(size=3) * 2
    hi = lo + np.abs(rng.normal(size=3))
    m = box_min_E(c, P, lo, hi)
    Q = np.linalg.inv(P)
    pts = lo + (hi - lo) * rng.random((2000, 3))
    sampled = np.einsum("ij,jk,ik->i", pts - c, Q, pts - c).min()
    assert m <= sampled * (1 + 1e-12) + 1e-12  # no point of the box lies below it
    pts = np.clip(c + rng.normal(size=(2000, 3)) * 1e-3, lo, hi)
    assert m <= np.einsum("ij,jk,ik->i", pts - c, Q, pts - c).min() * (1 + 1e-12) + 1e-12
