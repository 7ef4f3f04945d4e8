"""The widths part's report (netsetest_bench/widths.py): the SDP is judged on its worst node against the run's
target, a point exact interval shows its absolute excess, narrower intervals and violations fail the target, and the
region table sets each method without its region beside it with."""

from __future__ import annotations

from netsetest_bench.run import QUICK
from netsetest_bench.widths import LISTED, OTHER, cost_markdown, plan, region_markdown, widths_markdown, widths_summary_markdown
from netsetest.scenarios import bundled_topologies


# a compare row's figures the tables do not show (the row type, analysis/compare.py's CompareRow, has them all)
UNSHOWN = {
    "real_time": True,
    "assumptions": [],
    "node_steps": 100,
    "covered": 100,
    "misses_attributed": {},
    "fault_width_mean": None,
    "beta_width_mean": None,
    "r_width_mean": None,
    "rms_radius_rel": None,
    "ms_median": None,
    "ms_p95": None,
    "fallbacks": 0,
    "refused": [],
    "exact_reference": [],
}


def _row(name: str, by_node: dict[str, list[float | None]], narrower: int = 0, violations: int = 0, excess: float | None = None) -> dict:
    return UNSHOWN | {
        "estimator": name,
        "ratio_exact_state": [1.01, 1.02],  # β, r
        "ratio_exact": 1.03,
        "ratio_exact_by_node": by_node,
        "pinned_excess": excess,
        "violations": violations,
        "narrower": narrower,
        "compared": 100,
    }


def _run(label: str, target: float, sdp_nodes: dict, **sdp: int) -> dict:
    rows = [
        _row("sdp", sdp_nodes, **sdp),
        _row("sdp-ellipsoid", {"1": [2.0, 3.0, 1.1]}),
        _row("strip", {"1": [1.0, 1.0, 1.0]}),
        _row("strip-noregion", {"1": [1.2, 1.3, 2.5]}),
        _row("exact", {"1": [1.0, 1.0, 1.0]}),
    ]
    return {"label": label, "seeds": [0], "steps": 80, "target": target, "without_region": True, "rows": rows}


def _line(text: str, label: str) -> list[str]:
    row = next(line for line in text.splitlines() if line.startswith(f"| {label} "))
    return [c.strip() for c in row.strip("|").split("|")]


def test_the_sdp_is_judged_on_its_worst_node_and_a_narrower_interval_fails_the_target() -> None:
    res = {
        "from_step": 10,
        "runs": [
            _run("a", LISTED, {"1": [1.0, 1.0, 1.04], "2": [1.0, 1.0, None]}, excess=2e-3),
            _run("b", LISTED, {"1": [1.0, 1.0, 1.051]}),
            _run("c", OTHER, {"1": [1.0, 1.0, 1.09]}, narrower=1),
            _run("d", OTHER, {"1": [1.0, 1.0, 1.09]}),
        ],
    }
    text = widths_summary_markdown(res)
    a, b, c, d = (_line(text, f"{x} (seed 0; 80 steps)") for x in "abcd")
    assert a[2] == "1.020 / 1.010 / 1.030 (≤ 1.040), +2.0e-03 abs." and a[-1] == "yes"
    assert b[-1] == "**no**" and c[-1] == "**no**" and c[5] == "1 of 500" and d[-1] == "yes"
    full = widths_markdown(res)
    assert full.startswith(text) and "| `sdp` | 1.000 / 1.000 / 1.040 | 1.000 / 1.000 / – |" in full
    region = _line(region_markdown(res), "a")
    assert region[1] == "1.020 / 1.010 / 1.030 (≤ 2.500) → 1.020 / 1.010 / 1.030 (≤ 1.000)"


def test_the_plan_covers_the_listed_runs_and_every_other_bundled_scenario() -> None:
    runs = plan(QUICK)
    assert {r.topology for r in runs} == set(bundled_topologies())
    listed = [r for r in runs if r.target == LISTED]
    assert {(r.topology, r.case, r.signals) for r in listed} >= {("paper6", c, s) for c in ("nsnim", "saim") for s in ("paper", "worst")}
    assert all(r.seeds == (3, 11) for r in listed if r.signals == "worst")
    assert all(r.seeds[0] >= 10 for r in runs if r.topology == "paper6_car")  # held out of the mismatch calibration
    assert all(r.target == OTHER for r in runs if r.topology not in {x.topology for x in listed})


def test_the_cost_table_gives_each_case_its_step_and_the_regions_share() -> None:
    run = {"step_ms": 0.5, "moved_ms": 0.06, "cut_ms": 0.09, "share": 0.3}
    cost = {"steps": 40, "runs": 2, "nsnim": run | {"per_run": [run, run | {"step_ms": 0.6}]}, "saim": run | {"per_run": [run]}}
    line = _line(cost_markdown(cost), "paper6 NSNIM")
    assert line[1:] == ["0.500 (0.500, 0.600)", "0.060", "0.090", "30 %"]
    res = {"from_step": 10, "runs": [_run("a", LISTED, {"1": [1.0, 1.0, 1.0]})]}
    assert "region share" not in widths_markdown(res) and "region share" in widths_markdown(res | {"cost": cost})  # (figures of before it: none)
