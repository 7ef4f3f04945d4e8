"""The set estimators' region (estimator/region.py): each method's own set cut by a region of x and the fault range
the own measurement proves over it.  Sound (never narrower than the exact local limit under the method's own
assumptions, the truth inside), never wider than the method alone, judged whole by the collector (a region moved
off the truth is a violation), and what it buys measured by ``netsetest bench --only widths``."""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
import pytest

from netsetest.analysis.exact import exact_bounds
from run_helpers import step_data, stepped_bounds
from netsetest.config.schema import Scenario, load_topology
from netsetest.estimator.base import StepInput
from netsetest.estimator.names import NO_REGION
from netsetest.estimator.region import WithRegion
from netsetest.estimator.registry import SET_ESTIMATORS
from netsetest.polygon import Polygon
from netsetest.records.record import Record, record_from_parts
from netsetest.runtime.inmemory import run_inmemory
from netsetest.sets import RegionSet

STEPS = 30
TOL = 1e-8  # the exact ends' solver precision (analysis/exact.NARROWER_TOL)
METHODS = ("zonotope", "interval", "strip", "setprop")


@cache
def _run(case: str, signals: str, seed: int) -> tuple[Scenario, Record]:
    sc = load_topology("paper6", case, STEPS)
    res = run_inmemory(sc, signals, "scheduled", seed)
    return sc, record_from_parts(res.meta, res.parts["truth"], res.parts["nodes"], res.summary)


@pytest.mark.parametrize(("case", "signals", "seed"), [("nsnim", "worst", 1), ("saim", "paper", 2), ("saim", "worst", 0)])
@pytest.mark.parametrize("name", METHODS)
def test_the_region_keeps_the_exact_local_set_and_never_widens_the_method(name: str, case: str, signals: str, seed: int) -> None:
    """Every consistent trajectory's end stays inside (the exact local limit under the method's own assumptions: a
    cut that dropped a point of its input satisfying its slab would show here), the truth too, and every interval is
    within the method's own (the region only cuts)."""
    sc, rec = _run(case, signals, seed)
    for node in (2, 5):
        inner = SET_ESTIMATORS[name](sc, node)
        est = WithRegion(SET_ESTIMATORS[name](sc, node), sc, node)
        b, own = stepped_bounds(est, rec, node), stepped_bounds(inner, rec, node)
        mode = "all" if "fault_bound" in est.assumptions else "used"
        ex = exact_bounds(sc, rec, mode, nodes=[node])
        exact = np.stack([ex.beta, ex.r, ex.fault[node]], axis=1)
        slack = TOL * np.maximum(1.0, np.abs(np.nan_to_num(exact, posinf=0, neginf=0)))
        assert np.all(b[:, :, 0] <= exact[:, :, 0] + slack[:, :, 0]), f"{name} node {node} narrower than exact (lower)"
        assert np.all(b[:, :, 1] >= exact[:, :, 1] - slack[:, :, 1]), f"{name} node {node} narrower than exact (upper)"
        assert np.all(b[:, :, 0] >= own[:, :, 0] - TOL) and np.all(b[:, :, 1] <= own[:, :, 1] + TOL)
        for t in rec.truth:
            truth = np.r_[t["x"], t["faults"][node]]
            assert np.all(b[t["step"], :, 0] <= truth + TOL) and np.all(truth <= b[t["step"], :, 1] + TOL)


def _network(name: str, case: str, steps: int = STEPS) -> Scenario:
    sc = load_topology("paper6", case, steps)
    return replace(sc, nodes=[replace(n, estimator=name) for n in sc.nodes])


def _widths(res: object) -> np.ndarray:
    """(nodes × steps ≥ 10, 3) the published widths of a run's record."""
    return np.array([np.diff(np.asarray(e["bounds"]), axis=1)[:, 0] for es in res.parts["nodes"].values() for e in es if e["step"] >= 10])  # type: ignore[attr-defined]  # an InMemoryResult


@pytest.mark.parametrize("name", METHODS)
def test_a_saturated_reading_still_bounds_the_fault_on_its_open_side(name: str) -> None:
    """Changed by design (issue 46, one region engine): a reading at the sensor's limit leaves one side of C x + Ds f
    open, and the other still bounds f over the region (estimator/region_engine.region_fault, as the SDP's region
    cut has it); before, the set estimators' copy took the fault over the region only from two-sided readings.  On
    paper6 SAIM, worst-case signals, the saturated steps' published fault range is cut there (the region named among
    its cuts, narrower than the method's own set) and still holds the truth (the exact limit: the test above);
    ``netsetest bench --only widths`` shows what it buys."""
    sc, rec = _run("saim", "worst", 0)
    cut = 0
    for node in (1, 2, 5):
        sensor = sc.node(node).sensor
        est, inner = WithRegion(SET_ESTIMATORS[name](sc, node), sc, node), SET_ESTIMATORS[name](sc, node)
        prev = None
        for d in step_data(rec):
            inp = StepInput(d.step, d.y[node], d.gamma[node], None if prev is None else prev.u, None if prev is None else prev.vx)
            s, own = est.step(inp), inner.step(inp)
            prev = d
            lo, hi = sensor.measured_interval(d.y[node], d.gamma[node])
            if np.isfinite(lo) == np.isfinite(hi) or not isinstance(s, RegionSet):
                continue  # two-sided (or no region this step)
            side = 0 if np.isfinite(lo) else 1  # C x + Ds f ≥ m_lo bounds f from below (Ds > 0), and the other way round
            o_lo, o_hi = own.bounds()
            narrower = s.fault[0] > o_lo[2] + 1e-9 if side == 0 else s.fault[1] < o_hi[2] - 1e-9
            if narrower and "region" in s.cuts[2]:
                cut += 1
            truth = next(t for t in rec.truth if t["step"] == d.step)["faults"][node]
            assert s.fault[0] - 1e-9 <= truth <= s.fault[1] + 1e-9
    assert cut > 0, f"{name}: no saturated step's fault range cut by the region"


@pytest.mark.parametrize("name", METHODS)
def test_every_method_publishes_its_region_covered_and_contained_and_narrower(name: str) -> None:
    """In the network (the node publishes a region set; the collector judges it whole), SAIM: every node-step
    covered and contained, none narrower than without the region, and the state narrower on average."""
    with_region = run_inmemory(_network(name, "saim"), "worst", seed=3)
    alone = run_inmemory(_network(name + NO_REGION, "saim"), "worst", seed=3)
    for res in (with_region, alone):
        s = res.summary
        assert s.violations_total == 0 and s.node_steps_covered == s.node_steps_evaluated == s.node_steps_contained
    w, w0 = _widths(with_region), _widths(alone)
    assert np.all(w <= w0 + TOL) and np.mean(w[:, :2]) < np.mean(w0[:, :2])


@pytest.mark.parametrize("name", ("interval", "strip"))
def test_a_set_estimator_region_moved_off_the_truth_is_a_violation(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A region moved off the truth (a deliberate bug) is published inside the node's set: every covered node-step
    is then a miss, a violation (the collector judges the region, not only the method's own set)."""
    sc = _network(name, "nsnim", 20)
    step = WithRegion.step

    def moved_off(self: WithRegion, inp: StepInput, neighbours: tuple = ()) -> object:
        s = step(self, inp, neighbours)
        assert isinstance(s, RegionSet)
        return replace(s, region=Polygon(s.region.vertices + np.array([0.0, 1.0])))  # 1 rad/s of yaw rate off

    monkeypatch.setattr(WithRegion, "step", moved_off)
    broken = run_inmemory(sc, "paper", seed=0)
    assert broken.summary.violations_total > 0
    covered = [e for es in broken.parts["nodes"].values() for e in es if e["assumptions_ok"]]
    assert covered and all(e["contained"] is False for e in covered)
