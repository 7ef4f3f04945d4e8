"""The performance part side by side with a baseline checkout (netsetest_bench/baseline.py): issue 45's figures read
off each part's runs (the fastest run of each checkout judged, the median beside it), the real-time ladder of each
checkout ending at its own first miss, and the table."""

from __future__ import annotations

from pathlib import Path

import pytest

from netsetest_bench import baseline


def _step(this: float, base: float) -> dict:
    return {"replayed": {"this": this, "baseline": base, "this_median": this * 1.1, "baseline_median": base * 1.1}}


def _ring(this: float, base: float) -> dict:
    return {"this": this, "baseline": base, "this_median": this, "baseline_median": base, "ratio": this / base}


def _rt(nodes: int, cpu: float | None, ok: bool = True) -> dict:
    return {"nodes": nodes, "deadline_misses": 0 if ok else 7, "node_cpu_ms_per_step": cpu}


SIDE = {
    "commits": {"this": "aaa", "baseline": "16f81b4"},
    "step": {"nsnim": _step(0.24, 0.45), "saim": _step(1.7, 2.3)},
    "scaling": {"6": _ring(0.5, 1.1), "24": _ring(0.55, 1.09), "96": _ring(0.61, 1.3)},
    "realtime": {
        "this": {"max_nodes": 96, "runs": [_rt(48, 1.1), _rt(96, 1.3)], "node_cpu_ms_per_step": {"min": 1.1, "median": 1.2, "runs": 2}},
        "baseline": {"max_nodes": 48, "runs": [_rt(48, 1.9), _rt(64, 2.0, ok=False)], "node_cpu_ms_per_step": {"min": 1.9, "median": 1.95, "runs": 2}},
    },
}


def test_the_figures_are_judged_on_the_fastest_run_against_the_issues_targets() -> None:
    f = baseline.figures(SIDE)
    assert f["step_nsnim"]["met"] and not f["step_saim"]["met"] and f["step_nsnim"]["ratio"] == pytest.approx(0.24 / 0.45)
    assert f["node_step_24"]["met"] and not f["node_step_96"]["met"] and "target" not in f["node_step_6"]
    assert f["realtime_nodes"] == {"this": 96, "baseline": 48, "target": "≥ 96", "met": True}
    assert f["node_cpu_ms"]["this"] == 1.1 and f["node_cpu_ms"]["met"] and f["node_cpu_ms"]["ratio"] == pytest.approx(1.1 / 1.9)


def test_the_table_has_every_figure_and_says_what_was_not_measured() -> None:
    side = {**SIDE, "figures": baseline.figures(SIDE)}
    text = baseline.baseline_markdown(side)
    assert "`16f81b4`" in text and "| NSNIM estimator step, median node-step replayed (ms) | 0.240 / 0.264 | 0.450 / 0.495 | 0.53 | ≤ 0.25 | yes |" in text
    assert "| real-time nodes at τs = 0.1 s (largest ring without a miss) | 96 | 48 | — | ≥ 96 | yes |" in text
    assert "64: 7 (2.00)" in text
    failed = {**side, "scaling": {"error": "the in-memory rings on /x failed (exit 1): boom"}}
    failed["figures"] = baseline.figures(failed)
    text = baseline.baseline_markdown(failed)
    assert "| in-memory node-step, 24 nodes (ms) | — | — | — | | |" in text and "scaling: not measured: the in-memory rings on /x failed" in text


def test_the_ladders_stop_each_at_their_own_first_miss(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Each size is run by this checkout and then by the baseline; a checkout that missed is not run at larger sizes, and
    the ladder ends when both have missed."""
    calls: list[tuple[int, str]] = []
    limit = {"this": 64, "baseline": 24}

    def fake_run(topo, n, steps, retries, log, label="", env=None):  # the real-time run of zenoh_runs
        name = "baseline" if env else "this"
        calls.append((n, name))
        ok = n <= limit[name]
        return ok, [{"nodes": n, "deadline_misses": 0 if ok else 3, "node_cpu_ms_per_step": 1.0 if name == "this" else 2.0}]

    monkeypatch.setattr(baseline, "realtime_run", fake_run)
    monkeypatch.setattr("netsetest_bench.topologies.ring_topology", lambda d, n, steps: tmp_path / f"ring{n}.toml")
    out = baseline.realtime_side_by_side(tmp_path, [12, 24, 48, 64, 80, 96], 10, Path("/base"))
    assert calls == [(12, "this"), (12, "baseline"), (24, "this"), (24, "baseline"), (48, "this"), (48, "baseline"), (64, "this"), (80, "this")]
    assert out["this"]["max_nodes"] == 64 and out["baseline"]["max_nodes"] == 24
    assert out["this"]["node_cpu_ms_per_step"] == {"median": 1.0, "min": 1.0, "runs": 3}  # rings of 48 nodes and more


def test_the_side_by_side_takes_the_typed_step_as_its_file_holds_it(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """performance_side_by_side with widths.step_side_by_side's typed result (a SideBySide since the figures were
    typed): its figures and its table, as `bench --only performance --baseline` makes them (it crashed there)."""
    from netsetest_bench import widths
    from netsetest_bench.config import QUICK
    from netsetest_bench.figures.widths import Commits, SideBySide, SideCase, StepFigure

    def fig(this: float, base: float) -> StepFigure:
        return StepFigure([this], [base], this, base, this * 1.1, base * 1.1, this - base, 1.1 * (this - base), this <= 0.25)

    typed = SideBySide(steps=40, processes=1, runs=1, target_ms=0.25, commits=Commits("aaa", "16f81b4"))
    typed = SideBySide(**{**typed.__dict__, "nsnim": SideCase(fig(0.3, 0.45), fig(0.24, 0.45)), "saim": SideCase(fig(2.0, 2.3), fig(1.7, 2.3))})
    monkeypatch.setattr(widths, "step_side_by_side", lambda b: typed)
    monkeypatch.setattr(baseline, "scaling_side_by_side", lambda quick, b: SIDE["scaling"])
    failed = {"nodes": 12, "deadline_misses": None, "node_cpu_ms_per_step": None}  # the baseline's first run gave no summary
    realtime = {**SIDE["realtime"], "baseline": {"max_nodes": None, "runs": [failed], "node_cpu_ms_per_step": {"min": None, "median": None, "runs": 0}}}
    monkeypatch.setattr(baseline, "realtime_side_by_side", lambda d, sizes, steps, b: realtime)
    side = baseline.performance_side_by_side(QUICK, tmp_path, tmp_path, True)
    assert side["figures"]["step_nsnim"] == baseline.figures(SIDE)["step_nsnim"]
    text = baseline.baseline_markdown(side)
    assert "| NSNIM estimator step, median node-step replayed (ms) | 0.240 / 0.264 | 0.450 / 0.495 | 0.53 | ≤ 0.25 | yes |" in text
    assert "12: — (—)" in text  # a run without a summary is shown as not measured, not a crash


def test_this_checkout_is_the_repository_the_benchmark_runs_from() -> None:
    """The tables name this checkout's commit: the repository holding netsetest_bench/ (it named none after the move)."""
    from netsetest_bench.node_budget import THIS_CHECKOUT, checkout_commit

    assert (THIS_CHECKOUT / "pyproject.toml").is_file() and (THIS_CHECKOUT / "netsetest_bench").is_dir()
    assert checkout_commit(THIS_CHECKOUT) is not None
