"""A recorded drive as the world (issue 42, docs/your-log.md).

Round trip: a simulated run's truth and readings, written as a ROS 2 bag (MCAP and sqlite3), MDF4, Parquet and CSV by
those libraries (netsetest/logs/write.py) and replayed with a reference of accuracy 0, give the simulated run's
verdicts node-step for node-step.  A reference of some accuracy gives three counts and never calls an undecided
step contained.  Bad logs (a wrong unit, a missing channel, a topic the bag lacks, a truncated or corrupted file, a
log shorter than the run): exit 2 with one clear line, never a traceback.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from run_helpers import shared_run

from netsetest.cli.main import main
from netsetest.config.schema import load_topology
from netsetest.logs.drive import with_log_steps
from netsetest.logs.write import WRITE_FORMATS, DriveTable, from_truth, log_path, mapping_toml, write_log
from netsetest.runtime.inmemory import RunResult, run_inmemory

STEPS = 12  # enough for the faults of paper6 to start (f1 from step 5); each replay under a second of CPU


def _verdicts(res: RunResult) -> dict[tuple[int, int], tuple]:
    assert res.parts is not None
    return {(i, e["step"]): (e["contained"], e["missed"], e["assumptions_ok"], e["not_covered_cause"]) for i, es in res.parts["nodes"].items() for e in es}


@pytest.fixture(scope="module")
def simulated() -> tuple[RunResult, DriveTable]:
    res = shared_run("nsnim", "worst", 3, STEPS)  # made once per worker: test_calibrate_logs drives it too
    assert res.parts is not None
    return res, from_truth(res.parts["truth"], 0.1, "synthetic: the round-trip test's simulated paper6 run")


def _write(d: DriveTable, tmp: Path, fmt: str, accuracy: tuple[float, float] | None) -> tuple[Path, Path]:
    log = write_log(d, log_path(tmp, "drive", fmt), fmt)
    mapping = tmp / f"drive_{fmt}.map.toml"
    mapping.write_text(mapping_toml(d, fmt, accuracy))
    return log, mapping


@pytest.mark.parametrize("fmt", WRITE_FORMATS)
def test_a_simulated_run_written_as_a_log_replays_to_its_verdicts(simulated: tuple[RunResult, DriveTable], fmt: str, tmp_path: Path) -> None:
    res, drive = simulated
    log, mapping = _write(drive, tmp_path, fmt, (0.0, 0.0))
    sc = with_log_steps(load_topology("paper6", steps=STEPS, log=str(log), mapping=str(mapping)))
    replay = run_inmemory(sc, seed=0)  # the seed draws nothing the log gives
    assert _verdicts(replay) == _verdicts(res)
    s = replay.summary
    assert s.node_steps_undecided == 0 and s.node_steps_missed + s.node_steps_contained == s.node_steps_evaluated == res.summary.node_steps_evaluated
    assert s.violations_total == res.summary.violations_total == 0


def test_without_the_declared_faults_the_replay_differs(simulated: tuple[RunResult, DriveTable], tmp_path: Path) -> None:
    """What the round trip rests on: the profile's faults are injected on top of the logged readings.  Readings
    logged with their faults and injected again carry them twice: the verdicts are not the simulated run's."""
    res, drive = simulated
    assert res.parts is not None
    twice = DriveTable(
        drive.t, drive.speed, drive.steering, {i: np.array([e["y"][str(i)] for e in res.parts["truth"]]) for i in drive.yaw}, drive.beta, drive.r
    )
    log, mapping = _write(twice, tmp_path, "csv", (0.0, 0.0))
    replay = run_inmemory(with_log_steps(load_topology("paper6", steps=STEPS, log=str(log), mapping=str(mapping))), seed=0)
    assert _verdicts(replay) != _verdicts(res)


def test_a_reference_with_accuracy_gives_three_counts(simulated: tuple[RunResult, DriveTable], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A coarse reference: some node-steps undecided, none called contained that the box does not prove, and the
    verdict line, the summary JSON and inspect say the three counts."""
    _, drive = simulated
    log, mapping = _write(drive, tmp_path, "parquet", (0.05, 0.05))
    summary_json = tmp_path / "summary.json"
    record = tmp_path / "run.jsonl"
    code = main(
        [
            "run",
            "paper6",
            "--mode",
            "inmemory",
            "--steps",
            str(STEPS),
            "--log",
            str(log),
            "--map",
            str(mapping),
            "--quiet",
            "--summary-json",
            str(summary_json),
            "--record",
            str(record),
        ]
    )
    out = capsys.readouterr().out
    import json

    s = json.loads(summary_json.read_text())
    assert s["node_steps_undecided"] > 0 and s["node_steps_contained"] + s["node_steps_missed"] + s["node_steps_undecided"] == s["node_steps_evaluated"]
    assert f"undecided on {s['node_steps_undecided']} of {s['node_steps_evaluated']} node-steps" in out.splitlines()[-1]
    assert code == 0 and out.splitlines()[-1].startswith("PASS (partial coverage)")  # undecided is never full containment
    assert main(["inspect", str(record), "--node", "1"]) == 0
    assert "undecided" in capsys.readouterr().out


def _run(tmp: Path, log: Path, mapping: Path, capsys: pytest.CaptureFixture[str], steps: int = STEPS) -> tuple[int, str]:
    code = main(["run", "paper6", "--mode", "inmemory", "--steps", str(steps), "--log", str(log), "--map", str(mapping), "--quiet"])
    return code, capsys.readouterr().err


@pytest.mark.parametrize(
    "fmt, damage, expect",
    [
        ("csv", lambda log, m: m.write_text(m.read_text().replace('"yaw3"', '"yaw33"')), "no column 'yaw33'"),
        ("csv", lambda log, m: m.write_text(m.read_text().replace('unit = "m/s"', 'unit = "km/h"')), "is the mapping's speed unit right"),
        ("csv", lambda log, m: m.write_text(m.read_text().replace('channel = "yaw2"\nunit = "rad/s"', 'channel = "yaw2"\nunit = "deg/s"') or None), None),
        ("rosbag-mcap", lambda log, m: m.write_text(m.read_text().replace("/imu4/data", "/imu44/data")), "the bag has no topic /imu44/data"),
        ("parquet", lambda log, m: log.write_bytes(log.read_bytes()[: len(log.read_bytes()) // 2]), "cannot read it as parquet"),
        ("mdf4", lambda log, m: log.write_bytes(b"\x00garbage" * 64), "cannot read it as MDF4"),
        ("rosbag-sqlite3", lambda log, m: next(log.glob("*.db3")).write_bytes(b"not a database" * 64), "cannot read it as a ROS 2 bag"),
        ("rosbag-mcap", lambda log, m: (f := next(log.glob("*.mcap"))).write_bytes(f.read_bytes()[: f.stat().st_size // 2]), "cannot read it as a ROS 2 bag"),
        ("csv", lambda log, m: m.write_text(m.read_text() + "bogus = 1\n"), "Extra inputs are not permitted"),
    ],
)
def test_a_bad_log_exits_2_with_one_line(
    simulated: tuple[RunResult, DriveTable],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    fmt: str,
    damage: Callable[[Path, Path], object],
    expect: str | None,
) -> None:
    _, drive = simulated
    log, mapping = _write(drive, tmp_path, fmt, (0.0, 0.0))
    damage(log, mapping)
    code, err = _run(tmp_path, log, mapping, capsys)
    if expect is None:  # deg/s where the log holds rad/s: every reading ~57× too small; no range can tell, the run goes on
        return
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert expect in err, err


def test_a_log_shorter_than_the_run_is_an_error(simulated: tuple[RunResult, DriveTable], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, drive = simulated
    log, mapping = _write(drive, tmp_path, "csv", None)
    code, err = _run(tmp_path, log, mapping, capsys, steps=STEPS + 5)
    assert code == 2 and f"the log holds steps 0–{STEPS}" in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize("spike", [0.0, 0.3])
def test_without_a_reference_only_what_a_node_proves_alone(simulated: tuple[RunResult, DriveTable], tmp_path: Path, spike: float) -> None:
    """Nothing is judged against a truth, nothing is called contained; what a node's own data prove is counted: its
    reading impossible under its declared bounds and its own set of the step before.  Every assumption held in the
    simulated run (its noise at the bound: the worst signals), so none is; a logged spike of 0.3 on node 2 at step 6,
    beyond its fault bound (|f| ≤ 0.2, Ds = 0.47), is, there (and at step 7, carried from the set it built on it)."""
    _, drive = simulated
    yaw = dict(drive.yaw)
    yaw[2] = yaw[2].copy()
    yaw[2][6] += spike
    log, mapping = _write(DriveTable(drive.t, drive.speed, drive.steering, yaw, drive.beta, drive.r), tmp_path, "csv", None)
    res = run_inmemory(with_log_steps(load_topology("paper6", steps=STEPS, log=str(log), mapping=str(mapping))), seed=0)
    s, parts = res.summary, res.parts
    assert parts is not None
    assert s.node_steps_evaluated == s.node_steps_contained == 0 and s.node_steps_reported == 6 * (STEPS + 1) and s.node_steps_not_covered == {}
    assert s.violations_total == 0
    flagged = sorted((int(i), e["step"]) for i, es in parts["nodes"].items() for e in es if e.get("inconsistent"))
    from netsetest.runtime.report import outcome, verdict

    assert outcome(s).word == "PASS (partial coverage)"
    if not spike:
        assert flagged == [] and s.node_steps_inconsistent == 0 and "no node's own reading contradicted" in verdict(s)
    else:
        assert (2, 6) in flagged and {i for i, _ in flagged} == {2} and s.node_steps_inconsistent == len(flagged) == s.node(2).steps_inconsistent
        assert f"on {len(flagged)} node-step(s) (node 2: {len(flagged)}" in verdict(s)


def _with_gaps(d: DriveTable, gaps: dict[int, range], speed: dict[int, float] | None = None) -> DriveTable:
    """``d`` without node i's samples at the steps of ``gaps[i]`` (its own stamps), and the logged speed replaced at
    the steps of ``speed``."""
    yaw, stamps = dict(d.yaw), {}
    for i, steps in gaps.items():
        keep = np.ones(d.t.size, dtype=bool)
        keep[list(steps)] = False
        yaw[i], stamps[i] = d.yaw[i][keep], d.t[keep]
    v = d.speed.copy()
    for k, s in (speed or {}).items():
        v[k] = s
    return DriveTable(d.t, v, d.steering, yaw, d.beta, d.r, yaw_t=stamps)


def test_a_gap_in_a_reading_is_a_missing_measurement(simulated: tuple[RunResult, DriveTable], tmp_path: Path) -> None:
    """A node without a reading publishes nothing for the step (counted, never covered), its neighbours are told and
    wait for nothing, and it resumes at its next reading from its own set carried by the model (status resume): every
    set still holds the truth (accuracy 0) and the resumed ones are covered; a gap at the last step is no lost node."""
    res, drive = simulated
    gaps = {3: range(4, 7), 5: range(8, 9), 1: range(STEPS, STEPS + 1)}
    log, mapping = _write(_with_gaps(drive, gaps), tmp_path, "mdf4", (0.0, 0.0))
    replay = run_inmemory(with_log_steps(load_topology("paper6", steps=STEPS, log=str(log), mapping=str(mapping))), seed=0)
    s, parts = replay.summary, replay.parts
    assert parts is not None
    silent = sum(len(r) for r in gaps.values())
    assert s.node_steps_no_reading == silent and s.node_steps_evaluated == 6 * (STEPS + 1) - silent
    assert s.node_steps_contained == s.node_steps_covered == s.node_steps_evaluated and s.violations_total == 0
    assert s.nodes_missing == [] and all(n.missing_steps == 0 and n.neighbour_messages_missing == 0 for n in s.nodes)
    assert {n.id: n.steps_no_reading for n in s.nodes} == {1: 1, 2: 0, 3: 3, 4: 0, 5: 1, 6: 0}
    steps = {i: {e["step"]: e for e in parts["nodes"][str(i)]} for i in gaps}
    for i, r in gaps.items():
        assert not set(r) & set(steps[i])  # nothing published without a reading
    assert steps[3][7]["status"] == "resume" and steps[3][7]["resumed_from"] == 3 and steps[5][9]["resumed_from"] == 7
    assert all(steps[i][k]["assumptions_ok"] and steps[i][k]["contained"] for i, k in ((3, 7), (5, 9)))
    assert [t["no_reading"] for t in parts["truth"][3:10]] == [[], [3], [3], [3], [], [5], []]
    from netsetest.runtime.report import outcome, verdict

    assert outcome(s).word == "PASS (partial coverage)" and f"{silent} node-step(s) without a reading" in verdict(s)


def test_a_broken_assumption_inside_a_gap_leaves_the_resumed_step_uncovered(simulated: tuple[RunResult, DriveTable], tmp_path: Path) -> None:
    """The resumed set rests on every transition it was carried through: a speed outside the model's range at step 5
    (the model mismatch of 5 → 6 is then unbounded) takes node 3's resumed step 7 out of the guarantee, although the
    transition into step 7 itself held (the other nodes are covered again at 7)."""
    _, drive = simulated
    log, mapping = _write(_with_gaps(drive, {3: range(4, 7)}, speed={5: 40.0}), tmp_path, "mdf4", (0.0, 0.0))
    replay = run_inmemory(with_log_steps(load_topology("paper6", steps=STEPS, log=str(log), mapping=str(mapping))), seed=0)
    assert replay.parts is not None
    at7 = {int(i): next(e for e in es if e["step"] == 7) for i, es in replay.parts["nodes"].items()}
    assert at7[3]["status"] == "resume" and not at7[3]["assumptions_ok"] and at7[3]["not_covered_cause"] == "model mismatch"
    assert all(e["assumptions_ok"] for i, e in at7.items() if i != 3)
    assert replay.summary.violations_total == 0
