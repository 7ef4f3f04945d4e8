"""The benchmark's paper-scenario figures (``netsetest bench --only scenario``): what the README's and
docs/results.md's tables of the paper's scenario say, measured.

- per node: the paper network (``paper6``, the paper's 80 steps, scheduled variant, default objective) in
  memory, NSNIM and SAIM, paper and worst-case signals, seed 0: max E, the fault interval's width at
  step 0 and its mean from step FROM_STEP, the node-steps judged, contained and covered by the
  guarantee, violations, the steps the paper's fixed sector would break, the detection delay, and the
  published widths over the exact limit (``netsetest exact``, the fault bounds the run used);
- every estimator compared: ``netsetest compare paper6 --case nsnim|saim`` with every estimator of
  estimator/names.py, paper and worst-case signals, the configured seeds (analysis/compare.py).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import get_args

from netsetest.config.schema import Case
from netsetest.models.signals import SIGNAL_KINDS, SignalKind
from netsetest.scenarios import TOPOLOGY_DIR
from netsetest_bench.figures.scenario import Scenario
from netsetest_bench.figures.scenario import load as load_scenario
from netsetest_bench.render import figure, fill
from netsetest_bench.config import BenchConfig

PAPER6 = TOPOLOGY_DIR / "paper6.toml"
CASES: tuple[Case, ...] = get_args(Case)
SIGNALS: tuple[SignalKind, ...] = SIGNAL_KINDS
SEED = 0  # the per-node table's run (the README's reproduce line says it)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _per_node(case: Case, signals: SignalKind, tmp: Path) -> dict:
    """One in-memory run of paper6 and its record against the exact limit, per node."""
    import numpy as np

    from netsetest.analysis.exact import COORDINATES, FROM_STEP, compare_record, exact_bounds
    from netsetest.config.schema import load_topology
    from netsetest.records.record import load_record
    from netsetest.runtime.inmemory import run_inmemory

    sc = load_topology(PAPER6, case)
    path = tmp / f"scenario-{case}-{signals}.json"
    run = run_inmemory(sc, signals, "scheduled", SEED, record=str(path), keep=False)
    rec = load_record(str(path))
    ratios = {n.node: n for n in compare_record(rec, exact_bounds(sc, rec, "used")).nodes}
    nodes = {}
    for row in run.summary.nodes:
        track = rec.nodes[row.id]
        lo, hi = track.bounds(2)
        width = hi - lo
        nodes[row.id] = {
            "max_E": row.max_E,
            "violations": row.violations,
            "steps_evaluated": row.steps_evaluated,
            "steps_contained": row.steps_contained,
            "steps_covered": row.steps_covered,
            "sector_breaks": row.sector_breaks,
            "first_sector_break": row.first_sector_break,
            "fault_width_step0": float(width[track.steps == 0][0]),
            "fault_width": float(np.mean(width[track.steps >= FROM_STEP])),
            "detection_delay": row.detection_delay,
            "false_detections": row.false_detections,
            "ratio_exact": {c: ratios[row.id].ratios[c].width_ratio for c in COORDINATES},
        }
    _log(f"  paper6 {case} {signals}: max E " + ", ".join(f"{v['max_E']:.3f}" for v in nodes.values()))
    return {"case": case, "signals": signals, "seed": SEED, "steps": sc.steps, "objective": run.summary.objective, "nodes": nodes}


def _comparison(case: Case, seeds: list[int]) -> dict:
    from netsetest.analysis.compare import compare, comparison_document
    from netsetest.estimator.names import ESTIMATOR_NAMES

    t0 = time.perf_counter()
    c = compare(PAPER6, ESTIMATOR_NAMES, (case,), SIGNALS, tuple(seeds))
    _log(f"  compare paper6 {case}: {len(c.runs)} runs, {time.perf_counter() - t0:.0f} s")
    return {"case": case, "runs": c.runs, "steps": c.steps, "estimators": list(ESTIMATOR_NAMES), "rows": comparison_document(c)}


def scenario_figures(cfg: BenchConfig, tmp: Path) -> dict:
    runs = [_per_node(case, sig, tmp) for case in CASES for sig in SIGNALS]
    return {"runs": runs, "compare_seeds": cfg.compare_seeds, "compare": [_comparison(case, cfg.compare_seeds) for case in CASES]}


# ---------------------------------------------------------------- rendering


MISSING = "–"  # what this part prints for a figure it lacks (templates/scenario.md, its block ``missing``)


def _ms(v: float | None) -> str:
    """A time in ms with two significant figures' worth of resolution, however large."""
    return MISSING if v is None else format(v, ".0f" if v >= 10 else ".1f" if v >= 1 else ".2f")


def _span(vals: list[float], spec: str) -> str:
    lo, hi = min(vals), max(vals)
    return format(lo, spec) if format(lo, spec) == format(hi, spec) else f"{format(lo, spec)}–{format(hi, spec)}"


def _mean(xs: list[float]) -> float:
    return sum(xs) / len(xs)


def reproduce_line(s: Scenario) -> str:
    return fill("scenario", "reproduce", r=s.runs[0])


def scenario_markdown(doc: dict) -> str:
    """The per-node table of the paper's scenario and what the worst-case signals change."""
    s = load_scenario(doc)
    T = "scenario"
    ns, sa = s.run("nsnim", "paper"), s.run("saim", "paper")
    lines = [fill(T, "nodes-head", reproduce=reproduce_line(s))]
    for i in sorted(ns.nodes):
        a, b = ns.nodes[i], sa.nodes[i]
        first = "" if b.first_sector_break is None else fill(T, "first-break", k=b.first_sector_break)
        delays = {f"delay_{n}": "-" if x.detection_delay is None else format(x.detection_delay, "d") for n, x in (("a", a), ("b", b))}
        lines.append(fill(T, "node-row", i=i, a=a, b=b, first=first, **delays))
    lines.append("")
    for r in s.runs:
        v = list(r.nodes.values())
        lines.append(
            fill(
                T,
                "run-line",
                case=r.case.upper(),
                r=r,
                contained=sum(x.steps_contained for x in v),
                evaluated=sum(x.steps_evaluated for x in v),
                covered=sum(x.steps_covered for x in v),
                violations=sum(x.violations for x in v),
                false=sum(x.false_detections for x in v),
                max_e=_span([x.max_E for x in v], ".2f"),
                width0=_span([x.fault_width_step0 for x in v], ".2f"),
                width=_span([x.fault_width for x in v], ".3f"),
                over_f=_span([x.ratio_exact.f for x in v], ".2f"),
                over_r=_span([x.ratio_exact.r for x in v], ".2f"),
                over_beta=_span([x.ratio_exact.beta for x in v], ".2f"),
            )
        )
    return "\n".join(lines) + "\n"


def exact_markdown(doc: dict) -> str:
    """The SDP's published widths over the exact limit, per node and coordinate (docs/exact.md)."""
    s = load_scenario(doc)
    lines = [fill("scenario", "exact-head", reproduce=reproduce_line(s))]
    for r in s.runs:
        v = [r.nodes[i].ratio_exact for i in sorted(r.nodes)]
        f, yaw, beta = [x.f for x in v], [x.r for x in v], [x.beta for x in v]
        lines.append(
            fill(
                "scenario",
                "exact-row",
                case=r.case.upper(),
                r=r,
                faults=" ".join(format(x, ".2f") for x in f),
                mean_f=_mean(f),
                span_r=_span(yaw, ".2f"),
                mean_r=_mean(yaw),
                span_beta=_span(beta, ".2f"),
                mean_beta=_mean(beta),
            )
        )
    return "\n".join(lines) + "\n"


LABELS = {  # the paper each estimator is after (docs/references.md); interval-classical is the textbook one
    "sdp": "ellipsoidal SDP, 002",
    "zonotope": "001",
    "zonotope-q10": "001, ↓q = 10",
    "interval": "003, Alg. 1",
    "strip": "003, zonotope",
    "setprop": "003, eq. (8)",
    "exact": "offline",
}


def compare_markdown(doc: dict) -> str:
    """Every estimator on the paper network, one table per case."""
    s = load_scenario(doc)
    T = "scenario"
    first = s.compare[0]
    lines = [
        fill(
            T,
            "compare-head",
            c=first,
            estimators=",".join(first.estimators),
            signals=",".join(SIGNALS),
            seeds=",".join(map(str, s.compare_seeds)),
            runs=len(first.runs),
        )
    ]
    for c in s.compare:
        lines.append(fill(T, "compare-table", case=c.case.upper()))
        for r in c.rows:
            lines.append(
                fill(
                    T,
                    "compare-row",
                    r=r,
                    label=fill(T, "compare-label", label=LABELS[r.estimator]) if r.estimator in LABELS else "",
                    state=", ".join(figure(v, ".3f", MISSING) for v in r.ratio_exact_state),
                    ms_median=_ms(r.ms_median),
                    ms_p95=_ms(r.ms_p95),
                )
            )
        lines.append("")
    return "\n".join(lines)


__all__ = ["compare_markdown", "exact_markdown", "scenario_figures", "scenario_markdown"]
