"""A node without a reading carries its own set's x part by the model alone and resumes at its next reading
(estimator/rejoin.py: predict_x, resume_ellipsoid; docs/estimator.md#resume-after-steps-without-a-reading).  Soundness, drawn by Hypothesis: every
x of the set, every wind w² ≤ W and every mismatch ζ of the declared box or ball lands in the predicted set, and every
(x, f) the resumed ellipsoid must hold (x in the carried set, f any fault the reading leaves within the noise bound)
lies in it.  And the construction is not vacuous: a point outside what the model can reach lies outside."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.config.schema import load_topology
from netsetest.estimator.rejoin import predict_x, resume_ellipsoid
from netsetest.models.uncertainty import ModelUncertainty

SC = load_topology("paper6")
EXAMPLES = 60  # each a few hundred µs of numpy


def _inside(c: np.ndarray, S: np.ndarray, x: np.ndarray, slack: float = 1e-9) -> bool:
    e = x - c
    return float(e @ np.linalg.solve(S, e)) <= 1 + slack


@st.composite
def _case(draw: st.DrawFn) -> tuple:
    vx = draw(st.floats(SC.model.params.vx_min, SC.model.params.vx_max))
    a, b, d = SC.model.blend(SC.model.weights(vx))
    L = np.array([[draw(st.floats(1e-4, 0.05)), 0.0], [draw(st.floats(-0.05, 0.05)), draw(st.floats(1e-4, 0.3))]])
    xc = np.array([draw(st.floats(-0.05, 0.05)), draw(st.floats(-0.3, 0.3))])
    kind = draw(st.sampled_from(["none", "box", "ellipsoid"]))
    mismatch = (
        None
        if kind == "none"
        else ModelUncertainty.box((draw(st.floats(1e-4, 0.02)), draw(st.floats(1e-4, 0.06))))
        if kind == "box"
        else ModelUncertainty.ellipsoid(np.diag([draw(st.floats(1e-8, 4e-4)), draw(st.floats(1e-8, 4e-3))]))
    )
    u = draw(st.floats(-0.1, 0.1))
    return a, b[:, 0], d[:, 0], xc, L @ L.T, u, mismatch


@settings(max_examples=EXAMPLES, deadline=None, derandomize=True)
@given(_case(), st.lists(st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)), min_size=4, max_size=4))
def test_every_transition_from_the_set_lands_in_the_predicted_one(case: tuple, draws: list[tuple[float, ...]]) -> None:
    a, b, d, xc, S, u, mismatch = case
    c, S1 = predict_x(xc, S, a, b, d, u, SC.W, mismatch)
    M = np.linalg.cholesky(S)
    for s1, s2, wv, z1, z2 in draws:
        z = np.array([s1, s2])
        x = xc + M @ (z / max(1.0, float(np.linalg.norm(z))))  # a point of the set (its boundary included)
        w = wv * np.sqrt(SC.W)
        zeta = np.array([z1, z2])
        if mismatch is not None and mismatch.kind == "ellipsoid":
            zeta = zeta / max(1.0, float(np.linalg.norm(zeta)))
        e = np.zeros(2) if mismatch is None else mismatch.G @ zeta
        assert _inside(c, S1, a @ x + b * u + d * w + e)


def test_the_prediction_is_not_vacuous() -> None:
    """A point twice as far from the centre as the model can reach is outside: the set is not the whole plane."""
    a, b, d = SC.model.blend(SC.model.weights(SC.model.params.vx_min))
    S = np.diag([1e-4, 1e-3])
    c, S1 = predict_x(np.zeros(2), S, a, b[:, 0], d[:, 0], 0.0, SC.W, None)
    reach = np.sqrt(np.diag(S1))
    assert not _inside(c, S1, c + np.array([2.5 * reach[0], 0.0]))


@settings(max_examples=EXAMPLES, deadline=None, derandomize=True)
@given(_case(), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.integers(1, 6))
def test_the_resumed_ellipsoid_holds_every_state_and_fault_the_reading_allows(case: tuple, s1: float, s2: float, v: float, node: int) -> None:
    _, _, _, xc, S, _, _ = case
    n = SC.node(node)
    sen = n.sensor
    M = np.linalg.cholesky(S)
    z = np.array([s1, s2])
    x = xc + M @ (z / max(1.0, float(np.linalg.norm(z))))
    f = 0.07
    y = float(sen.C @ x + sen.Ds * f + sen.Dv * v * np.sqrt(sen.R))  # a reading the truth (x, f) gives within the noise bound
    xhat, P = resume_ellipsoid(sen, y, 1.0, n.rho, xc, S)
    e = np.r_[x, f] - xhat
    assert float(e @ np.linalg.solve(P, e)) <= n.rho * (1 + 1e-9)
