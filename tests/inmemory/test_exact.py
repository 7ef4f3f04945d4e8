"""`netsetest exact`: witnesses reproduce the data, the truth is inside, records are never narrower."""

from __future__ import annotations

import dataclasses

import json
from pathlib import Path
from functools import cache

import numpy as np
import pytest
from run_helpers import recorded_run

from netsetest.analysis.exact import (
    COORDINATES,
    ExactBounds,
    ExactError,
    Witness,
    WitnessKey,
    compare_record,
    exact_bounds,
    step_data,
)
from netsetest.cli.main import main
from netsetest.config.schema import Scenario, load_topology
from netsetest.records.record import Record, save_record

PAPER6 = "topologies/paper6.toml"
STEPS = 16
# Clarabel stops at 1e-10 relative gap/feasibility; witnesses meet every bound to ~5e-10 (80-step SAIM); this is the slack allowed
WITNESS_TOL = 1e-8
# the published interval is a numerically certified ellipsoid; it may touch the exact one to rounding
CONTAIN_TOL = 1e-9


def _run(case: str, signals: str, seed: int, tmp: str) -> tuple[Scenario, Record]:
    return recorded_run(case, signals, seed, STEPS, tmp)


@pytest.fixture(scope="module")
def tmp(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(tmp_path_factory.mktemp("exact"))


@cache
def _exact(case: str, signals: str, seed: int, tmp: str, mode: str = "used") -> ExactBounds:
    sc, rec = _run(case, signals, seed, tmp)
    return exact_bounds(sc, rec, mode, keep_witnesses=True)


def _coordinate(x: np.ndarray, f: dict[int, float], key: WitnessKey) -> float:
    return f[key.node] if key.coordinate == "f" else x[0 if key.coordinate == "beta" else 1]


def _check_witness(sc: Scenario, rec: Record, ex: ExactBounds, key: WitnessKey, wit: Witness) -> None:
    """Simulate the witness with the project's model and sensor code; check every bound and datum."""
    data = step_data(rec)
    sqrt_w = np.sqrt(sc.W)
    assert len(wit.w) == key.step
    assert np.all(np.abs(wit.w) <= sqrt_w + WITNESS_TOL)
    for n in sc.nodes:
        e = np.r_[wit.x0, wit.f[n.id][0]] - n.x0_hat
        assert e @ np.linalg.solve(n.P0, e) <= n.rho + WITNESS_TOL, f"prior of node {n.id}"
        f = wit.f[n.id]
        if n.id in ex.bounded_nodes:
            if n.fault_size is not None:
                assert np.all(np.abs(f) <= n.fault_size + WITNESS_TOL)
            if n.fault_rate is not None:
                assert np.all(np.abs(np.diff(f)) <= n.fault_rate + WITNESS_TOL)
    x = wit.x0.copy()
    for j in range(key.step + 1):
        d = data[j]
        for n in sc.nodes:
            s = n.sensor
            xbar = np.r_[x, wit.f[n.id][j]]
            # the noise that reproduces the measurement exactly, and it must be within its bound
            v = (d.y[n.id] - d.gamma[n.id] * s.sigma(float(s.Cbar @ xbar))) / s.Dv
            assert v * v <= s.R + WITNESS_TOL, f"noise of node {n.id} at step {j}: {v * v} > {s.R}"
            assert abs(s.measure(xbar, d.gamma[n.id], v) - d.y[n.id]) <= 1e-12
        if j < key.step:
            x = sc.model.step(x, d.u, float(wit.w[j]), d.vx)
    value = _coordinate(x, {i: f[key.step] for i, f in wit.f.items()}, key)
    bound = ex.interval(key.coordinate, key.node)[key.step, 0 if key.side == "lo" else 1]
    assert value == pytest.approx(bound, abs=WITNESS_TOL), f"witness does not reach {key}"


@pytest.mark.parametrize(("case", "signals", "seed"), [("nsnim", "paper", 0), ("saim", "worst", 1), ("saim", "paper", 0)])
def test_every_bound_has_a_witness(case: str, signals: str, seed: int, tmp: str) -> None:
    sc, rec = _run(case, signals, seed, tmp)
    ex = _exact(case, signals, seed, tmp)
    assert not ex.infeasible_steps
    finite = sum(int(np.isfinite(ex.interval(c, i)).sum()) for c in COORDINATES for i in sc.ids[: 1 if c != "f" else None])
    assert len(ex.witnesses) == finite == (STEPS + 1) * 2 * (2 + len(sc.ids))
    for key, wit in ex.witnesses.items():
        _check_witness(sc, rec, ex, key, wit)


@pytest.mark.parametrize(
    ("case", "signals", "seed", "mode"),
    [("nsnim", "paper", 0, "used"), ("nsnim", "worst", 1, "all"), ("saim", "worst", 1, "used"), ("saim", "paper", 2, "none")],
)
def test_truth_inside_every_exact_interval(case: str, signals: str, seed: int, mode: str, tmp: str) -> None:
    sc, rec = _run(case, signals, seed, tmp)
    ex = _exact(case, signals, seed, tmp, mode)
    for t in rec.truth:
        k = t["step"]
        assert all(t["noise_ok"].values()) and t["dist_ok"]
        for coord, value, node in [("beta", t["x"][0], None), ("r", t["x"][1], None)] + [("f", t["faults"][i], i) for i in sc.ids]:
            lo, hi = ex.interval(coord, node)[k]
            assert lo - CONTAIN_TOL <= value <= hi + CONTAIN_TOL, f"{coord} node {node} step {k}: {value} ∉ [{lo}, {hi}]"


def test_declared_fault_bounds_hold_in_the_paper_profiles(tmp: str) -> None:
    """The truth must satisfy the declared bounds the exact program uses (else the tests above mean little)."""
    sc, rec = _run("saim", "paper", 0, tmp)
    faults = {i: np.array([t["faults"][i] for t in rec.truth]) for i in sc.ids}
    for n in sc.nodes:
        assert np.abs(faults[n.id]).max() <= n.fault_size
        assert np.abs(np.diff(faults[n.id])).max() <= n.fault_rate


def _assert_not_narrower(rec: Record, ex: ExactBounds) -> None:
    for i, track in rec.nodes.items():
        for idx, coord in enumerate(COORDINATES):
            lo, hi = track.bounds(idx)
            e = ex.interval(coord, i)[track.steps]
            assert np.all(lo <= e[:, 0] + CONTAIN_TOL), f"node {i} {coord}: published lower bound above exact"
            assert np.all(hi >= e[:, 1] - CONTAIN_TOL), f"node {i} {coord}: published upper bound below exact"


@pytest.mark.parametrize(("signals", "seed"), [("paper", 0), ("worst", 1), ("worst", 2)])
def test_nsnim_record_never_narrower_than_exact(signals: str, seed: int, tmp: str) -> None:
    sc, rec = _run("nsnim", signals, seed, tmp)
    ex = _exact("nsnim", signals, seed, tmp)
    assert all(tr.assumptions_ok.all() for tr in rec.nodes.values())
    _assert_not_narrower(rec, ex)
    cmp = compare_record(rec, ex)
    assert min(n.ratios[c].width_ratio_all for n in cmp.nodes for c in COORDINATES) >= 1.0
    assert sum(n.ratios[c].narrower for n in cmp.nodes for c in COORDINATES) == 0


def test_a_shrunk_record_is_reported_narrower(tmp: str) -> None:
    """Shrinking every published set to a quarter of its width must show up as narrower than exact."""
    sc, rec = _run("nsnim", "paper", 0, tmp)
    ex = _exact("nsnim", "paper", 0, tmp)
    for track in rec.nodes.values():
        track.P[:] = track.P / 16
        assert track.set_bounds is not None  # the published set's bounds (the ellipsoid ∩ the fault range ∩ the region)
        mid, half = track.set_bounds.mean(axis=2, keepdims=True), np.diff(track.set_bounds, axis=2) / 2
        track.set_bounds[:] = mid + np.concatenate([-half, half], axis=2) / 4
    cmp = compare_record(rec, ex)
    assert all(n.ratios["f"].narrower > STEPS // 2 for n in cmp.nodes)
    assert cmp.mean_width_ratio["f"] < 0.5
    recorded_run.cache_clear()  # the record object was changed in place


@pytest.mark.parametrize(("signals", "seed"), [("paper", 0), ("worst", 1)])
def test_saim_record_never_narrower_than_exact(signals: str, seed: int, tmp: str) -> None:
    sc, rec = _run("saim", signals, seed, tmp)
    _assert_not_narrower(rec, _exact("saim", signals, seed, tmp))


def test_free_fault_elimination_is_exact(tmp: str) -> None:
    """The reduced program (past free faults dropped) gives the bounds of the whole program."""
    for case in ("nsnim", "saim"):
        sc, rec = _run(case, "worst", 1, tmp)
        for mode in ("used", "none"):
            a = exact_bounds(sc, rec, mode)
            b = exact_bounds(sc, rec, mode, eliminate_free_faults=False)
            for coord in COORDINATES:
                for i in sc.ids:
                    np.testing.assert_allclose(a.interval(coord, i), b.interval(coord, i), atol=1e-7)


def test_saturation_opens_a_side_without_fault_bounds(tmp: str) -> None:
    """With no fault bound, a measurement at the saturation limit leaves one side of the fault free."""
    sc, rec = _run("saim", "paper", 0, tmp)
    ex = _exact("saim", "paper", 0, tmp, "none")
    data = step_data(rec)
    for n in sc.nodes:
        for k, d in enumerate(data):
            lo, hi = n.sensor.measured_interval(d.y[n.id], d.gamma[n.id])
            f = ex.fault[n.id][k]
            if k > 0:  # past step 0 only the measurement bounds the fault (the prior bounds f_i,0)
                assert np.isfinite(f[0]) == np.isfinite(lo if n.sensor.Ds > 0 else hi)
                assert np.isfinite(f[1]) == np.isfinite(hi if n.sensor.Ds > 0 else lo)
    assert any(not np.isfinite(ex.fault[i]).all() for i in sc.ids), "this run never saturates at the limit"
    with_bounds = _exact("saim", "paper", 0, tmp, "used")
    assert all(np.isfinite(with_bounds.fault[i]).all() for i in sc.ids)


def test_nsnim_fault_interval_is_the_measurement_minus_the_state_set(tmp: str) -> None:
    """DESIGN §6: with free faults, f_i,k = (ỹ − C_i x_k − Dv v)/Ds over the open-loop state set (k ≥ 1)."""
    sc, rec = _run("nsnim", "paper", 0, tmp)
    ex = _exact("nsnim", "paper", 0, tmp)
    data = step_data(rec)
    n = sc.node(3)  # C = [0, c]: only r enters, so the state box gives the exact range of C x
    assert n.sensor.C[0] == 0
    for k in range(1, STEPS + 1):
        lo, hi = n.sensor.measured_interval(data[k].y[n.id], 1.0)
        cr = n.sensor.C[1] * ex.r[k]
        expect = sorted(((lo - cr.max()) / n.sensor.Ds, (hi - cr.min()) / n.sensor.Ds))
        np.testing.assert_allclose(ex.fault[n.id][k], expect, atol=1e-8)


def test_cli_prints_ratios_and_writes_json(tmp: str, capsys: pytest.CaptureFixture[str]) -> None:
    sc, rec = _run("nsnim", "paper", 0, tmp)
    out = f"{tmp}/exact.json"
    assert main(["exact", rec.path, "--json", out, "--topology", PAPER6]) == 0
    text = capsys.readouterr().out
    assert "relative-RMS radius" in text and "overall" in text
    doc = json.load(open(out))
    assert doc["format"] == "netsetest-exact" and doc["version"] == 3 and doc["fault_bounds"] == "used"
    assert len(doc["exact"]["fault"]["1"]) == STEPS + 1 == len(doc["steps"])
    ex = _exact("nsnim", "paper", 0, tmp)
    assert doc["exact"]["fault"]["2"][5] == pytest.approx(list(ex.fault[2][5]))
    assert doc["ratios"]["overall_width_ratio"] > 1


def test_cli_unbounded_side_is_null_in_json(tmp: str, capsys: pytest.CaptureFixture[str]) -> None:
    sc, rec = _run("saim", "paper", 0, tmp)
    out = f"{tmp}/exact-none.json"
    assert main(["exact", rec.path, "--json", out, "--fault-bounds", "none"]) == 0
    assert "left out" in capsys.readouterr().out
    doc = json.load(open(out))
    assert any(v is None for a in doc["exact"]["fault"].values() for iv in a for v in iv)


def test_cli_bad_input(tmp: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["exact", f"{tmp}/missing.json"]) == 2
    assert "file not found" in capsys.readouterr().err
    sc, rec = _run("nsnim", "paper", 0, tmp)
    assert main(["exact", rec.path, "--topology", f"{tmp}/nope.toml"]) == 2
    assert "nope.toml: file not found" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["exact", rec.path, "--fault-bounds", "some"])
    assert exc.value.code == 2


def test_record_and_topology_must_match(tmp: str) -> None:
    sc, rec = _run("nsnim", "paper", 0, tmp)
    other = load_topology(PAPER6, "nsnim", STEPS)
    fewer = type(other)(**{**other.__dict__, "nodes": other.nodes[:3]})
    with pytest.raises(ExactError, match="topology has nodes"):
        exact_bounds(fewer, rec)


def test_cli_refuses_a_topology_the_record_was_not_run_on(tmp: str, capsys: pytest.CaptureFixture[str]) -> None:
    """`exact REC --topology OTHER` once ran and exited 0 with bounds for another car: refused, exit 2, in
    one line naming the fields that differ; the record's own topology still runs."""
    sc, rec = _run("nsnim", "paper", 0, tmp)
    assert main(["exact", rec.path, "--topology", "topologies/paper6_car.toml"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "not run on topology topologies/paper6_car.toml" in err
    assert "plant (record 'ts', topology 'single-track/2')" in err and "model_uncertainty" in err
    assert main(["exact", rec.path, "--topology", PAPER6]) == 0
    capsys.readouterr()
    # what the meta does not hold (here the k-of-N declaration) the settings digest tells apart
    assert main(["exact", rec.path, "--topology", "topologies/paper6_max_faulty.toml"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "its other values" in err and "settings digest" in err
    # a copy under another name and path, its profiles elsewhere, is the same topology
    text = Path(PAPER6).read_text().replace('node_dir = "../nodes"', f'node_dir = "{Path("nodes").resolve()}"')
    copy = Path(tmp) / "renamed.toml"
    copy.write_text(text.replace('name = "paper6"', 'name = "renamed"'))
    assert main(["exact", rec.path, "--topology", str(copy)]) == 0
    capsys.readouterr()


def test_cli_record_naming_a_missing_topology(tmp: str, capsys: pytest.CaptureFixture[str]) -> None:
    sc, rec = _run("nsnim", "paper", 0, tmp)
    meta = dataclasses.replace(rec.meta, topology=f"{tmp}/moved.toml")
    path = f"{tmp}/moved-record.json"
    save_record(path, meta, rec.truth, rec.raw_nodes, rec.summary)
    assert main(["exact", path]) == 2
    err = capsys.readouterr().err
    assert "moved.toml" in err and "--topology" in err and len(err.strip().splitlines()) == 1
    truth = [dict(t) for t in rec.truth]
    del truth[3]["y"]
    save_record(path, meta, truth, rec.raw_nodes, rec.summary)
    assert main(["exact", path, "--topology", PAPER6]) == 2
    assert "malformed truth entry" in capsys.readouterr().err


def test_local_limit_contains_the_centralized_one(tmp: str) -> None:
    """One node's own data only (a purely local estimator's limit) is never tighter than all nodes'."""
    sc, rec = _run("nsnim", "worst", 1, tmp)
    central = _exact("nsnim", "worst", 1, tmp)
    for i in (1, 4):
        local = exact_bounds(sc, rec, nodes=[i])
        assert list(local.fault) == [i]
        for coord in COORDINATES:
            lo, ce = local.interval(coord, i), central.interval(coord, i)
            assert np.all(lo[:, 0] <= ce[:, 0] + 1e-8) and np.all(lo[:, 1] >= ce[:, 1] - 1e-8)
        assert (local.fault[i][0, 1] - local.fault[i][0, 0]) > 1.01 * (central.fault[i][0, 1] - central.fault[i][0, 0])
    with pytest.raises(ExactError, match="subset"):
        exact_bounds(sc, rec, nodes=[99])
