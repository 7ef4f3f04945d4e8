"""Per-node per-step solve times on the paper scenario, fast path and yardsticks side by side.

1. An in-memory run with the default (fast) estimator records every node-step's inputs (the exact
   arguments of ``LocalEstimator.step``, through its observer hook) and the run's summary; the
   estimators are built as the nodes build them (``LocalEstimator.for_node``: declared fault bounds).
2. The recorded steps are solved again, interleaved step by step so that every formulation sees the
   same machine load: the fast path (``backend="clarabel"``, every step), the previous default
   (``backend="cvxpy"``: the reduced LMI through cvxpy Parameters), the straightforward and the naive
   formulations of :mod:`bench.reference` (on an evenly spaced subset of the steps).
3. Every formulation is timed over its whole step: its data, its solve, and the certification of the
   answer (the fast path's ``LocalEstimator.step`` as the node calls it).  The fast path's
   ``solve_ms`` (assembly + Clarabel + mapping back) is reported as well.  Ratios are medians over the
   same subset of steps.  The fault-bound widths of the answers are compared on that subset too.

Everything here uses the paper's objective (``trace``): it compares formulations of one problem.  The
yardsticks of :mod:`bench.reference` keep the paper's fixed sector (h1, h2 of the profile); the fast
path derives a sector per step (netsetest/estimator/sector.py), so in SAIM their widths are of a
different problem and only the times compare.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field

import numpy as np

from netsetest.config.schema import Scenario
from netsetest.estimator import sdp
from netsetest.records.summary import RunSummary
from netsetest.runtime.inmemory import run_inmemory


@dataclass
class StepCase:
    node: int
    args: tuple  # (prev, inp): the arguments of LocalEstimator.step


@dataclass
class Capture:
    scenario: Scenario
    variant: str
    cases: list[StepCase]
    summary: RunSummary
    wall_s: float
    step_ms: list[float] = field(default_factory=list)  # the fast path inside the run
    parts: dict | None = None  # the run's record parts (its published states)


def capture(scenario: Scenario, variant: str, signals: str = "paper", seed: int = 0) -> Capture:
    """Run in memory with the fast path, as the nodes run it; keep every node-step's estimator inputs
    (through the estimators' observer hook) and the run's published states."""
    cases: list[StepCase] = []
    times: list[float] = []

    def record(est: sdp.LocalEstimator, prev: sdp.NodeSet, inp: sdp.UpdateInput, res: sdp.StepResult, ms: float) -> None:
        times.append(ms)
        cases.append(StepCase(est.node_id, (prev, inp)))

    t0 = time.perf_counter()
    res = run_inmemory(scenario, signals, variant, seed, objective="trace", observer=record)  # type: ignore[arg-type]  # signals and variant are the Literal's values, passed through as str
    wall = time.perf_counter() - t0
    return Capture(scenario, variant, cases, res.summary, wall, times, res.parts)


def fast_estimators(sc: Scenario, variant: str) -> dict[int, sdp.LocalEstimator]:
    """The fast path the benchmark times: each node's estimator exactly as the node builds it."""
    return {i: sdp.LocalEstimator.for_node(sc, i, variant, "trace") for i in sc.ids}  # type: ignore[arg-type]  # variant is one of the Literal's values, passed through as str


def _yardstick_args(sc: Scenario, i: int, variant: str) -> tuple:
    """The positional arguments of bench.reference's formulations (they keep the profile's fixed sector)."""
    n = sc.node(i)
    return (i, n.sensor, {j: sc.node(j).sensor for j in n.in_weights}, n.in_weights, sc.model, sc.W, variant)


def _stats(v: list[float]) -> dict:
    if not v:
        return {"n": 0, "median": None, "p95": None}
    return {"n": len(v), "median": statistics.median(v), "p95": float(np.percentile(v, 95)), "mean": statistics.fmean(v)}


def side_by_side(cap: Capture, n_ref: int, n_naive: int, n_cvxpy: int) -> dict:
    """Solve the captured steps with every formulation, interleaved; times in ms (wall and CPU)."""
    sc, variant = cap.scenario, cap.variant
    ids = sc.ids
    fast = fast_estimators(sc, variant)
    prev, ref, naive = _yardstick_estimators(sc, variant, n_cvxpy, n_ref, n_naive)
    cases = cap.cases
    sub_ref, sub_naive, sub_prev = (_spread(k, len(cases)) for k in (n_ref, n_naive, n_cvxpy))
    out: dict[str, dict[int, float]] = {k: {} for k in ("fast", "fast_cpu", "fast_solve", "prev", "straightforward", "naive")}
    width: dict[str, dict[int, float]] = {k: {} for k in ("fast", "prev", "straightforward", "naive")}
    iters: list[int] = []
    fallbacks = 0
    for k, c in enumerate(cases):
        t0, c0 = time.perf_counter(), time.thread_time()
        r = fast[c.node].step(*c.args)
        prev_set, inp = c.args
        old_args = (prev_set.xhat, prev_set.P, prev_set.rho, inp.alpha, inp.u, inp.y, inp.gamma, inp.neigh)  # the yardsticks' form
        out["fast"][k] = 1e3 * (time.perf_counter() - t0)
        out["fast_cpu"][k] = 1e3 * (time.thread_time() - c0)
        out["fast_solve"][k] = r.figures.solve_ms
        iters.append(fast[c.node].last_iterations)
        fallbacks += r.figures.status != "ok"
        rho = prev_set.rho
        width["fast"][k] = 2.0 * np.sqrt(rho * r.continued.P[2, 2])
        if k in sub_prev:
            t0 = time.perf_counter()
            rp = prev[c.node].step(*c.args)
            out["prev"][k] = 1e3 * (time.perf_counter() - t0)
            width["prev"][k] = 2.0 * np.sqrt(rho * rp.continued.P[2, 2])
        if k in sub_ref:
            rr = ref[c.node].step(*old_args)
            out["straightforward"][k] = rr.step_ms
            if rr.P is not None:
                width["straightforward"][k] = 2.0 * np.sqrt(rho * rr.P[2, 2])
        if k in sub_naive:
            rn = naive[c.node].step(*old_args)
            out["naive"][k] = rn.step_ms
            if rn.P is not None:
                width["naive"][k] = 2.0 * np.sqrt(rho * rn.P[2, 2])

    res: dict = {
        "variant": variant,
        "case": sc.case,
        "node_steps": len(cases),
        "fallbacks": fallbacks,
        "iterations_median": statistics.median(iters) if iters else None,
        "iterations_max": max(iters) if iters else None,
        "fast_ms": _stats(list(out["fast"].values())),
        "fast_cpu_ms": _stats(list(out["fast_cpu"].values())),
        "fast_solve_ms": _stats(list(out["fast_solve"].values())),
        "in_run_fast_ms": _stats(cap.step_ms),
        "degree_of_nodes": {i: len(sc.node(i).in_weights) for i in ids},
    }
    for name in ("prev", "straightforward", "naive"):
        if out[name]:
            res[name] = _yardstick(out[name], width[name], out["fast"], width["fast"])
    return res


def _yardstick_estimators(sc: Scenario, variant: str, n_cvxpy: int, n_ref: int, n_naive: int) -> tuple[dict, dict, dict]:
    """Per node, the yardsticks asked for (a count of 0: none): the previous default (cvxpy), the straightforward and the
    naive formulation."""
    from netsetest_bench.reference import NaiveSDP, StraightforwardSDP

    ids = sc.ids
    prev = {i: sdp.LocalEstimator.for_node(sc, i, variant, "trace", backend="cvxpy") for i in ids} if n_cvxpy else {}  # type: ignore[arg-type]  # variant is one of the Literal's values, passed through as str
    ref = {i: StraightforwardSDP(*_yardstick_args(sc, i, variant)) for i in ids} if n_ref else {}
    naive = {i: NaiveSDP(*_yardstick_args(sc, i, variant)) for i in ids} if n_naive else {}
    return prev, ref, naive


def _spread(k: int, n: int) -> set[int]:
    """``k`` of the ``n`` captured steps, spread evenly (none for k ≤ 0)."""
    if k <= 0:
        return set()
    return set(np.linspace(0, n - 1, min(k, n)).round().astype(int).tolist())


def _yardstick(times: dict[int, float], widths: dict[int, float], fast: dict[int, float], fast_widths: dict[int, float]) -> dict:
    """A yardstick's figures on the steps it solved (step → ms, step → fault width), against the fast path's on the
    same steps: its times, how many times slower, its fault width relative to the fast path's, its uncertified steps."""
    ks = sorted(times)
    fast_same = statistics.median([fast[k] for k in ks])
    rel = [fast_widths[k] / widths[k] - 1.0 for k in ks if k in widths]
    return {
        **_stats([times[k] for k in ks]),
        "fast_median_same_steps": fast_same,
        "ratio": statistics.median([times[k] for k in ks]) / fast_same,
        "uncertified": len(ks) - len(rel),
        "width_rel_diff_min": min(rel) if rel else None,
        "width_rel_diff_max": max(rel) if rel else None,
    }
