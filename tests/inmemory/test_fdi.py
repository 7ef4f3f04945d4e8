"""Guaranteed fault detection and isolation (roles/fdi.py, docs/fdi.md): per node-step detected / proved
healthy / undecided from the published fault interval, and per node the onset, first detection, delay and
false detections in the summary, the record, `inspect` and the run's table."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from run_helpers import shared_run

from netsetest.cli.main import main
from netsetest.config.schema import load_topology
from netsetest.estimator.sdp import LocalEstimator
from netsetest.records.record import load_record
from netsetest.roles.fdi import FdiTotals, classify
from netsetest.runtime.inmemory import run_inmemory


def test_classify() -> None:
    assert classify(0.01, 0.2) == "detected" and classify(-0.3, -1e-9) == "detected"
    assert classify(-0.01, 0.2) == "undecided" and classify(0.0, 0.2) == "undecided"  # 0 itself is not excluded
    assert classify(0.0, 0.0) == "healthy"
    assert classify(-0.01, 0.01, tolerance=0.02) == "healthy"
    assert classify(0.01, 0.2, tolerance=0.02) == "undecided"  # |f| ≤ 0.02 counts as no fault
    assert classify(0.03, 0.2, tolerance=0.02) == "detected"


def test_totals_delay_counts_from_the_true_onset() -> None:
    t = FdiTotals()
    for k, (f, status) in enumerate([(0.0, "undecided"), (0.0, "detected"), (0.1, "undecided"), (0.1, "detected"), (0.0, "healthy")]):
        t.truth(k, f, 0.0)
        t.add(k, status, f, 0.0, covered=k != 1)
    assert (t.fault_onset, t.first_detection, t.first_true_detection, t.detection_delay) == (2, 1, 3, 1)
    assert (t.detected_steps, t.healthy_steps, t.false_detections, t.false_detections_covered) == (2, 1, 1, 0)


@pytest.mark.parametrize("case", ["nsnim", "saim"])
def test_no_false_detection_and_every_fault_detected_on_the_paper_network(case: str) -> None:
    """Seeds 0-4, paper and worst-case signals: no false detection anywhere; the four faulty sensors are
    detected after their onset, the two healthy ones never. (Runs shared with test_containment and test_sector.)"""
    for seed in range(5):
        for sig in ("paper", "worst"):
            s = shared_run(case, sig, seed).summary
            assert s.violations_total == 0
            for r in s.nodes:
                assert r.false_detections == 0, (case, sig, seed, r.id)
                if r.id in (3, 5):  # the profiles' fault-free sensors
                    assert r.fault_onset is None and r.detected_steps == 0
                else:
                    assert r.fault_onset is not None and r.detection_delay is not None and r.detection_delay <= 10, (case, sig, seed, r)


def test_a_false_detection_where_the_assumptions_held_is_a_violation(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """An estimator bug that moves healthy node 3's fault set off 0: every such step is a false detection
    on a covered node-step, counted as one and as a violation (exit 1)."""
    orig = LocalEstimator.step

    def shifted(self: LocalEstimator, prev, inp, prepared=None):
        res = orig(self, prev, inp, prepared)
        if self.node_id == 3:  # StepResult is frozen: the published set replaced, moved by 1 along f
            pub = dataclasses.replace(res.published, xhat=res.published.xhat + np.array([0.0, 0.0, 1.0]))
            return res.continuing(pub) if res.published is res.continued else dataclasses.replace(res, published=pub)
        return res

    monkeypatch.setattr(LocalEstimator, "step", shifted)
    sc = load_topology("paper6", steps=10)
    res = run_inmemory(sc, seed=0, record=str(tmp_path / "r.json"))
    row = next(r for r in res.summary.nodes if r.id == 3)
    assert row.false_detections == row.false_detections_covered > 0
    assert row.violations >= row.false_detections_covered
    rows = load_record(str(tmp_path / "r.json")).fault_rows(3)
    assert [r["fdi"] for r in rows].count("detected") == row.detected_steps > 0


def test_fault_tolerance_is_declared_in_the_topology(tmp_path: Path) -> None:
    """[network] fault_tolerance: a fault within it is no fault; healthy where the interval lies inside."""
    root = Path(__file__).resolve().parents[2]
    text = (root / "topologies" / "paper6.toml").read_text().replace('node_dir = "../nodes"', f'node_dir = "{root / "nodes"}"')
    path = tmp_path / "t.toml"
    path.write_text(text + "\n[network]\nfault_tolerance = 0.5\n")
    sc = load_topology(path, steps=30)
    assert sc.fault_tolerance == 0.5
    s = run_inmemory(sc, seed=0).summary
    assert all(r.fault_onset is None and r.detected_steps == 0 for r in s.nodes)  # every fault is below 0.5
    assert sum(r.healthy_steps for r in s.nodes) > 0  # settled intervals lie inside ±0.5
    path.write_text(text + "\n[network]\nfault_tolerance = -1.0\n")
    assert main(["run", str(path), "--mode", "inmemory", "--steps", "2"]) == 2


def test_the_run_table_and_inspect_show_detection(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    rec = tmp_path / "r.json"
    assert main(["run", "paper6", "--mode", "inmemory", "--seed", "0", "--record", str(rec)]) == 0
    out = capsys.readouterr().out
    assert "fault detection (detected" in out and "false detections" in out
    assert main(["inspect", str(rec), "--node", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "fault" in lines[1] and any("detected" in ln for ln in lines[2:])
    assert dataclasses.is_dataclass(FdiTotals())
