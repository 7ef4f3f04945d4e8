"""The widths part's region cost (netsetest_bench/widths.py, ``region_cost``) at a tiny size: every node-step's move
and cut are timed in the run that times the step, their share is a part of it, and the timers are gone after.  The
step side by side with a baseline checkout (``step_side_by_side``, here this checkout itself): both measured in
processes of their own, the difference and the verdict against the target in the table."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from netsetest_bench.widths import CASES, STEP_FIGURES, STEP_TARGET_MS, SideBySideFailed, region_cost, side_by_side_markdown, step_side_by_side
from netsetest.estimator import cuts, sdp


def test_the_region_cost_times_its_pieces_within_the_step_and_unhooks_them() -> None:
    moved, cut = sdp.LocalEstimator._moved_region, cuts.REGION.apply
    cost = region_cost(steps=3, runs=2)
    assert sdp.LocalEstimator._moved_region is moved and cuts.REGION.apply is cut
    for case in CASES:
        c = cost.case(case)
        assert len(c.per_run) == 2 and c.step_ms > 0.0
        assert all(0.0 < r.share < 1.0 and 0.0 < r.moved_ms + r.cut_ms < r.step_ms for r in c.per_run)


def test_the_step_side_by_side_measures_both_checkouts_in_processes_and_judges_the_fastest_runs() -> None:
    root = Path(__file__).resolve().parents[2]  # this checkout as its own baseline: the program runs on both
    side = step_side_by_side(root, steps=3, processes=1, runs=2)
    text = side_by_side_markdown(side)
    for case in CASES:
        for key, what in STEP_FIGURES:
            c = side.case(case).figure(key)
            assert len(c.this_ms) == len(c.baseline_ms) == 2 and min(c.this_ms + c.baseline_ms) > 0.0
            assert c.this == min(c.this_ms) and c.baseline == min(c.baseline_ms) and c.this_median >= c.this
            assert c.over_ms == c.this - c.baseline and c.met == (c.over_ms <= STEP_TARGET_MS)
            assert f"| paper6 {case.upper()} | {what} | {c.this:.3f} / {c.this_median:.3f} | {c.baseline:.3f} / {c.baseline_median:.3f} |" in text
    nsnim = side.case("nsnim")
    side = replace(side, nsnim=replace(nsnim, in_run=replace(nsnim.in_run, over_ms=0.3, over_median_ms=0.4, met=False)))
    assert "| +0.300 / +0.400 ms | no |" in side_by_side_markdown(side)


def test_a_baseline_the_step_program_fails_on_is_named_not_a_traceback(tmp_path: Path) -> None:
    (tmp_path / "netsetest").mkdir()
    (tmp_path / "netsetest" / "__init__.py").write_text("raise ImportError('an old checkout')\n")
    with pytest.raises(SideBySideFailed, match=f"the step program on {tmp_path} failed .*an old checkout"):
        step_side_by_side(tmp_path, steps=3, processes=1, runs=1)
    assert "was not measured: the step program" in side_by_side_markdown({"error": "the step program on X failed"})
