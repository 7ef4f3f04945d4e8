"""The k-of-N interval (netsetest/estimator/health.py) against the union over every hypothesis."""

from __future__ import annotations

import itertools
import math

from hypothesis import given
from hypothesis import strategies as st

from netsetest.estimator.health import healthy_interval

_END = st.one_of(st.integers(-20, 20).map(float), st.just(math.inf), st.just(-math.inf))


@st.composite
def _spans(draw: st.DrawFn) -> list[tuple[float, float]]:
    out = []
    for _ in range(draw(st.integers(1, 7))):
        a, b = draw(_END), draw(_END)
        lo, hi = min(a, b), max(a, b)
        if lo == hi and math.isinf(lo):
            lo, hi = -math.inf, math.inf
        out.append((lo, hi))
    return out


def _by_hypotheses(spans: list[tuple[float, float]], need: int) -> tuple[float, float] | None:
    """Every choice of ``need`` healthy sensors: the hull of the non-empty intersections."""
    los, his = [], []
    for healthy in itertools.combinations(spans, need):
        lo, hi = max(s[0] for s in healthy), min(s[1] for s in healthy)
        if lo <= hi:
            los.append(lo)
            his.append(hi)
    return (min(los), max(his)) if los else None


@given(_spans(), st.integers(1, 7))
def test_the_sweep_equals_the_union_over_every_hypothesis(spans: list[tuple[float, float]], need: int) -> None:
    need = min(need, len(spans))
    assert healthy_interval(spans, need) == _by_hypotheses(spans, need)


def test_paper_like_readings() -> None:
    """Two healthy sensors agree near 0.2, four faulty ones are far off in pairs that do not overlap."""
    spans = [(0.19, 0.21), (0.195, 0.215), (0.5, 0.52), (0.8, 0.82), (-0.4, -0.38), (1.2, 1.22)]
    assert healthy_interval(spans, 2) == (0.195, 0.21)
    assert healthy_interval(spans, 1) == (-0.4, 1.22)  # everyone may be the healthy one
    assert healthy_interval(spans, 3) is None  # no three agree: the assumption broke
    # a missing reading may be a healthy one agreeing with any other: every reading's interval is consistent
    assert healthy_interval(spans + [(-math.inf, math.inf)], 2) == (-0.4, 1.22)
