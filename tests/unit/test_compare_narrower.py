"""``netsetest compare`` counts the intervals narrower than the exact limit where the node-step's assumptions held
(analysis/compare.py): a sound set has none.  An end the k-of-N search left relaxed is an outer bound, not the limit,
and is not compared; nor is a node-step whose cone broke."""

from __future__ import annotations

import numpy as np

from netsetest.analysis.compare import _Accumulator, _score
from netsetest.analysis.exact import ExactBounds, HealthSearch, WitnessKey

K = 4


def _exact(relaxed: tuple[WitnessKey, ...] = ()) -> ExactBounds:
    ones = np.tile([-1.0, 1.0], (K, 1))
    health = HealthSearch("max_faulty = 1", (5,), ((1, 2),), 10, 12, 12 - len(relaxed), relaxed, 20)
    return ExactBounds(np.arange(K), ones.copy(), ones.copy(), {1: ones.copy()}, "used", (), (), health=health)


def _scored(bounds: np.ndarray, exact: ExactBounds, broken: list[str | None]) -> _Accumulator:
    acc = _Accumulator()
    _score(acc, 1, bounds, np.arange(K), np.zeros((K, 3)), exact, broken)
    return acc


def test_a_narrower_interval_is_counted_where_the_assumptions_held_only() -> None:
    bounds = np.tile([-1.0, 1.0], (K, 3, 1))
    assert _scored(bounds, _exact(), [None] * K).narrower == 0
    bounds[1, 2] = [-0.5, 1.0]  # step 1's fault: narrower at its lower end
    bounds[3, 0] = [-1.0, 0.9]  # step 3's β
    acc = _scored(bounds, _exact(), [None] * K)
    assert (acc.narrower, acc.compared) == (2, 3 * K)
    assert _scored(bounds, _exact(), [None, None, None, "noise"]).narrower == 1  # step 3's cone broke
    assert _scored(bounds + np.array([-1e-9, 1e-9]), _exact(), [None] * K).narrower == 2  # beyond the exact ends' precision


def test_an_end_the_search_left_relaxed_is_not_the_limit() -> None:
    bounds = np.tile([-1.0, 1.0], (K, 3, 1))
    bounds[1, 2] = [-0.5, 1.0]
    assert _scored(bounds, _exact((WitnessKey("f", 1, 1, "lo"),)), [None] * K).narrower == 0
    assert _scored(bounds, _exact((WitnessKey("f", 1, 1, "hi"),)), [None] * K).narrower == 1  # the other end is
