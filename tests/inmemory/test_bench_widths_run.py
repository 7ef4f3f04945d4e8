"""The widths part's measuring functions (netsetest_bench/widths.py, network_sets.py) at a tiny size: each builds its typed
figures, the file holds them as the committed one does (issue 44's ``with`` keys included), and the report is the same
from the typed figures and from the file."""

from __future__ import annotations

import importlib
from pathlib import Path


def test_the_widths_part_measures_typed_figures_and_reports_them_as_its_file_holds_them(tmp_path: Path) -> None:
    ns = importlib.import_module("netsetest_bench.network_sets")  # (sys.modules' copies: test_bench_extras imports the benchmark again)
    widths = importlib.import_module("netsetest_bench.widths")
    figures = importlib.import_module("netsetest_bench.figures.widths")
    sets_figures = importlib.import_module("netsetest_bench.figures.network_sets")
    run = importlib.import_module("netsetest_bench.run")

    compared = widths._measure(widths.WidthRun("tiny", "paper6", "nsnim", "paper", (0,), widths.LISTED, steps=12, without_region=True))
    assert {r.estimator for r in compared.rows} >= {"sdp", "sdp-ellipsoid", "exact", "strip-noregion"} and compared.steps == 12
    sets = sets_figures.Sets(
        at_bounds=[ns.at_bounds(tmp_path, "paper6", [0], steps=12)],
        rings=[ns.ring(tmp_path, "near_reference", 0, 14, budget_s=5.0)],
        declared=[ns.declared_bounds(0, True, 12), ns.declared_bounds(0, False, 12)],
        cost=[ns.cost(tmp_path, "paper6", "paper6", "nsnim", steps=3, rounds=1)],
        step_target_ms=ns.STEP_TARGET_MS,
    )
    assert sets.declared[1].false_nodes and sets.rings[0].network and sets.at_bounds[0].runs[0].ratios
    typed = figures.Widths(from_step=10, runs=[compared], cost=widths.region_cost(steps=3, runs=1), sets=sets)
    written = run._as_written({"widths": typed})["widths"]
    cost = written["sets"]["cost"][0]
    assert {"with", "without"} <= set(cost["wire"]) & set(cost["step"]) and "with_" not in set(cost["wire"]) | set(cost["step"])
    assert widths.widths_markdown(written) == widths.widths_markdown(typed)
    assert "| paper6 | NSNIM |" in widths.widths_markdown(written)
