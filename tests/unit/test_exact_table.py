"""The table `netsetest exact` prints is built from typed data (analysis/exact_table.py): a node row per node and the
mean, a point exact interval as the absolute width over it, and the likely reason beside a narrower count."""

from __future__ import annotations

import math

import numpy as np

from netsetest.analysis.exact import COORDINATES, CoordinateRatio, ExactBounds, ExactComparison, HealthSearch, LocalLimit, NodeRatios, WitnessKey
from netsetest.analysis.exact_table import exact_table, local_table

K = 12


def _exact(omitted: tuple[str, ...] = (), relaxed: tuple[WitnessKey, ...] = ()) -> ExactBounds:
    ones = np.tile([-1.0, 1.0], (K, 1))
    health = HealthSearch("max_faulty = 1", (1,), ((1, 2),), 10, 72, 72 - len(relaxed), relaxed, 80) if not omitted else None
    return ExactBounds(np.arange(K), ones, ones.copy(), {1: ones.copy(), 2: ones.copy()}, "used", (1,), (), omitted=omitted, health=health)


def _comparison(narrower: int = 0) -> ExactComparison:
    ratio = CoordinateRatio("beta", 1.5, 1.25, 1.1, steps=K - 1, left_out=1, narrower=narrower)
    point = CoordinateRatio("f", math.nan, math.nan, math.nan, steps=K, left_out=0, narrower=0, width_excess=2e-3, width_excess_all=1e-3)
    nodes = (NodeRatios(1, dict.fromkeys(COORDINATES, ratio)), NodeRatios(2, {"beta": ratio, "r": ratio, "f": point}))
    mean = dict.fromkeys(COORDINATES, 1.5)
    return ExactComparison(nodes, mean, dict.fromkeys(COORDINATES, 1.1), 1.5, dict.fromkeys(COORDINATES, 1.25), 1.1)


def test_the_exact_table_has_a_row_per_node_and_the_mean() -> None:
    table = exact_table("run.jsonl", "saim", _exact(), _comparison(), 2.0)
    assert [r.label for r in table.rows] == ["1", "2", "mean"]
    assert table.intervals == 2 * K * len(COORDINATES) and table.left_out == 5 and table.narrower == 0
    lines = table.lines()
    assert lines[0] == "exact bounds for run.jsonl: case saim, 12 steps, fault bounds 'used' (applied on nodes: 1), 2.0 s"
    assert lines[1].startswith("  applied: k-of-N health (max_faulty = 1")
    assert lines[4].split() == ["1", *["1.500", "|", "1.250", "1.100"] * 3]
    assert lines[5].endswith("+2.0e-03 |+1.0e-03 abs")  # node 2's fault: a point exact interval
    assert lines[-1] == f"published interval narrower than exact on 0 of {2 * K * 3} node-step intervals"


def test_a_narrower_count_says_why() -> None:
    assert exact_table("r", "nsnim", _exact(), _comparison(2), 0.0).lines()[-1].endswith("or one of the two is wrong)")
    relaxed = _exact(relaxed=(WitnessKey("f", 1, 3, "lo"),))
    assert exact_table("r", "nsnim", relaxed, _comparison(2), 0.0).lines()[-1].endswith("(some ends are relaxed: an outer bound there)")
    omitted = exact_table("r", "nsnim", _exact(omitted=("k-of-N health (max_faulty = 1)",)), _comparison(2), 0.0)
    assert "not applied: k-of-N health" in omitted.notes[0]
    assert omitted.lines()[-1].endswith("(the nodes used k-of-N health (max_faulty = 1), which these bounds leave out)")


def test_the_local_table_shows_a_declared_zero() -> None:
    lines = local_table([LocalLimit(1, math.nan, 1.5, 1.25)]).lines()
    assert lines[-1] == "   1    declared 0       1.500       1.250"
