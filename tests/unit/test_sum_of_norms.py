"""The closed form of the NSNIM step (netsetest/estimator/sum_of_norms.py): min_L Σ_g ‖M_g − L b_gᵀ‖_F + c‖L‖
by Newton's method, checked against cvxpy on random instances, and its exact zero-gain case."""

from __future__ import annotations

import numpy as np
import pytest

from netsetest.estimator.sum_of_norms import SumOfNorms


def _instance(rng: np.random.Generator, c: float, nsnim_like: bool = True) -> SumOfNorms:
    """Groups of 3, 2, 1 and 1 columns.  ``nsnim_like``: the single-column groups have b = 0 (as w and v⁺ in
    NSNIM: constant terms), so no term can vanish at the minimum; else every b is random, and a single-column
    group can vanish there (a kink of F)."""
    sizes = [3, 2, 1, 1]
    onehot = np.zeros((sum(sizes), len(sizes)))
    onehot[np.arange(sum(sizes)), np.repeat(np.arange(len(sizes)), sizes)] = 1.0
    b = rng.normal(size=sum(sizes))
    if nsnim_like:
        b[-2:] = 0.0
    return SumOfNorms(rng.normal(size=(3, sum(sizes))), b, onehot, c)


def _by_cvxpy(p: SumOfNorms) -> float:
    cp = pytest.importorskip("cvxpy")
    L = cp.Variable(3)
    groups = [np.flatnonzero(p.onehot[:, g]) for g in range(p.onehot.shape[1])]
    terms = [cp.norm(p.M[:, cols] - cp.reshape(L, (3, 1), order="F") @ p.b[cols][None, :], "fro") for cols in groups]
    prob = cp.Problem(cp.Minimize(sum(terms) + p.c * cp.norm(L)))
    prob.solve(solver="CLARABEL")
    return float(prob.value)


@pytest.mark.parametrize("seed", range(8))
def test_newton_reaches_the_minimum(seed: int) -> None:
    rng = np.random.default_rng(seed)
    p = _instance(rng, c=0.05 * seed)
    found = p.minimise()
    assert found is not None
    L, a, ln, iterations = found
    assert p.value(L) <= _by_cvxpy(p) * (1 + 1e-7)
    assert np.allclose(a.sum() + p.c * ln, p.value(L), rtol=1e-12)
    for _ in range(50):  # and no nearby point is lower (convexity: a local minimum is global)
        assert p.value(L) <= p.value(L + 1e-4 * rng.normal(size=3)) * (1 + 1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_newton_gives_the_minimum_or_nothing(seed: int) -> None:
    """Where a term can vanish at the minimum (F not smooth there) Newton may not converge: it then says so
    (None, and the caller solves with Clarabel), never returns a worse point as the minimum."""
    rng = np.random.default_rng(seed)
    p = _instance(rng, c=0.05 * seed, nsnim_like=False)
    found = p.minimise()
    assert found is None or p.value(found[0]) <= _by_cvxpy(p) * (1 + 1e-7)


def test_zero_gain_is_exact_when_the_noise_costs_more() -> None:
    """When ‖Σ_g M_g b_g / ‖M_g‖‖ ≤ c the minimum is L = 0 exactly (the subgradient of c‖L‖ cancels the
    rest), found without iterating; just above that threshold it is not."""
    rng = np.random.default_rng(3)
    p = _instance(rng, c=0.0)
    r0 = np.sqrt((p.M * p.M).sum(axis=0) @ p.onehot)
    threshold = float(np.linalg.norm(((p.M * p.b) @ p.onehot) @ (1.0 / r0)))
    at = SumOfNorms(p.M, p.b, p.onehot, threshold * (1 + 1e-9))
    L, _, ln, iterations = at.minimise()
    assert ln == 0.0 and iterations == 0 and not np.any(L)
    assert at.value(L) <= _by_cvxpy(at) * (1 + 1e-7)
    below = SumOfNorms(p.M, p.b, p.onehot, threshold * 0.9)
    found = below.minimise()
    assert found is not None and found[2] > 0.0 and below.value(found[0]) < below.value(np.zeros(3))


def test_a_minimum_where_a_term_vanishes_is_found_and_is_the_minimum() -> None:
    """The readings' update of paper6_max_faulty (captured): the minimum lies where the one-column group of
    slot 3 vanishes (L = M₃ / b₃), where Newton stalls; the subgradient test finds it, without iterating."""
    M = np.array([[0.00846, -0.00591, 0.0, 0.00126, 0.0], [0.02938, 0.04838, 0.0, 0.03164, 0.0], [-0.04109, -0.06766, 0.0, -0.04424, -0.14388]])
    b = np.array([0.02938, 0.04838, 0.0, 0.03164, 0.0])
    onehot = np.array([[1.0, 0, 0], [1, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    p = SumOfNorms(M, b, onehot, 0.019272747222410277)
    L, a, ln, iterations = p.minimise()
    assert iterations == 0 and np.allclose(L, M[:, 3] / b[3], rtol=1e-12)
    assert a[1] <= 1e-12 * np.abs(M).max()  # the vanished term's share of the multipliers: negligible, positive
    assert p.value(L) <= _by_cvxpy(p) * (1 + 1e-7)
    rng = np.random.default_rng(0)
    for _ in range(200):
        assert p.value(L) <= p.value(L + 1e-4 * rng.normal(size=3)) * (1 + 1e-12)


@pytest.mark.parametrize("seed", range(16))
def test_with_vanishing_terms_the_answer_is_the_minimum_or_nothing(seed: int) -> None:
    """Random instances whose one-column groups can vanish at the minimum: every answer given is the
    minimum (cvxpy), the kink ones included."""
    rng = np.random.default_rng(100 + seed)
    p = _instance(rng, c=0.02 * seed, nsnim_like=False)
    found = p.minimise()
    assert found is None or p.value(found[0]) <= _by_cvxpy(p) * (1 + 1e-7)


def test_a_warm_start_next_to_a_kink_still_reaches_the_minimum() -> None:
    """A readings' update of paper6_max_faulty (NSNIM, node 1): the last step's gain, the warm start, sits next
    to the kink of the single-column group, and the minimum lies close to it but off it.  Newton from there
    heads onto the kink and its steps shrink to nothing; the cold start reaches the minimum (before, the
    step fell back to Clarabel)."""
    M = np.array(
        [
            [8.9147991040134603e-03, -5.7265204537430333e-03, 0.0, 1.2711602694829495e-03, 0.0],
            [3.1584770126813239e-02, 4.6848582337754387e-02, 0.0, 3.1613300492793393e-02, -3.7490726515634942e-19],
            [-4.4169424013798059e-02, -6.5514958298364678e-02, 0.0, -4.4209322035128798e-02, -1.4387721111655644e-01],
        ]
    )
    b = np.array([3.158477012681324e-02, 4.684858233775439e-02, 0.0, 3.161330049279339e-02, -3.749072651563494e-19])
    onehot = np.zeros((5, 3))
    onehot[[0, 1, 2, 3, 4], [0, 0, 0, 1, 2]] = 1.0
    p = SumOfNorms(M, b, onehot, 0.03610537001264863)
    start = np.array([0.0399289036423516, 1.0, -1.3984405723536146])
    kink = M[:, 3] / b[3]  # the single-column group's term vanishes there
    assert p.value(kink) > _by_cvxpy(p) * (1 + 1e-4)  # the minimum is not the kink
    found = p.minimise(start)
    assert found is not None
    assert p.value(found[0]) <= _by_cvxpy(p) * (1 + 1e-7)


def test_newton_creeping_onto_a_kink_that_is_no_minimum_gives_up_early(monkeypatch: pytest.MonkeyPatch) -> None:
    """A readings' update of paper6_max_faulty (NSNIM, node 1) once the recursion carries the readings: the
    minimum lies off the single-column group's kink, which minimise's test rules out, yet Newton from both
    starts creeps onto the kink with ever more halvings.  It gives up once a term is below KINK_NEAR of F while
    the line search needs STALL_HALVINGS (105 evaluations of F instead of 569), and the caller solves
    with Clarabel."""
    M = np.array(
        [
            [0.008451201680302377, -0.0052759465295171845, 0.0, 0.0012533593174262534, -0.0],
            [0.04003204854654091, 0.043168230204656016, 0.0, 0.031643981917059145, 9.067480287531796e-19],
            [-0.05032301379822181, -0.054265407919561214, 0.0, -0.03977864227436462, -0.12190373811013513],
        ]
    )
    b = np.array([0.04003204854654091, 0.043168230204656016, 0.0, 0.031643981917059145, 9.067480287531796e-19])
    onehot = np.zeros((5, 3))
    onehot[[0, 1, 2, 3, 4], [0, 0, 0, 1, 2]] = 1.0
    p = SumOfNorms(M, b, onehot, 0.03610537005918982)
    start = np.array([0.036156254337944144, 0.8847232503144914, -1.1121574325986083])
    kink = M[:, 3] / b[3]
    assert p.value(kink) > _by_cvxpy(p) * (1 + 1e-5)  # the kink is not the minimum
    calls = []
    value = SumOfNorms.value
    monkeypatch.setattr(SumOfNorms, "value", lambda self, L: calls.append(1) or value(self, L))
    assert p.minimise(start) is None
    assert len(calls) < 200
