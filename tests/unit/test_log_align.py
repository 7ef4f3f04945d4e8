"""A drive log on the run's steps (netsetest/logs/align.py, readers.clean; docs/your-log.md), as properties
(Hypothesis): with random rates, jitter, gaps, offsets and shuffled stamps, no sample is ever used at a step before
it was taken, a step whose newest sample is older than the tolerance is always missing (never filled), and every
other step gets exactly its newest sample."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.config.logmap import SignalMap
from netsetest.logs.align import at_or_before, step_times
from netsetest.logs.readers import LogError, clean

EXAMPLES = int(os.environ.get("NETSETEST_FUZZ_EXAMPLES", "40"))


@st.composite
def channels(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, int, int, int, int]:
    """Samples of one channel (stamps ns, values), shuffled, with gaps; and a run's start, τs, steps, tolerance."""
    period = draw(st.integers(1_000_000, 200_000_000))  # 5 Hz – 1 kHz
    n = draw(st.integers(1, 300))
    jitter = draw(st.integers(0, period // 2))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    t = np.arange(n, dtype=np.int64) * period + rng.integers(-jitter, jitter + 1, n)
    keep = rng.random(n) > draw(st.floats(0, 0.5))  # gaps: dropped samples
    t = t[keep] + draw(st.integers(-(10**9), 10**9))  # an offset against the run's clock
    v = rng.normal(size=t.size)
    if t.size:
        t, v = np.unique(t, return_index=True)[0], v[np.unique(t, return_index=True)[1]]  # one value per stamp
    order = rng.permutation(t.size)  # a log is written in arrival order
    tau = draw(st.integers(1_000_000, 500_000_000))
    return t[order], v[order], draw(st.integers(-(10**9), 10**9)), tau, draw(st.integers(1, 200)), draw(st.integers(0, 2 * tau))


@settings(max_examples=EXAMPLES, deadline=None, derandomize=True)
@given(channels())
def test_a_sample_is_never_used_before_it_was_taken_and_a_gap_is_never_filled(ch: tuple) -> None:
    t, v, start, tau, steps, tol = ch
    if not t.size:
        return
    c = clean(Path("drive.csv"), SignalMap("yaw rate of node 1", "yaw1", "", 1.0, 0), t, v)
    steps_ns = step_times(start, tau, steps)
    a = at_or_before(c.t_ns, c.v, steps_ns, tol)
    for k, tk in enumerate(steps_ns):
        before = c.t_ns <= tk
        if not before.any() or tk - c.t_ns[before].max() > tol:
            assert not a.present[k] and np.isnan(a.value[k])  # a gap: missing, never a value
            continue
        j = int(np.flatnonzero(before)[-1])
        assert a.present[k] and a.value[k] == c.v[j]  # the newest sample at or before the step
        assert c.t_ns[j] <= tk  # never one taken after it


def _sig(name: str = "yaw rate of node 1", scale: float = 1.0, offset_ns: int = 0) -> SignalMap:
    return SignalMap(name, "yaw1", "", scale, offset_ns)


def test_the_stated_rules_of_a_channel() -> None:
    """NaN is no sample; stamps are sorted; an equal duplicate is one; the offset moves the stamps; the unit scales."""
    t = np.array([30, 10, 20, 20, 40], dtype=np.int64)
    v = np.array([3.0, 1.0, 2.0, 2.0, np.nan])
    c = clean(Path("d.csv"), _sig(scale=0.5, offset_ns=5), t, v)
    assert c.t_ns.tolist() == [15, 25, 35] and c.v.tolist() == [0.5, 1.0, 1.5]


def test_two_different_samples_at_one_stamp_are_an_error() -> None:
    with pytest.raises(LogError, match="two samples at t = .* differ"):
        clean(Path("d.csv"), _sig(), np.array([1, 1]), np.array([0.1, 0.2]))


@pytest.mark.parametrize(
    "name, value",
    [("yaw rate of node 1", 20.0), ("speed", 200.0), ("steering", 3.0)],  # deg/s as rad/s, km/h as m/s at 720 km/h, deg as rad
)
def test_a_wrong_unit_is_caught_by_the_signal_s_physical_range(name: str, value: float) -> None:
    with pytest.raises(LogError, match="is the mapping's unit"):
        clean(Path("d.csv"), _sig(name), np.array([0, 1]), np.array([0.0, value]))
