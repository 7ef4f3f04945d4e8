"""A recorded drive's missing readings for every estimator family (issue 42, docs/your-log.md *Time, stated*).

A reading missing at step 0 leaves the prior (Assumption 1) as the node's set there, for every family; a reading
missing later is a set estimator's prediction-only step (its set moved through the model, the disturbance and
mismatch bounds and the declared fault bound alone), published (status ``no-reading``, no innovation) and judged like
any, while an SDP node publishes nothing and resumes at its next reading.  With a reference of accuracy 0 every set
holds the truth, the steps without a reading are named in the record and counted in the summary; a fault nothing of
a step tells (the logged sensor not declared healthy) is never called contained; a set estimator without a declared
fault bound is refused a gap after step 0 (exit 2, one line).  Hypothesis: a gap anywhere keeps containment.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from gaps_helpers import EVERY_FAMILY, FAMILIES, GAPS, STEPS, check_gapped_run, replay, simulated_drive, write
from hypothesis import HealthCheck, given, settings, strategies as st
from run_helpers import ROOT, mixed_topology

from netsetest.cli.main import main
from netsetest.config.schema import load_topology
from netsetest.logs.write import DriveTable


@pytest.fixture(scope="module")
def drive() -> DriveTable:
    return simulated_drive()


@pytest.mark.parametrize("estimator", FAMILIES)
def test_a_reading_missing_at_step_0_and_mid_drive_keeps_containment(drive: DriveTable, estimator: str, tmp_path: Path) -> None:
    """Before issue 42's leftovers the step-0 gap was refused for every family and a later one for the set estimators."""
    log, mapping = write(drive, tmp_path, GAPS)
    res = replay("paper6", log, mapping, estimator)
    check_gapped_run(res, dict.fromkeys(range(1, 7), estimator))
    assert res.parts is not None
    first = res.parts["nodes"]["3"][0]
    prior = load_topology("paper6").node(3)
    if estimator == "sdp":  # the prior itself (Assumption 1), exactly the profile's
        assert first["published"]["xhat"] == prior.x0_hat.tolist() and first["published"]["P"] == prior.P0.reshape(9).tolist()
    half = np.sqrt(prior.rho * np.diag(prior.P0))  # every family's step-0 set without ỹ₀: the prior's hull in β, r
    np.testing.assert_allclose(np.diff(first["bounds"]).ravel()[:2], 2 * half[:2], rtol=1e-9)


def test_every_family_in_one_network(drive: DriveTable, tmp_path: Path) -> None:
    """Mixed: an SDP node's in-neighbour running a set estimator publishes its prediction without a reading (no
    innovation); the SDP node was told not to expect it and uses nothing of it."""
    log, mapping = write(drive, tmp_path, GAPS)
    res = replay(mixed_topology(tmp_path, EVERY_FAMILY), log, mapping)
    check_gapped_run(res, {i: EVERY_FAMILY.get(i, "sdp") for i in range(1, 7)})


def test_a_fault_nothing_tells_is_never_called_contained(drive: DriveTable, tmp_path: Path) -> None:
    """Node 3's logged sensor not declared healthy: without its reading nothing bounds its fault's truth, so its
    prediction-only sets are undecided (never contained), its step-0 prior is not proven to hold the truth, and nothing
    is a miss."""
    log, mapping = write(drive, tmp_path, GAPS, unhealthy=(3,))
    res = replay("paper6", log, mapping, "zonotope")
    assert res.parts is not None
    states = {e["step"]: e for e in res.parts["nodes"]["3"]}
    assert [t["fault_unknown"] for t in res.parts["truth"][:7]] == [[3], [], [], [], [3], [3], [3]]
    for k in GAPS[3]:
        assert not states[k]["contained"] and not states[k]["missed"], k
    assert not states[0]["assumptions_ok"] and states[0]["not_covered_cause"] == "initial set"
    s = res.summary
    assert s.violations_total == 0 and s.node_steps_missed == 0 and s.node(3).steps_undecided >= len(GAPS[3])


def test_a_set_estimator_without_a_declared_fault_bound_is_refused_a_gap(drive: DriveTable, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Without a reading nothing but a declared bound carries the fault: exit 2 naming the node, the step and the fix;
    step 0's gap alone needs no bound (the prior bounds the fault), and the SDP needs none (it publishes nothing)."""
    nodes = tmp_path / "nodes"
    nodes.mkdir()
    for p in (ROOT / "nodes").glob("*.toml"):
        text = p.read_text()
        if p.stem == "yaw3":
            text = re.sub(r"\[fault_bound\][^\[]*", "", text)
        (nodes / p.name).write_text(text)
    topology = tmp_path / "free.toml"
    topology.write_text((ROOT / "topologies/paper6.toml").read_text().replace('node_dir = "../nodes"', 'node_dir = "nodes"'))
    log, mapping = write(drive, tmp_path, GAPS)
    argv = ["run", str(topology), "--mode", "inmemory", "--quiet", "--steps", str(STEPS), "--log", str(log), "--map", str(mapping)]
    assert main([*argv, "--estimator", "zonotope"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "node 3 missing at step 4" in err and "declare a [fault_bound] rate or size" in err, err
    assert "Traceback" not in err
    log0, mapping0 = write(drive, tmp_path, {3: (0,)})
    argv0 = ["run", str(topology), "--mode", "inmemory", "--quiet", "--steps", str(STEPS), "--log", str(log0), "--map", str(mapping0)]
    assert main([*argv0, "--estimator", "zonotope"]) == 0
    assert main(argv) == 0  # the SDP
    capsys.readouterr()


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    estimator=st.sampled_from(FAMILIES),
    gaps=st.dictionaries(st.integers(1, 6), st.sets(st.integers(0, STEPS), min_size=1, max_size=STEPS), min_size=1, max_size=3),
)
def test_a_gap_anywhere_keeps_containment(drive: DriveTable, tmp_path_factory: pytest.TempPathFactory, estimator: str, gaps: dict[int, set[int]]) -> None:
    """Any nodes, any steps (the first, the last, a whole drive but one step): every set published holds the truth and
    every node-step without a reading is counted."""
    tmp = tmp_path_factory.mktemp("gaps")
    log, mapping = write(drive, tmp, {i: tuple(sorted(s)) for i, s in gaps.items()})
    s = replay("paper6", log, mapping, estimator).summary
    quiet = sum(1 for i, ks in gaps.items() for k in ks if estimator == "sdp" and k > 0)
    assert s.violations_total == 0 and s.node_steps_missed == 0
    assert s.node_steps_contained == s.node_steps_evaluated == 6 * (STEPS + 1) - quiet
    assert s.node_steps_no_reading == sum(map(len, gaps.values())) and s.nodes_missing == []
