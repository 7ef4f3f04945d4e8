"""The committed benchmark figures are not older than the code: the headline run (paper6, NSNIM and SAIM, paper
signals, seed 0, its 80 steps, in memory, as `netsetest run paper6 --mode inmemory --seed 0` runs it) measured
against the exact limit as `netsetest exact` computes it (analysis.exact: exact_bounds with the fault bounds the run
used, compare_record), and every bench/*.json that reports a figure of that run held to it: per node the published
width over the exact width from step 10 per coordinate (f, r, β), the fault width from step 10 and max E, and the
mean over nodes of each ratio.  A figure off by more than :data:`RTOL` fails the part's test, which names the command
that re-measures it (docs/results.md has each under its heading; then `netsetest bench --render-docs`), so a
README or docs/results.md figure cannot go on describing code that has changed.

RTOL is 0.2 %: the CPU's BLAS kernels move these figures by about 10⁻⁶ (tests/recorded_runs.py says why and how
much), and an estimator whose widths move by 1 % must fail here (checked on 2026-12-07: every region 1 % wider, the
scaling of its move's margin, fails the scenario, widths, network and performance parts on every node).
The runs are run_helpers.shared_run's, shared with test_containment, test_fdi and test_sector (one pytest-xdist
group, tests/conftest.py)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import pytest
from run_helpers import ROOT, shared_run

from netsetest.analysis.exact import COORDINATES, FROM_STEP, compare_record, exact_bounds
from netsetest_bench.docs import PARTS, RENDER_COMMAND
from netsetest.config.schema import Case, load_topology
from netsetest.records.record import load_record, save_record

pytestmark = pytest.mark.blas  # (.ci/run runs it under every OpenBLAS kernel the CPU runs)

RTOL = 2e-3  # relative: far above the kernels' 10⁻⁶, five times below a 1 % change
SEED = 0
CASES: tuple[Case, ...] = ("nsnim", "saim")
Key = tuple[str, str, str]  # (case, node or "mean", figure)


@dataclass(frozen=True)
class Headline:
    """The headline run's figures now, per (case, node, figure): ``f``, ``r``, ``beta`` (published width / exact
    from step 10), ``fault_width`` (from step 10) and ``max_E`` per node; the ratios' means over nodes as node
    ``mean``; and the run's length."""

    figures: dict[Key, float]
    steps: int


@pytest.fixture(scope="module")
def now(tmp_path_factory: pytest.TempPathFactory) -> Headline:
    tmp = tmp_path_factory.mktemp("headline")
    figures: dict[Key, float] = {}
    steps = 0
    for case in CASES:
        run = shared_run(case, "paper", SEED)
        assert run.parts is not None
        sc = load_topology(ROOT / "topologies" / "paper6.toml", case)
        path = tmp / f"{case}.json"
        save_record(path, run.meta, run.parts["truth"], run.parts["nodes"], run.summary)
        rec = load_record(str(path))
        cmp = compare_record(rec, exact_bounds(sc, rec, "used"))  # what `netsetest exact` does
        for n in cmp.nodes:
            for c in COORDINATES:
                figures[(case, str(n.node), c)] = n.ratios[c].width_ratio
            lo, hi = rec.nodes[n.node].bounds(2)
            figures[(case, str(n.node), "fault_width")] = float(np.mean((hi - lo)[rec.nodes[n.node].steps >= FROM_STEP]))
        for c in COORDINATES:
            figures[(case, "mean", c)] = cmp.mean_width_ratio[c]
        for row in run.summary.nodes:
            figures[(case, str(row.id), "max_E")] = row.max_E
        steps = sc.steps
    return Headline(figures, steps)


# Where each part's figures file holds the headline run's figures: (case, node, figure) → value, and how it was run
# where that differs from the headline run (a message; None if it is the headline run).


def _scenario(doc: dict, steps: int) -> Iterator[tuple[Key, float | None] | str]:
    for case in CASES:
        run = next((r for r in doc["scenario"]["runs"] if (r["case"], r["signals"], r["seed"]) == (case, "paper", SEED)), None)
        if run is None or run["steps"] != steps:
            yield f"no paper6 {case} run of seed {SEED} and {steps} steps"
            continue
        for i, node in run["nodes"].items():
            yield from (((case, i, c), node["ratio_exact"][c]) for c in COORDINATES)
            yield (case, i, "fault_width"), node["fault_width"]
            yield (case, i, "max_E"), node["max_E"]


def _widths(doc: dict, steps: int) -> Iterator[tuple[Key, float | None] | str]:
    for case in CASES:
        run = next(
            (
                r
                for r in doc["widths"]["runs"]
                if (r["topology"], r["case"], r["signals"], r["seeds"], r["without_region"]) == ("paper6", case, "paper", [SEED], False)
            ),
            None,
        )
        row = None if run is None else next((r for r in run["rows"] if r["estimator"] == "sdp"), None)
        if run is None or row is None or run["steps"] != steps:
            yield f"no paper6 {case} SDP row of seed {SEED} and {steps} steps"
            continue
        for i, ratios in row["ratio_exact_by_node"].items():
            yield from (((case, i, c), v) for c, v in zip(("beta", "r", "f"), ratios))


def _network(doc: dict, steps: int) -> Iterator[tuple[Key, float | None] | str]:
    net = doc["network"]
    for case in CASES:
        run = next((r for r in net["runs"] if (r["topology"], r["case"], r["signals"], r["seed"]) == ("paper6", case, "paper", SEED)), None)
        if run is None or net["steps"] != steps:
            yield f"no paper6 {case} run of seed {SEED} and {steps} steps"
            continue
        for i, node in run["nodes"].items():
            yield (case, i, "f"), node["sdp_network_over_exact"]
            yield (case, i, "r"), node["sdp_r_over_exact"]
            yield (case, i, "beta"), node["sdp_beta_over_exact"]


def _performance(doc: dict, steps: int) -> Iterator[tuple[Key, float | None] | str]:
    for case in CASES:
        t = doc["tightness"][case]
        if t.get("steps") != steps:
            yield f"the {case} tightness measured on {t.get('steps', 'fewer')} steps, not the headline run's {steps}"
            continue
        yield from (((case, "mean", c), t["width_ratio"][c]) for c in COORDINATES)
        yield from (((case, i, "f"), v) for i, v in t["fault_width_ratio_by_node"].items())


READERS: dict[str, Callable[[dict, int], Iterator[tuple[Key, float | None] | str]]] = {
    "scenario": _scenario,
    "widths": _widths,
    "network": _network,
    "performance": _performance,
}


@pytest.mark.parametrize("part", sorted(READERS))
def test_the_committed_figures_are_the_codes(part: str, now: Headline) -> None:
    p = PARTS[part]
    doc = json.loads((ROOT / p.source).read_text())
    stale = []
    for item in READERS[part](doc, now.steps):
        if isinstance(item, str):
            stale.append(item)
            continue
        (case, node, figure), committed = item
        want = now.figures[(case, node, figure)]
        if committed is None or not math.isclose(committed, want, rel_tol=RTOL):
            stale.append(f"paper6 {case.upper()} node {node} {figure}: committed {committed}, the code gives {want:.6g}")
    shown = stale[:10] + ([f"… and {len(stale) - 10} more"] if len(stale) > 10 else [])
    assert not stale, (
        f"{p.source} is older than the code (tolerance {RTOL:.1%}):\n  "
        + "\n  ".join(shown)
        + f"\nre-measure it: `{p.measure}`, then `{RENDER_COMMAND}`, and commit both"
    )
