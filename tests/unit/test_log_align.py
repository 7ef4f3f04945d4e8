"""A drive log on the run's steps as it streams (netsetest/logs/readers.py SampleStream, logs/align.py StepAligner;
docs/your-log.md), as properties (Hypothesis): with random rates, jitter, gaps, offsets, stamps shuffled within the
reorder window and random chunking, no sample is ever used at a step before it was taken, a step whose newest
sample is older than the tolerance is always missing (never filled), every other step gets exactly its newest
sample, and a sample further out of order than the window is an error, never silently used."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.config.logmap import SignalMap
from netsetest.logs.align import StepAligner, step_time
from netsetest.logs.readers import NEVER, LogError, SampleStream

EXAMPLES = int(os.environ.get("NETSETEST_FUZZ_EXAMPLES", "40"))
NAME = "yaw rate of node 1"


def _sig(name: str = NAME, scale: float = 1.0, offset_ns: int = 0) -> SignalMap:
    return SignalMap(name, "yaw1", "", scale, offset_ns)


def _stream(t: np.ndarray, v: np.ndarray, sig: SignalMap, reorder: int, cuts: list[int]) -> SampleStream:
    """One signal's samples in file order, cut into chunks at ``cuts``."""
    bounds = [0, *sorted({c for c in cuts if 0 < c < t.size}), t.size]
    chunks = ([(sig.name, t[a:b], v[a:b])] for a, b in zip(bounds, bounds[1:]))
    return SampleStream(Path("drive.csv"), [sig], chunks, reorder)


@st.composite
def channels(draw: st.DrawFn) -> tuple:
    """Samples of one channel (stamps ns, values) in file order, out of time order by at most the reorder window,
    with gaps; the chunking; the reorder window; and a run's start, τs, steps, tolerance; and the channel's offset."""
    period = draw(st.integers(1_000_000, 200_000_000))  # 5 Hz – 1 kHz
    n = draw(st.integers(1, 300))
    jitter = draw(st.integers(0, period // 2))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    t = np.arange(n, dtype=np.int64) * period + rng.integers(-jitter, jitter + 1, n)
    keep = rng.random(n) > draw(st.floats(0, 0.5))  # gaps: dropped samples
    t = t[keep] + draw(st.integers(-(10**9), 10**9))  # an offset against the run's clock
    t, first = np.unique(t, return_index=True)  # one value per stamp
    v = rng.normal(size=n)[keep][first]
    reorder = draw(st.integers(0, 3 * period))
    arrival = t + rng.integers(0, reorder + 1, t.size)  # a logger's latency: written in arrival order, late by ≤ the window
    order = np.argsort(arrival, kind="stable")
    cuts = draw(st.lists(st.integers(0, max(t.size, 1)), max_size=6))
    tau = draw(st.integers(1_000_000, 500_000_000))
    offset = draw(st.integers(-(10**8), 10**8))
    return t[order], v[order], cuts, reorder, draw(st.integers(-(10**9), 10**9)), tau, draw(st.integers(1, 200)), draw(st.integers(0, 2 * tau)), offset


@settings(max_examples=EXAMPLES, deadline=None, derandomize=True)
@given(channels())
def test_a_sample_is_never_used_before_it_was_taken_and_a_gap_is_never_filled(ch: tuple) -> None:
    t, v, cuts, reorder, start, tau, steps, tol, offset = ch
    if not t.size:
        return
    al = StepAligner(_stream(t, v, _sig(offset_ns=offset), reorder, cuts), tol)
    ts = t + offset  # a sample's time on the run's clock
    for k in range(steps + 1):
        tk = step_time(start, tau, k)
        s = al.at(tk)[NAME]
        before = ts <= tk
        if not before.any() or tk - ts[before].max() > tol:
            assert not s.present and np.isnan(s.value)  # a gap: missing, never a value
            continue
        j = int(np.flatnonzero(before)[np.argmax(ts[before])])
        assert s.present and s.value == v[j] and s.age_ns == tk - ts[j]  # the newest sample at or before the step
        assert ts[j] <= tk  # never one taken after it


def _drain(stream: SampleStream) -> tuple[list[int], list[float]]:
    out_t, out_v = [], []
    while True:
        more = stream.pull()
        t, v = stream.take(NAME)
        out_t += t.tolist()
        out_v += v.tolist()
        if not more:
            return out_t, out_v


def test_the_stated_rules_of_a_channel() -> None:
    """NaN is no sample; stamps are sorted (within the window); an equal duplicate is one; the offset moves the
    stamps; the unit scales."""
    t = np.array([30, 10, 20, 20, 40], dtype=np.int64)
    v = np.array([3.0, 1.0, 2.0, 2.0, np.nan])
    assert _drain(_stream(t, v, _sig(scale=0.5, offset_ns=5), 20, [2, 3])) == ([15, 25, 35], [0.5, 1.0, 1.5])


def test_two_different_samples_at_one_stamp_are_an_error() -> None:
    with pytest.raises(LogError, match="two samples at t = .* differ"):
        _drain(_stream(np.array([1, 1]), np.array([0.1, 0.2]), _sig(), 0, [1]))


def test_a_sample_further_out_of_order_than_the_window_is_an_error() -> None:
    """Released samples are final: one stamped before what the window already closed is refused, never used late."""
    t = np.array([0, 10, 100, 5], dtype=np.int64)
    with pytest.raises(LogError, match="out of time order: raise reorder_s"):
        _drain(_stream(t, np.zeros(4), _sig(), 50, [1, 2, 3]))
    assert _drain(_stream(t, np.zeros(4), _sig(), 100, [1, 2, 3]))[0] == [0, 5, 10, 100]  # within a wider window: sorted


def test_the_stream_holds_only_the_window() -> None:
    """Bounded memory: after each chunk, what is held back is the samples within the reorder window of the newest."""
    t = np.arange(0, 10_000, dtype=np.int64) * 10
    s = _stream(t, np.zeros(t.size), _sig(), 50, list(range(0, t.size, 100)))
    while s.pull():
        s.take(NAME)
        held = sum(p[0].size for p in s.pending[NAME])
        assert held <= 6  # stamps within 50 ns of the newest, 10 ns apart
    assert s.horizon(NAME) == NEVER


@pytest.mark.parametrize(
    "name, value",
    [("yaw rate of node 1", 20.0), ("speed", 200.0), ("steering", 3.0)],  # deg/s as rad/s, km/h as m/s at 720 km/h, deg as rad
)
def test_a_wrong_unit_is_caught_by_the_signal_s_physical_range(name: str, value: float) -> None:
    with pytest.raises(LogError, match="is the mapping's unit"):
        _drain(_stream(np.array([0, 1]), np.array([0.0, value]), _sig(name), 0, []))
