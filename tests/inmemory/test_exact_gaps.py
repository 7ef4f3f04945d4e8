"""`netsetest exact` over a recorded drive with gaps (issue 42; docs/exact.md, *Readings missing*).

A node without a reading at a step has no measurement constraint there; its prior, its fault's declared bounds and
the model still hold.  The limit is then checked against a direct formulation of the same program (cvxpy, written
out here from the assumptions, not from analysis/exact.py's rows), against brute force over every k-of-N hypothesis
sequence, against the same drive without gaps (the gaps only widen it), against the truth (a reference of accuracy
0) and against every published set (never narrower); `exact` (with ``--local`` and ``--network``) and `compare`
give ratios where they refused such a log before; a truth entry without a node's reading and not saying so is still
refused (exit 2, one line).
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import cvxpy as cp
import numpy as np
import pytest
from gaps_helpers import EVERY_FAMILY, GAPS, STEPS, simulated_drive, write
from run_helpers import ROOT, mixed_topology
from test_exact_kofn import AGREE, _brute_force

from netsetest.analysis.compare import compare
from netsetest.analysis.exact import COORDINATES, ExactBounds, Witness, WitnessKey, compare_record, exact_bounds, step_data
from netsetest.cli.main import main
from netsetest.config.schema import FaultBoundsMode, HealthGroup, Scenario, load_topology
from netsetest.logs.drive import with_log_steps
from netsetest.logs.write import DriveTable
from netsetest.records.record import Record, load_record, record_from_parts, save_record
from netsetest.runtime.inmemory import run_inmemory

WITNESS_TOL = 1e-8  # as tests/inmemory/test_exact.py: Clarabel at 1e-10, witnesses meet every bound to ~1e-9
CONTAIN_TOL = 1e-9
DIRECT_TOL = 1e-6  # two solvers' formulations of one program (cvxpy's canonical form, ours): both at ~1e-8
MISSING = sorted((i, k) for i, ks in GAPS.items() for k in ks)


def _replay(
    topology: str | Path, log: Path, mapping: Path, steps: int = STEPS, estimator: str | None = None, record: str | None = None
) -> tuple[Scenario, Record]:
    sc = with_log_steps(load_topology(topology, steps=steps, log=str(log), mapping=str(mapping), estimator=estimator))
    res = run_inmemory(sc, seed=0, record=record)
    assert res.parts is not None
    return sc, record_from_parts(res.meta, res.parts["truth"], res.parts["nodes"], res.summary)


@pytest.fixture(scope="module")
def drive() -> DriveTable:
    return simulated_drive()


@pytest.fixture(scope="module")
def tmp(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("exact_gaps")


@pytest.fixture(scope="module")
def gapped(drive: DriveTable, tmp: Path) -> tuple[Path, Path]:
    d = tmp / "gapped"
    d.mkdir()
    return write(drive, d, GAPS)


@pytest.fixture(scope="module")
def sdp(gapped: tuple[Path, Path], tmp: Path) -> tuple[Scenario, Record]:
    """paper6's SDP network replayed from the drive with GAPS, its record also on file (the CLI's)."""
    return _replay("paper6", *gapped, record=str(tmp / "gapped.jsonl"))


@pytest.fixture(scope="module")
def limits(sdp: tuple[Scenario, Record]) -> dict[str, ExactBounds]:
    sc, rec = sdp
    return {mode: exact_bounds(sc, rec, mode, keep_witnesses=True) for mode in ("used", "all")}


def _check_witness(sc: Scenario, rec: Record, ex: ExactBounds, key: WitnessKey, wit: Witness) -> None:
    """The witness simulated with the project's model and sensors: every assumption holds, every reading there is is
    reproduced within its noise bound (none is asked of a missing one), and it reaches the bound."""
    data = step_data(rec)
    assert np.all(np.abs(wit.w) <= np.sqrt(sc.W) + WITNESS_TOL)
    for n in sc.nodes:
        e = np.r_[wit.x0, wit.f[n.id][0]] - n.x0_hat
        assert e @ np.linalg.solve(n.P0, e) <= n.rho + WITNESS_TOL, f"prior of node {n.id}"
        if n.id in ex.bounded_nodes:  # at every step, with or without a reading there
            assert np.all(np.abs(wit.f[n.id]) <= n.fault_size + WITNESS_TOL)
            assert np.all(np.abs(np.diff(wit.f[n.id])) <= n.fault_rate + WITNESS_TOL)
    x = wit.x0.copy()
    for j in range(key.step + 1):
        d = data[j]
        for n in sc.nodes:
            if n.id in d.no_reading:
                assert n.id not in d.y
                continue
            s = n.sensor
            v = (d.y[n.id] - d.gamma[n.id] * s.sigma(float(s.Cbar @ np.r_[x, wit.f[n.id][j]]))) / s.Dv
            assert v * v <= s.R + WITNESS_TOL, f"noise of node {n.id} at step {j}"
        if j < key.step:
            x = sc.model.step(x, d.u, float(wit.w[j]), d.vx)
    value = wit.f[key.node][key.step] if key.coordinate == "f" else x[0 if key.coordinate == "beta" else 1]
    assert value == pytest.approx(ex.interval(key.coordinate, key.node)[key.step, 0 if key.side == "lo" else 1], abs=WITNESS_TOL), key


@pytest.mark.parametrize("mode", ["used", "all"])
def test_every_end_has_a_witness_that_skips_only_the_missing_readings(sdp: tuple[Scenario, Record], limits: dict[str, ExactBounds], mode: str) -> None:
    """Before: refused ("the exact limit takes every reading").  ``all`` bounds a fault at its gap by its rate and size
    from the steps around it (finite ends, each with its witness); ``used`` leaves paper6's free faults unbounded there."""
    sc, rec = sdp
    ex = limits[mode]
    assert not ex.infeasible_steps and sorted(ex.no_reading) == MISSING
    finite = sum(int(np.isfinite(ex.interval(c, i)).sum()) for c in COORDINATES for i in sc.ids[: 1 if c != "f" else None])
    assert len(ex.witnesses) == finite
    for key, wit in ex.witnesses.items():
        _check_witness(sc, rec, ex, key, wit)
    for i, k in MISSING:
        f = ex.fault[i][k]
        assert np.isfinite(f).all() == (k == 0 or i in ex.bounded_nodes), (mode, i, k, f)  # step 0: the prior bounds it


def _direct(sc: Scenario, rec: Record, k: int, bounded: tuple[int, ...]) -> dict[tuple[str, int | None], tuple[float, float]]:
    """Horizon k's ends, the program written out from the assumptions with cvxpy: the scheduled dynamics, the wind, each
    node's prior, each reading there is (NSNIM, γ = 1: ỹ − C x − Ds f within ±|Dv|√R) and the declared fault bounds."""
    data = step_data(rec)
    x, f = cp.Variable((k + 1, 2)), {n.id: cp.Variable(k + 1) for n in sc.nodes}
    cons = []
    if k:
        w = cp.Variable(k)
        cons.append(cp.abs(w) <= np.sqrt(sc.W))
    for j in range(k):
        a, b, d = sc.model.blend(sc.model.weights(data[j].vx))
        cons.append(x[j + 1] == a @ x[j] + b[:, 0] * data[j].u + d[:, 0] * w[j])
    for n in sc.nodes:
        s = n.sensor
        cons.append(cp.quad_form(cp.hstack([x[0], f[n.id][:1]]) - n.x0_hat, np.linalg.inv(n.P0)) <= n.rho)
        for j in range(k + 1):
            if n.id in data[j].y:
                r, half = s.C @ x[j] + s.Ds * f[n.id][j], abs(s.Dv) * np.sqrt(s.R)
                cons += [r >= data[j].y[n.id] - half, r <= data[j].y[n.id] + half]
        if n.id in bounded:
            cons.append(cp.abs(f[n.id]) <= n.fault_size)
            if k:
                cons.append(cp.abs(cp.diff(f[n.id])) <= n.fault_rate)
    c = cp.Parameter(2 + len(sc.ids))
    z = cp.hstack([x[k], *(f[i][k : k + 1] for i in sc.ids)])
    problem = cp.Problem(cp.Minimize(c @ z), cons)
    keys: list[tuple[str, int | None]] = [("beta", None), ("r", None), *(("f", i) for i in sc.ids)]
    out = {}
    for m, key in enumerate(keys):
        ends = []
        for sign in (1.0, -1.0):
            c.value = np.eye(len(keys))[m] * sign
            problem.solve(solver=cp.CLARABEL)
            assert problem.status in ("optimal", "unbounded"), (key, problem.status)
            ends.append(sign * problem.value if problem.status == "optimal" else -sign * np.inf)
        out[key] = (ends[0], ends[1])
    return out


@pytest.mark.parametrize("mode", ["used", "all"])
def test_the_limit_is_the_program_written_out(sdp: tuple[Scenario, Record], limits: dict[str, ExactBounds], mode: FaultBoundsMode) -> None:
    """At the horizons of the gaps (step 0 of nodes 1 and 3; 4–6 of node 3; 8 of node 5) and the last one."""
    sc, rec = sdp
    assert sc.uncertainty is None  # (the direct program has no model-mismatch term)
    ex = limits[mode]
    for k in (0, 4, 6, 8, STEPS):
        for (coord, node), (lo, hi) in _direct(sc, rec, k, ex.bounded_nodes).items():
            got = ex.interval(coord, node)[k]  # type: ignore[arg-type]  # coord: one of COORDINATES
            for a, b in zip(got, (lo, hi)):
                assert (np.isinf(a) and a == b) or abs(a - b) <= DIRECT_TOL * max(1.0, abs(b)), (mode, k, coord, node, got, (lo, hi))


def test_a_gap_only_widens_the_limit(drive: DriveTable, tmp: Path, limits: dict[str, ExactBounds]) -> None:
    """The same drive with every reading: each end of the gapped limit lies outside or on its end, strictly outside at
    least at the gapped nodes' faults."""
    d = tmp / "full"
    d.mkdir()
    sc, rec = _replay("paper6", *write(drive, d, {}))
    wider = 0
    for mode in ("used", "all"):
        full, gapped = exact_bounds(sc, rec, mode), limits[mode]
        for coord in COORDINATES:
            for i in sc.ids:
                a, b = gapped.interval(coord, i), full.interval(coord, i)
                assert np.all(a[:, 0] <= b[:, 0] + 1e-8) and np.all(a[:, 1] >= b[:, 1] - 1e-8), (mode, coord, i)
        wider += sum(gapped.fault[i][k, 1] - gapped.fault[i][k, 0] > full.fault[i][k, 1] - full.fault[i][k, 0] + 1e-6 for i, k in MISSING)
    assert wider == 2 * len(MISSING)


def test_the_truth_is_inside_and_no_published_set_is_narrower(
    gapped: tuple[Path, Path], tmp: Path, sdp: tuple[Scenario, Record], limits: dict[str, ExactBounds]
) -> None:
    """Reference of accuracy 0: the truth lies in every exact interval.  The SDP network (nothing published at its gaps
    after step 0, resumed after) against ``used``; every family in one network (prediction-only sets at the gaps)
    against ``all``, whose fault bounds the set estimators rely on there: 0 narrower, every ratio ≥ 1."""
    sc, rec = sdp
    for t in rec.truth:
        k = t["step"]
        for mode, ex in limits.items():
            for coord, value, node in [("beta", t["x"][0], None), ("r", t["x"][1], None), *(("f", t["faults"][i], i) for i in sc.ids)]:
                lo, hi = ex.interval(coord, node)[k]  # type: ignore[arg-type]  # coord: one of COORDINATES
                assert lo - CONTAIN_TOL <= value <= hi + CONTAIN_TOL, (mode, coord, node, k)
    mixed_sc, mixed = _replay(mixed_topology(tmp, EVERY_FAMILY), *gapped)
    for record, ex in ((rec, limits["used"]), (mixed, exact_bounds(mixed_sc, mixed, "all"))):
        cmp = compare_record(record, ex)
        assert sum(n.ratios[c].narrower for n in cmp.nodes for c in COORDINATES) == 0
        assert all(n.ratios[c].width_ratio_all >= 1.0 for n in cmp.nodes for c in ("beta", "r"))
    assert {e["status"] for e in mixed.raw_nodes["3"] if e["step"] in GAPS[3]} == {"no-reading"}  # (interval: a prediction-only set)


@pytest.mark.parametrize(("fault_bounds", "tolerance"), [("used", 0.0), ("all", 0.02)])
def test_k_of_n_with_gaps_is_brute_force_over_every_hypothesis_sequence(drive: DriveTable, tmp: Path, fault_bounds: FaultBoundsMode, tolerance: float) -> None:
    """paper6_max_faulty's sensors 1, 3 and 5, at most one faulty, 4 steps, with node 1's reading missing at step 0,
    node 3's at 2 and node 5's at 1 and 3: a sensor without a reading is healthy or not on the whole line (its span),
    and the branch and bound over the unions gives brute force's ends (tests/inmemory/test_exact_kofn.py)."""
    d = tmp / f"kofn_{fault_bounds}"
    d.mkdir()
    full, rec = _replay("paper6_max_faulty", *write(drive, d, {1: (0,), 3: (2,), 5: (1, 3)}), steps=3)
    full = dataclasses.replace(full, health_groups=(HealthGroup(tuple(full.ids), 1),), fault_tolerance=tolerance)
    ex = exact_bounds(full, rec, fault_bounds, nodes=[1, 3, 5])
    assert ex.health is not None and ex.health.exact_ends == ex.health.ends and not ex.infeasible_steps
    assert sorted(ex.no_reading) == [(1, 0), (3, 2), (5, 1), (5, 3)]
    sc = dataclasses.replace(full, nodes=[n for n in full.nodes if n.id in (1, 3, 5)])
    brute = _brute_force(sc, rec, fault_bounds)
    for coord, node in [("beta", None), ("r", None), *(("f", i) for i in sc.ids)]:
        for k in range(4):
            lo, hi = brute.get((coord, node, k), (np.inf, -np.inf))  # none solved: unbounded (a free fault at its gap)
            got = ex.interval(coord, node)[k]  # type: ignore[arg-type]  # coord: one of COORDINATES
            want = (lo if np.isfinite(lo) else -np.inf, hi if np.isfinite(hi) else np.inf)
            for a, b in zip(got, want):
                assert (np.isinf(a) and a == b) or abs(a - b) <= AGREE, (coord, node, k, got, want)


def test_cli_exact_local_and_network_over_a_gapped_record(sdp: tuple[Scenario, Record], tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Exit 0 with ratios and the gaps named (before: exit 2, "a gap in the log"); the record's own topology with its
    log (plant "log"), so no --topology is needed."""
    path, out = str(tmp / "gapped.jsonl"), tmp / "exact.json"
    assert main(["exact", path, "--local", "--network", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"{len(MISSING)} node-step(s) without a reading (gaps in the log; nodes 1, 3, 5)" in text
    assert "overall: width ratio" in text and "published interval narrower than exact on 0 of" in text
    doc = json.loads(out.read_text())
    assert sorted(map(tuple, doc["no_reading"])) == MISSING and doc["ratios"]["overall_width_ratio"] >= 1.0
    assert len(doc["local_over_central"]) == 6 and set(doc["network"]["exact"]) == {str(i) for i in range(1, 7)}


def test_cli_a_reading_missing_without_saying_so_is_refused(sdp: tuple[Scenario, Record], tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A truth entry that lacks node 2's reading and does not list it in no_reading is damaged, not a gap."""
    rec = load_record(str(tmp / "gapped.jsonl"))
    truth = [dict(t) for t in rec.truth]
    truth[3]["y"] = {i: v for i, v in truth[3]["y"].items() if i != 2}
    path = str(tmp / "damaged.jsonl")
    save_record(path, rec.meta, truth, rec.raw_nodes, rec.summary)
    assert main(["exact", path]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "step 3 has measurements of nodes [1, 3, 4, 5, 6], the topology has nodes" in err, err
    assert "Traceback" not in err


def test_compare_over_a_gapped_log_gives_ratios(gapped: tuple[Path, Path], tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`compare` on a topology whose vehicle is the gapped drive: each row's ratio to the exact limit, none narrower
    (before: ExactError, exit 2)."""
    log, mapping = gapped
    text = (ROOT / "topologies/paper6.toml").read_text().replace('node_dir = "../nodes"', f'node_dir = "{ROOT / "nodes"}"')
    text = re.sub(r"(?m)^steps = \d+$", f"steps = {STEPS}", text)
    text = text.replace("[vehicle]", f'[vehicle]\nsource = "log"\nlog = "{log}"\nmapping = "{mapping}"', 1)
    topology = tmp / "paper6_gapped.toml"
    topology.write_text(text)
    c = compare(topology, ("sdp", "zonotope", "exact"))
    rows = {r.estimator: r for r in c.rows}
    assert rows["exact"].ratio_exact == pytest.approx(1.0)
    for name in ("sdp", "zonotope"):
        assert rows[name].ratio_exact is not None and rows[name].ratio_exact >= 1.0 and rows[name].narrower == 0, rows[name]
    assert main(["compare", str(topology), "--estimators", "sdp,exact"]) == 0
    assert "sdp" in capsys.readouterr().out
