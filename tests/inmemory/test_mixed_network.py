"""Mixed networks: nodes running different guaranteed estimators side by side.

Nodes 1–3 run the SDP, 4 the zonotope, 5 the interval and 6 the strip observer (paper6, saim: three
saturating sensors).  A non-SDP node publishes its own set and an enclosing ellipsoid; the collector
judges the set and records its bounds.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import msgpack
import numpy as np
import pytest
from run_helpers import MIXED, mixed_topology

from netsetest.config.schema import ConfigError, load_topology
from netsetest.messages import NodeState, decode, encode
from netsetest.records.record import load_record
from netsetest.roles.node import enclosing_ellipsoid
from netsetest.runtime.inmemory import run_inmemory
from netsetest.sets import Box, Zonotope, set_to_wire
from message_helpers import make_state

ROOT = Path(__file__).resolve().parents[2]
STEPS = 40


@pytest.fixture(scope="module")
def mixed_run(tmp_path_factory: pytest.TempPathFactory):
    d = tmp_path_factory.mktemp("mixed")
    sc = load_topology(mixed_topology(d), "saim", STEPS)
    rec = d / "run.json"
    res = run_inmemory(sc, "paper", "scheduled", seed=1, record=str(rec))
    return sc, res, load_record(rec), rec


def test_topology_field_and_override(tmp_path: Path) -> None:
    sc = load_topology(mixed_topology(tmp_path))
    assert [n.estimator for n in sc.nodes] == ["sdp", "sdp", "sdp", "zonotope", "interval", "strip"]
    assert {n.estimator for n in load_topology(mixed_topology(tmp_path), estimator="setprop").nodes} == {"setprop"}
    with pytest.raises(ConfigError, match="estimator"):
        load_topology(mixed_topology(tmp_path, {2: "exact"}))  # a comparison row, not a node's estimator
    with pytest.raises(ConfigError, match="estimator"):
        load_topology("paper6", estimator="nope")


def test_mixed_network_contained_where_assumptions_held(mixed_run) -> None:
    sc, res, rec, _ = mixed_run
    s = res.summary
    assert s.violations_total == 0
    assert s.node_steps_evaluated == 6 * (STEPS + 1)
    assert s.node_steps_covered > 0.9 * s.node_steps_evaluated  # the guarantee actually covered them
    rows = {r.id: r for r in s.nodes}
    assert {i: rows[i].estimator for i in MIXED} == MIXED
    assert rec.meta.estimators == {n.id: n.estimator for n in sc.nodes}
    truth = {t["step"]: t for t in rec.truth}
    for i, entries in rec.raw_nodes.items():
        for e in entries:
            t = truth[e["step"]]
            xbar = np.r_[t["x"], t["faults"][int(i)]]
            b = np.asarray(e["bounds"])  # every node's published set: a set estimator's, the SDP's ellipsoid ∩ range ∩ region
            inside = bool(np.all(b[:, 0] <= xbar) and np.all(xbar <= b[:, 1]))
            assert inside or not e["contained"]  # the set is inside its interval hull
            if e["assumptions_ok"]:
                assert e["contained"], f"node {i} step {e['step']}: missed inside its cone"
            if int(i) not in MIXED:
                continue  # an SDP node: its box is of the ellipsoid ∩ its region, within the ellipsoid's box
            # the published ellipsoid (a set estimator's neighbour-facing summary) encloses the box
            P = np.asarray(e["published"]["P"]).reshape(3, 3)
            for corner in np.array(np.meshgrid(*b)).T.reshape(-1, 3):
                d = corner - np.asarray(e["published"]["xhat"])
                assert d @ np.linalg.solve(P, d) <= e["published"]["rho"] * (1 + 1e-9)


def test_inspect_uses_the_set_bounds(mixed_run) -> None:
    *_, path = mixed_run
    out = subprocess.run([sys.executable, "-m", "netsetest.cli.main", "inspect", str(path), "--node", "5"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr


def test_enclosing_ellipsoid_contains_the_set() -> None:
    rng = np.random.default_rng(0)
    z = Zonotope(np.array([0.1, -0.2, 0.3]), rng.normal(size=(3, 7)))
    for rho in (1.0, 0.3):
        c, P = enclosing_ellipsoid(z, rho)
        for _ in range(500):
            x = z.center + z.generators @ rng.uniform(-1, 1, 7)
            assert (x - c) @ np.linalg.solve(P, x - c) <= rho
    flat = Box(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.5, 2.0]))  # flat coordinates: still definite
    c, P = enclosing_ellipsoid(flat, 1.0)
    assert np.all(np.linalg.eigvalsh(P) > 0)
    assert (flat.hi - c) @ np.linalg.solve(P, flat.hi - c) <= 1.0


def _state(**kw) -> NodeState:
    base = dict(step=1, node=1, xhat=[0.0, 0.0, 0.0], P=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], rho=1.0, gamma=1.0, innov=0.0, status="ok")
    return make_state(**{**base, **kw})


def test_wire_set_field() -> None:
    assert "set" not in msgpack.unpackb(encode(_state()), raw=False)["published"]  # the SDP sends no set
    box = Box(np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0]))
    back = decode(encode(_state(set=set_to_wire(box))))
    assert isinstance(back.published.own_set, Box)
    raw = msgpack.unpackb(encode(_state(set=set_to_wire(box))), raw=False)
    raw["published"]["set"] = {"type": "box", "lo": [0.0, 0.0], "hi": [1.0, 1.0]}  # wrong dimension: dropped at decode
    with pytest.raises(Exception, match="invalid"):
        decode(msgpack.packb(raw, use_bin_type=True))


def test_record_uses_the_set_bounds(mixed_run) -> None:
    *_, rec, path = mixed_run
    for i in MIXED:
        rows = rec.fault_rows(i)
        entries = rec.raw_nodes[str(i)]
        assert [[r["fault_lower"], r["fault_upper"]] for r in rows] == [e["bounds"][2] for e in entries]
    sdp = rec.nodes[1]  # an SDP node: its published set's bounds, and its ellipsoid's alone beside them
    assert sdp.set_bounds is not None
    assert np.array_equal(sdp.bounds(2)[0], [e["bounds"][2][0] for e in rec.raw_nodes["1"]])
    lo, _ = sdp.ellipsoid_bounds(2)
    assert np.allclose(lo, sdp.xhat[:, 2] - np.sqrt(sdp.rho * sdp.P[:, 2, 2]))
    assert np.all(sdp.bounds(2)[0] >= lo - 1e-12)


def test_simulate_estimator_and_mcap(tmp_path: Path) -> None:
    import netsetest

    res = netsetest.simulate("paper6", steps=8, estimator="interval")
    assert res.summary.violations_total == 0
    assert {r.estimator for r in res.summary.nodes} == {"interval"}
    with pytest.raises(ConfigError, match="estimator"):
        netsetest.simulate("paper6", steps=2, estimator="exact")
    path = tmp_path / "run.mcap"
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "netsetest.cli.main",
            "run",
            "paper6",
            "--mode",
            "inmemory",
            "--quiet",
            "--steps",
            "6",
            "--estimator",
            "zonotope",
            "--record",
            str(path),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    rec = load_record(path)
    assert all(tr.set_bounds is not None for tr in rec.nodes.values())
    bad = subprocess.run(
        [sys.executable, "-m", "netsetest.cli.main", "run", "paper6", "--mode", "inmemory", "--estimator", "nope"], capture_output=True, text=True, timeout=60
    )
    assert bad.returncode == 2 and "Traceback" not in bad.stderr


def test_estimator_refusing_a_node_is_a_config_error(tmp_path: Path) -> None:
    nodes = tmp_path / "nodes"
    nodes.mkdir()
    for f in (ROOT / "nodes").glob("*.toml"):
        text = f.read_text()
        if f.stem == "yaw6":  # no declared fault bound: the strip observer needs one
            text = re.sub(r"\[fault_bound\][^\n]*\nrate = [^\n]*\nsize = [^\n]*\n", "", text)
            assert "[fault_bound]" not in text
        (nodes / f.name).write_text(text)
    topo = mixed_topology(tmp_path).read_text().replace(f'node_dir = "{ROOT / "nodes"}"', f'node_dir = "{nodes}"')
    path = tmp_path / "refused.toml"
    path.write_text(topo)
    with pytest.raises(ConfigError, match="node 6: estimator 'strip'"):
        run_inmemory(load_topology(path, steps=2), "paper", "scheduled", seed=0)
    out = subprocess.run(
        [sys.executable, "-m", "netsetest.cli.main", "run", str(path), "--mode", "inmemory", "--steps", "2"], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 2 and "node 6" in out.stderr and "Traceback" not in out.stderr


def test_set_estimator_refusing_a_step_falls_back(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """A step whose measurement contradicts the set (only after a broken assumption): the node publishes
    its last set marked ``fallback`` and the run goes on; the collector still judges it."""
    from netsetest.estimator.base import EstimatorError
    from netsetest.estimator.interval_althoff_rath import IntervalObserver

    step = IntervalObserver.step

    def refuse_step_3(self, inp, neighbours=()):
        if inp.step == 3:
            raise EstimatorError("the measurement is inconsistent with the set (an assumption broke)")
        return step(self, inp, neighbours)

    monkeypatch.setattr(IntervalObserver, "step", refuse_step_3)
    res = run_inmemory(load_topology(mixed_topology(tmp_path), steps=6), "paper", "scheduled", seed=0, keep=True)
    entries = res.parts["nodes"]["5"]
    assert [e["status"] for e in entries] == ["init", "ok", "ok", "fallback", "ok", "ok", "ok"]
    assert entries[3]["bounds"] == entries[2]["bounds"]
    row = res.summary.node(5)
    assert row.fallbacks == 1
    # the previous step's set again is no guarantee for this step: judged, but never as covered
    assert entries[3]["judged"] and not entries[3]["assumptions_ok"] and entries[3]["not_covered_cause"] == "fallback"
    assert res.summary.node_steps_not_covered.get("fallback") == 1


def test_set_node_cannot_be_killed_and_rejoined(tmp_path: Path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "netsetest.cli.main", "run", str(mixed_topology(tmp_path)), "--insecure", "--steps", "4", "--kill", "5@2", "--rejoin", "5@3"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "cannot rejoin" in out.stderr and "Traceback" not in out.stderr


def test_compare_on_a_mixed_topology_runs_the_sdp(tmp_path: Path) -> None:
    from netsetest.analysis.compare import compare

    cmp = compare(mixed_topology(tmp_path), estimators=("sdp", "interval"), steps=8)
    rows = {r.estimator: r for r in cmp.rows}
    assert rows["sdp"].violations == rows["interval"].violations == 0
    assert rows["sdp"].node_steps == rows["interval"].node_steps == 6 * 9
    sdp = netsetest_simulate_all_sdp(mixed_topology(tmp_path), steps=8)
    for i in MIXED:  # the sdp row of a mixed topology is the SDP's, not the file's node estimators
        np.testing.assert_allclose(cmp.bounds["sdp"][i][:, 2, 0], sdp.nodes[i].lower[:, 2], rtol=0, atol=1e-12)


def netsetest_simulate_all_sdp(topology: Path, steps: int):
    import netsetest

    return netsetest.simulate(topology, steps=steps, estimator="sdp")


def test_live_table_shows_the_set_bounds(tmp_path: Path) -> None:
    from netsetest.bus.base import MemoryBus
    from netsetest.runtime.live import LiveTable, observed_key

    bus = MemoryBus()
    table = LiveTable()
    bus.subscribe(observed_key("mem", None), lambda key, msg: table.update(msg))
    res = run_inmemory(load_topology(mixed_topology(tmp_path), steps=5), bus=bus)
    rows = {r.id: r for r in table.sorted_rows()}
    for i in MIXED:
        last = res.parts["nodes"][str(i)][-1]
        assert [rows[i].fault_lower, rows[i].fault_upper] == last["bounds"][2]


def test_inspect_labels_a_set_estimators_bounds_as_what_they_are(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A zonotope node's bounds are its set's interval hull, not an ellipsoid's f̂ ± √(ρ P33)."""
    from netsetest.cli.main import main

    rec = tmp_path / "r.json"
    run_inmemory(load_topology(mixed_topology(tmp_path), steps=3), "paper", "scheduled", seed=0, record=str(rec))
    assert main(["inspect", str(rec)]) == 0
    out = capsys.readouterr().out
    assert "node 1: fault estimate f̂ (its ellipsoid's centre) and bounds: the ellipsoid {x̄: (x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ}'s extent in f" in out
    for i in MIXED:
        assert f"node {i} ({MIXED[i]}): fault bounds of its published set (interval hull)" in out


@pytest.mark.parametrize("estimator", ["zonotope", "interval", "strip", "setprop"])
def test_set_estimators_on_saturating_sensors_without_a_fault_bound_are_refused(estimator: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """zonotope fell back to its previous set at the first saturated reading and failed the run with 441
    false violations; interval raised a traceback. Every set estimator now refuses the set-up, exit 2."""
    from netsetest.cli.main import main

    (tmp_path / "topologies").mkdir()
    shutil.copy(ROOT / "topologies" / "paper6.toml", tmp_path / "topologies" / "paper6.toml")
    shutil.copytree(ROOT / "nodes", tmp_path / "nodes")
    for prof in (tmp_path / "nodes").glob("*.toml"):
        prof.write_text(re.sub(r"\[fault_bound\][^\[]*", "", prof.read_text()))
    topo = tmp_path / "topologies" / "paper6.toml"
    assert main(["run", str(topo), "--mode", "inmemory", "--case", "saim", "--signals", "worst", "--steps", "3", "--estimator", estimator]) == 2
    err = capsys.readouterr().err
    assert "fault" in err and f"{estimator!r}" in err and "Traceback" not in err
