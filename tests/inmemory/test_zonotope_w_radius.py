"""The zonotopic W-radius estimator ([Ifqir-zonotope]) offline against `netsetest exact`, and the set types."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from run_helpers import recorded_run

from netsetest.analysis.exact import COORDINATES, ExactBounds, exact_bounds, step_data
from netsetest.config.schema import Scenario
from netsetest.estimator.zonotope_w_radius import ZonotopeEstimator, reduce_order
from netsetest.records.record import Record
from netsetest.sets import Box, Ellipsoid, SlicedEllipsoid, Slab, SumSet, Zonotope

STEPS = 30
EXACT_TOL = 1e-7  # both are Clarabel answers at 1e-10 tolerances; the zonotope adds only float sums
CONTAIN_TOL = 1e-8


def _run(case: str, signals: str, seed: int, tmp: str) -> tuple[Scenario, Record]:
    return recorded_run(case, signals, seed, STEPS, tmp)


@pytest.fixture(scope="module")
def tmp(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(tmp_path_factory.mktemp("zono"))


def _zonotope_bounds(sc: Scenario, rec: Record, node: int, order: int | None, mode: str, gain: str = "hull") -> np.ndarray:
    """(K, 3, 2) published bounds of β, r, f of one node's zonotopic estimator over the record's data."""
    est = ZonotopeEstimator(sc, node, order=order, fault_bounds=mode, gain=gain)
    out = []
    prev = None
    for d in step_data(rec):
        s = est.advance(d.y[node], d.gamma[node]) if prev is None else est.advance(d.y[node], d.gamma[node], prev.u, prev.vx)
        lo, hi = s.bounds()
        out.append(np.stack([lo, hi], axis=1))
        prev = d
    return np.array(out)


def _exact_array(ex: ExactBounds, node: int) -> np.ndarray:
    return np.stack([ex.interval(c, node) for c in COORDINATES], axis=1)


@pytest.mark.parametrize(("signals", "seed", "node"), [("paper", 0, 1), ("worst", 1, 4), ("worst", 2, 6)])
def test_without_reduction_equals_the_exact_local_limit(signals: str, seed: int, node: int, tmp: str) -> None:
    """NSNIM, free faults: the descriptor construction is exact, so the zonotope is the exact local set.  (Without the
    bounded readings: with them, the bundled default, every sensor's declared bound is relied on (issue 44), and a
    zonotope cut by the bound's slabs is an outer bound of the cut set, no longer the exact one.)"""
    sc, rec = _run("nsnim", signals, seed, tmp)
    sc = dataclasses.replace(sc, bounded_readings=False)
    assert sc.fault_bounded("used") == ()
    z = _zonotope_bounds(sc, rec, node, None, "used")
    ex = _exact_array(exact_bounds(sc, rec, "used", nodes=[node]), node)
    np.testing.assert_allclose(z, ex, atol=EXACT_TOL, rtol=0)


@pytest.mark.parametrize(
    ("case", "signals", "seed", "order"), [("nsnim", "worst", 1, 6), ("nsnim", "paper", 0, 3), ("saim", "worst", 1, None), ("saim", "paper", 0, 8)]
)
def test_never_narrower_than_exact_and_contains_the_truth(case: str, signals: str, seed: int, order: int | None, tmp: str) -> None:
    sc, rec = _run(case, signals, seed, tmp)
    for node in (2, 5):
        z = _zonotope_bounds(sc, rec, node, order, "used")
        ex = _exact_array(exact_bounds(sc, rec, "used", nodes=[node]), node)
        assert np.all(z[:, :, 0] <= ex[:, :, 0] + CONTAIN_TOL) and np.all(z[:, :, 1] >= ex[:, :, 1] - CONTAIN_TOL)
        for t in rec.truth:
            truth = np.r_[t["x"], t["faults"][node]]
            assert np.all(z[t["step"], :, 0] <= truth + CONTAIN_TOL) and np.all(truth <= z[t["step"], :, 1] + CONTAIN_TOL)


def test_reduction_keeps_q_generators_and_loosens(tmp: str) -> None:
    sc, rec = _run("nsnim", "worst", 1, tmp)
    full = _zonotope_bounds(sc, rec, 3, None, "used")
    reduced = _zonotope_bounds(sc, rec, 3, 3, "used")
    w_full, w_red = np.diff(full, axis=2)[..., 0], np.diff(reduced, axis=2)[..., 0]
    assert np.all(w_red >= w_full - CONTAIN_TOL)
    assert w_red[10:].mean() > 1.01 * w_full[10:].mean()
    G = np.random.default_rng(0).normal(size=(3, 12))
    R = reduce_order(G, 5, np.eye(3))
    assert R.shape == (3, 5)
    lo, hi = Zonotope(np.zeros(3), R).bounds()
    lo0, hi0 = Zonotope(np.zeros(3), G).bounds()
    assert np.all(lo <= lo0 + 1e-12) and np.all(hi >= hi0 - 1e-12)
    with pytest.raises(ValueError, match="at least"):
        reduce_order(G, 2, np.eye(3))


def test_saturated_node_without_fault_bounds_is_refused(tmp: str) -> None:
    sc, rec = _run("saim", "paper", 0, tmp)
    ex = exact_bounds(sc, rec, "none", nodes=[6])
    assert not np.isfinite(ex.fault[6]).all(), "this run never reaches the saturation limit"
    with pytest.raises(ValueError, match="declared fault bound"):
        _zonotope_bounds(sc, rec, 6, None, "none")


# ---------------------------------------------------------------- set types


def test_set_types_bounds_and_membership() -> None:
    box = Box(np.array([0.0, -1.0]), np.array([1.0, 1.0]))
    assert box.contains(np.array([1.0, -1.0])) and not box.contains(np.array([1.01, 0.0]))
    el = Ellipsoid(np.array([1.0, 0.0]), np.diag([4.0, 1.0]), 1.0)
    lo, hi = el.bounds()
    np.testing.assert_allclose(lo, [-1.0, -1.0]) and np.testing.assert_allclose(hi, [3.0, 1.0])
    assert el.contains(np.array([3.0, 0.0])) and not el.contains(np.array([2.5, 0.8]))
    z = Zonotope(np.zeros(2), np.array([[1.0, 1.0], [0.0, 1.0]]))
    np.testing.assert_allclose(z.bounds()[1], [2.0, 1.0])
    assert z.contains(np.array([2.0, 1.0])) and z.contains(np.array([0.0, 1.0]))
    assert not z.contains(np.array([2.0, 0.0])) and not z.contains(np.array([-0.5, 1.0]))


def test_sum_set_support_and_membership_agree() -> None:
    """The support of ⟨c, G⟩ ⊕ M·(ellipsoid ∩ slab) is attained by a member and exceeded by none."""
    rng = np.random.default_rng(3)
    sliced = SlicedEllipsoid(Ellipsoid(np.zeros(3), np.eye(3) * 0.3, 1.0), (Slab(np.array([0.2, 0.1, 0.5]), -0.05, 0.1),))
    s = SumSet(Zonotope(np.array([0.1, 0.0, -0.2]), rng.normal(size=(3, 4)) * 0.1), rng.normal(size=(3, 3)), sliced)
    lo, hi = s.bounds()
    for d in rng.normal(size=(5, 3)):
        h = s.support(d)
        _, e = s._ellipsoid_part(s.M.T @ d)
        b = np.sign(d @ s.zonotope.generators)
        point = s.zonotope.center + s.zonotope.generators @ b + s.M @ e
        assert d @ point == pytest.approx(h, abs=1e-8)
        assert s.contains(point)
        assert not s.contains(point + 1e-3 * d / np.linalg.norm(d))
    assert np.all(lo < hi)


def test_frobenius_gain_is_sound_and_the_hull_gain_tighter(tmp: str) -> None:
    """001's closed-form (Frobenius W-radius) gain is also guaranteed, but much looser on saturated steps."""
    sc, rec = _run("saim", "worst", 1, tmp)
    node = 3
    ex = _exact_array(exact_bounds(sc, rec, "used", nodes=[node]), node)
    frob = _zonotope_bounds(sc, rec, node, None, "used", "frobenius")
    hull = _zonotope_bounds(sc, rec, node, None, "used", "hull")
    for z in (frob, hull):
        assert np.all(z[:, :, 0] <= ex[:, :, 0] + CONTAIN_TOL) and np.all(z[:, :, 1] >= ex[:, :, 1] - CONTAIN_TOL)
    w_frob, w_hull = np.diff(frob, axis=2)[10:, 2, 0].mean(), np.diff(hull, axis=2)[10:, 2, 0].mean()
    assert w_hull < w_frob
