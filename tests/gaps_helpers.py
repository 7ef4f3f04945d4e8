"""A recorded drive with readings missing at step 0 and mid-drive, and what a replay of it must give
(tests/inmemory/test_log_gaps.py, tests/process/test_zenoh_log.py; docs/your-log.md *Time, stated*)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from run_helpers import shared_run

from netsetest.config.schema import load_topology
from netsetest.logs.drive import with_log_steps
from netsetest.logs.write import DriveTable, from_truth, log_path, mapping_toml, write_log
from netsetest.runtime.inmemory import RunResult, run_inmemory

STEPS = 12
FAMILIES = ("sdp", "zonotope", "interval", "strip", "setprop")
GAPS = {1: (0,), 3: (0, 4, 5, 6), 5: (8,)}  # node → steps without its reading: step 0 and mid-drive
EVERY_FAMILY = {2: "zonotope", 3: "interval", 4: "strip", 5: "setprop"}  # nodes 1 and 6 the SDP


def simulated_drive() -> DriveTable:
    res = shared_run("nsnim", "worst", 3, STEPS)  # the log tests' simulated paper6 run (tests/inmemory/test_log_replay.py)
    assert res.parts is not None
    return from_truth(res.parts["truth"], 0.1, "synthetic: the gap tests' simulated paper6 run")


def with_gaps(d: DriveTable, gaps: dict[int, tuple[int, ...]]) -> DriveTable:
    """``d`` without node i's samples at the steps of ``gaps[i]`` (its own stamps)."""
    yaw, stamps = dict(d.yaw), {}
    for i, steps in gaps.items():
        keep = np.ones(d.t.size, dtype=bool)
        keep[list(steps)] = False
        yaw[i], stamps[i] = d.yaw[i][keep], d.t[keep]
    return DriveTable(d.t, d.speed, d.steering, yaw, d.beta, d.r, yaw_t=stamps, description=d.description)


def write(d: DriveTable, tmp: Path, gaps: dict[int, tuple[int, ...]], unhealthy: tuple[int, ...] = ()) -> tuple[Path, Path]:
    """The drive with ``gaps`` as MDF4 (the sensors' own stamps) and its mapping, step 0 at the drive's first step (a
    gap there is a gap, not a later start); ``unhealthy``: nodes whose logged sensor is not declared healthy."""
    log = write_log(with_gaps(d, gaps), log_path(tmp, "drive", "mdf4"), "mdf4")
    text = mapping_toml(d, "mdf4", (0.0, 0.0), start_s=float(d.t[0]))
    for i in unhealthy:
        text, n = re.subn(rf"(\[\[yaw_rate\]\]\nnode = {i}\n)", r"\1healthy = false\n", text)
        assert n == 1
    mapping = tmp / "drive.map.toml"
    mapping.write_text(text)
    return log, mapping


def replay(topology: str | Path, log: Path, mapping: Path, estimator: str | None = None) -> RunResult:
    return run_inmemory(with_log_steps(load_topology(topology, steps=STEPS, log=str(log), mapping=str(mapping), estimator=estimator)), seed=0)


def silent(i: int, k: int, estimator: str) -> bool:
    """Node i publishes nothing at step k: an SDP node without its reading after step 0."""
    return estimator == "sdp" and k > 0 and k in GAPS.get(i, ())


def check_gapped_run(res: RunResult, estimators: dict[int, str]) -> None:
    """Every node-step of a replay of the drive with GAPS judged or counted, every set holding the truth (accuracy 0),
    and the steps without a reading named: in the truth, as the states' status, in the summary."""
    s, parts = res.summary, res.parts
    assert parts is not None
    assert [t["no_reading"] for t in parts["truth"][:10]] == [[1, 3], [], [], [], [3], [3], [3], [], [5], []]
    for i in range(1, 7):
        est = estimators[i]
        states = {e["step"]: e for e in parts["nodes"][str(i)]}
        assert sorted(states) == [k for k in range(STEPS + 1) if not silent(i, k, est)], f"node {i} ({est})"
        for k, e in states.items():
            gap = k in GAPS.get(i, ())
            assert (e["status"] == "no-reading") == gap, f"node {i} ({est}) step {k}: {e['status']}"
            assert e["contained"] and e["assumptions_ok"], f"node {i} ({est}) step {k}: {e['not_covered_cause']}"
        if est == "sdp" and i in GAPS:  # resumed at the first reading after each gap, from the last set it published
            after = [k for k in range(1, STEPS + 1) if k - 1 in GAPS[i] and k not in GAPS[i]]
            assert all(states[k]["status"] == "resume" for k in after), {k: states[k]["status"] for k in after}
    quiet = sum(silent(i, k, estimators[i]) for i in range(1, 7) for k in range(STEPS + 1))
    assert s.node_steps_no_reading == sum(map(len, GAPS.values()))
    assert {n.id: n.steps_no_reading for n in s.nodes} == {i: len(GAPS.get(i, ())) for i in range(1, 7)}
    assert s.node_steps_evaluated == s.node_steps_contained == s.node_steps_covered == 6 * (STEPS + 1) - quiet
    assert s.violations_total == 0 and s.nodes_missing == [] and s.node_steps_rejected == 0
    assert all(n.missing_steps == 0 and n.neighbour_messages_missing == 0 for n in s.nodes)


def gapped_drive(tmp: Path) -> tuple[Path, Path]:
    """The simulated drive with GAPS, written (MDF4) with its mapping."""
    return write(simulated_drive(), tmp, GAPS)
