"""The widths part's region cost (netsetest/bench/widths.py, ``region_cost``) at a tiny size: every node-step's move
and cut are timed in the run that times the step, their share is a part of it, and the timers are gone after."""

from __future__ import annotations

from netsetest.bench.widths import CASES, region_cost
from netsetest.estimator import cuts, sdp


def test_the_region_cost_times_its_pieces_within_the_step_and_unhooks_them() -> None:
    moved, cut = sdp.LocalEstimator._moved_region, cuts.REGION.apply
    cost = region_cost(steps=3, runs=2)
    assert sdp.LocalEstimator._moved_region is moved and cuts.REGION.apply is cut
    for case in CASES:
        c = cost[case]
        assert len(c["per_run"]) == 2 and c["step_ms"] > 0.0
        assert all(0.0 < r["share"] < 1.0 and 0.0 < r["moved_ms"] + r["cut_ms"] < r["step_ms"] for r in c["per_run"])
