"""A recorded drive over Zenoh (docs/your-log.md): ``netsetest run --mode zenoh --log BAG --map MAP`` in lockstep gives
the in-memory replay's verdicts node-step for node-step, and its sets to within rounding (the role processes' own
BLAS kernels: never compared bit for bit).  The drive is a simulated paper6 run written as a ROS 2 bag (MCAP) with an
INS-grade reference (so the truth is a box: contained, missed and undecided all possible) and gaps in two readings
(missing measurements: nothing published, neighbours told, the node resumes): the vehicle process streams the bag
and tells everyone; only it reads the log (the nodes and the collector are started with the steps `run` decided).
A real-time run from the same bag ends with every node-step judged or counted, and no violation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from zenoh_helpers import read_json, read_record, run_to_success

pytestmark = pytest.mark.zenoh
pytest.importorskip("rosbags")

STEPS = 12
GAPS = {3: range(4, 7), 5: range(8, 9)}  # node → steps without a reading
ACCURACY = (0.00262, 0.00175)  # ±0.15°, ±0.1 °/s: an INS
TOL = 1e-9


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    from netsetest.config.schema import load_topology
    from netsetest.logs.write import DriveTable, from_truth, mapping_toml, write_log
    from netsetest.runtime.inmemory import run_inmemory

    sc = load_topology("paper6", steps=STEPS)
    res = run_inmemory(sc, "worst", seed=3)
    assert res.parts is not None
    d = from_truth(res.parts["truth"], sc.tau_s, "synthetic: the Zenoh log test's simulated paper6 run")
    yaw, stamps = dict(d.yaw), {}
    for i, r in GAPS.items():
        keep = np.ones(d.t.size, dtype=bool)
        keep[list(r)] = False
        yaw[i], stamps[i] = d.yaw[i][keep], d.t[keep]
    d = DriveTable(d.t, d.speed, d.steering, yaw, d.beta, d.r, yaw_t=stamps, description=d.description)
    tmp = tmp_path_factory.mktemp("zenoh-log")
    bag = write_log(d, tmp / "drive_mcap", "rosbag-mcap")
    mapping = tmp / "drive.map.toml"
    mapping.write_text(mapping_toml(d, "rosbag-mcap", ACCURACY))
    return bag, mapping


@pytest.mark.timeout(150)
def test_a_lockstep_zenoh_run_from_a_log_gives_the_in_memory_verdicts(drive: tuple[Path, Path], tmp_path: Path) -> None:
    from netsetest.config.schema import load_topology
    from netsetest.logs.drive import with_log_steps
    from netsetest.runtime.inmemory import run_inmemory

    bag, mapping = drive
    rec, summ = tmp_path / "record.jsonl", tmp_path / "summary.json"
    logs = run_to_success(
        tmp_path / "logs",
        ["paper6", "--steps", str(STEPS), "--log", str(bag), "--map", str(mapping), "--record", str(rec), "--summary-json", str(summ)],
        timeout=100,
    )
    z, zs = read_record(rec), read_json(summ)
    m = run_inmemory(with_log_steps(load_topology("paper6", steps=STEPS, log=str(bag), mapping=str(mapping))), seed=0)
    assert m.parts is not None
    ms = m.summary.to_dict()

    assert zs["steps_completed"] == ms["steps_completed"] == STEPS
    for zt, mt in zip(z["truth"], m.parts["truth"], strict=True):
        assert zt["no_reading"] == mt["no_reading"] and zt["reference"] == mt["reference"], zt["step"]
        np.testing.assert_allclose(zt["x"], mt["x"], rtol=0, atol=TOL)
        assert zt["y"].keys() == mt["y"].keys()
    assert [t["no_reading"] for t in z["truth"]].count([3]) == 3 and [t["no_reading"] for t in z["truth"]].count([5]) == 1

    verdict = ("status", "resumed_from", "contained", "missed", "judged", "assumptions_ok", "not_covered_cause", "used", "missing")
    assert sorted(z["nodes"]) == sorted(m.parts["nodes"])
    for i, zes in z["nodes"].items():
        mes = m.parts["nodes"][i]
        assert [e["step"] for e in zes] == [e["step"] for e in mes] == [k for k in range(STEPS + 1) if k not in GAPS.get(int(i), ())]
        for ze, me in zip(zes, mes):
            assert {f: ze.get(f) for f in verdict} == {f: me.get(f) for f in verdict}, f"node {i} step {ze['step']}"
            np.testing.assert_allclose(ze["published"]["xhat"], me["published"]["xhat"], rtol=0, atol=TOL)
            np.testing.assert_allclose(ze["published"]["P"], me["published"]["P"], rtol=0, atol=TOL)
    counts = ("node_steps_evaluated", "node_steps_contained", "node_steps_missed", "node_steps_undecided", "node_steps_covered", "node_steps_no_reading")
    assert {c: zs[c] for c in counts} == {c: ms[c] for c in counts}, logs
    assert zs["node_steps_no_reading"] == 4 and zs["violations_total"] == 0 and zs["nodes_missing"] == []
    assert all(r["neighbour_messages_missing"] == 0 for r in zs["nodes"]), "a neighbour waited for a node without a reading"


@pytest.mark.timeout(150)
def test_every_family_without_readings_over_zenoh_gives_the_in_memory_verdicts(tmp_path: Path) -> None:
    """Every estimator family in one network (nodes 1 and 6 the SDP, 2 zonotope, 3 interval, 4 strip, 5 setprop), readings
    missing at step 0 (nodes 1, 3: the prior) and mid-drive (3: a set estimator's prediction-only steps, published;
    5 likewise): a lockstep Zenoh run gives the in-memory verdicts node-step for node-step, the steps without a reading
    named in the record (status no-reading, the truth's no_reading), containment on every one (accuracy 0)."""
    from gaps_helpers import EVERY_FAMILY, GAPS, STEPS as GAP_STEPS, check_gapped_run, gapped_drive

    from netsetest.config.schema import load_topology
    from netsetest.logs.drive import with_log_steps
    from netsetest.runtime.inmemory import run_inmemory
    from run_helpers import mixed_topology

    log, mapping = gapped_drive(tmp_path)
    topo = mixed_topology(tmp_path, EVERY_FAMILY)
    rec, summ = tmp_path / "record.jsonl", tmp_path / "summary.json"
    argv = [str(topo), "--steps", str(GAP_STEPS), "--log", str(log), "--map", str(mapping), "--record", str(rec), "--summary-json", str(summ)]
    logs = run_to_success(tmp_path / "logs", argv, timeout=100)
    z, zs = read_record(rec), read_json(summ)
    m = run_inmemory(with_log_steps(load_topology(topo, steps=GAP_STEPS, log=str(log), mapping=str(mapping))), seed=0)
    assert m.parts is not None
    check_gapped_run(m, {i: EVERY_FAMILY.get(i, "sdp") for i in range(1, 7)})
    assert [t["no_reading"] for t in z["truth"]] == [t["no_reading"] for t in m.parts["truth"]]
    verdict = ("status", "resumed_from", "contained", "missed", "judged", "assumptions_ok", "not_covered_cause", "used", "missing")
    assert sorted(z["nodes"]) == sorted(m.parts["nodes"])
    for i, zes in z["nodes"].items():
        mes = m.parts["nodes"][i]
        assert [e["step"] for e in zes] == [e["step"] for e in mes], f"node {i}"
        for ze, me in zip(zes, mes):
            assert {f: ze.get(f) for f in verdict} == {f: me.get(f) for f in verdict}, f"node {i} step {ze['step']}"
            np.testing.assert_allclose(ze["bounds"], me["bounds"], rtol=0, atol=TOL)
    counts = ("node_steps_evaluated", "node_steps_contained", "node_steps_covered", "node_steps_no_reading", "violations_total")
    assert {c: zs[c] for c in counts} == {c: m.summary.to_dict()[c] for c in counts}, logs
    assert zs["node_steps_no_reading"] == sum(map(len, GAPS.values())) and zs["violations_total"] == 0 and zs["nodes_missing"] == []


@pytest.mark.timeout(150)
def test_a_realtime_zenoh_run_from_a_log(drive: tuple[Path, Path], tmp_path: Path) -> None:
    bag, mapping = drive
    summ = tmp_path / "summary.json"
    run_to_success(
        tmp_path / "logs",
        ["paper6", "--steps", str(STEPS), "--clock", "realtime", "--log", str(bag), "--map", str(mapping), "--summary-json", str(summ)],
        timeout=100,
    )
    s = read_json(summ)
    assert s["clock"] == "realtime" and s["violations_total"] == 0 and s["node_steps_no_reading"] == 4
    judged = s["node_steps_evaluated"] + s["node_steps_overloaded"] + s["node_steps_no_reading"] + sum(r["missing_steps"] for r in s["nodes"])
    assert judged == 6 * (STEPS + 1), s


@pytest.mark.timeout(150)
def test_every_family_without_readings_in_real_time(tmp_path: Path) -> None:
    """The same mixed network and gaps on the real-time clock: no node waits for a reading at a step without its own
    (nor counts a reference silent for it), every node-step is judged or counted, no violation."""
    from gaps_helpers import EVERY_FAMILY, GAPS, STEPS as GAP_STEPS, gapped_drive
    from run_helpers import mixed_topology

    log, mapping = gapped_drive(tmp_path)
    summ = tmp_path / "summary.json"
    argv = [str(mixed_topology(tmp_path, EVERY_FAMILY)), "--steps", str(GAP_STEPS), "--clock", "realtime", "--log", str(log), "--map", str(mapping)]
    run_to_success(tmp_path / "logs", [*argv, "--summary-json", str(summ)], timeout=100)
    s = read_json(summ)
    assert s["violations_total"] == 0 and s["node_steps_no_reading"] == sum(map(len, GAPS.values()))
    silent_sdp = sum(1 for i, ks in GAPS.items() if i not in EVERY_FAMILY for k in ks if k > 0)
    accounted = s["node_steps_evaluated"] + s["node_steps_overloaded"] + silent_sdp + sum(r["missing_steps"] for r in s["nodes"])
    assert accounted == 6 * (GAP_STEPS + 1), s
