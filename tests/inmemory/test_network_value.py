"""A reference sensor (`[fault_bound] size = 0`) and what the exchange can buy at best: `netsetest exact
--local` (the one-node exact limit against the whole network's), docs/network.md."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from netsetest.analysis.exact import local_limits
from netsetest.cli.main import main
from netsetest.config.schema import load_topology
from netsetest.records.record import load_record
from netsetest.runtime.inmemory import run_inmemory

ROOT = Path(__file__).resolve().parents[2]


def _record(name: str, tmp_path: Path, steps: int = 30, case: str = "nsnim", signals: str = "paper") -> tuple:
    sc = load_topology(name, case=case, steps=steps)
    path = tmp_path / f"{name}-{case}-{signals}.json"
    run_inmemory(sc, signals, seed=0, record=str(path), keep=False)
    return sc, load_record(str(path))


def test_a_reference_sensor_is_declared_and_applied_where_exact_applies_bounds() -> None:
    sc = load_topology("paper6_reference")
    assert sc.node(3).fault_size == 0.0
    assert sc.fault_bounded("used") == (3,)  # NSNIM: no saturating sensor relies on a bound, the reference counts
    assert sc.fault_bounded("none") == ()
    assert 3 in sc.fault_bounded("all") and len(sc.fault_bounded("all")) == 6


def test_under_the_papers_assumptions_the_network_buys_nothing(tmp_path: Path) -> None:
    sc, rec = _record("paper6", tmp_path)
    for lim in local_limits(sc, rec):
        for v in (lim.fault_ratio, lim.r_ratio, lim.beta_ratio):
            assert v == pytest.approx(1.0, abs=0.01), lim


def test_a_reference_makes_the_whole_network_narrower_than_any_node(tmp_path: Path) -> None:
    sc, rec = _record("paper6_reference", tmp_path)
    limits = {lim.node: lim for lim in local_limits(sc, rec)}
    for i, lim in limits.items():
        if i == 3:  # the reference: its own fault is declared 0, its own data already pin the state
            assert lim.fault_ratio != lim.fault_ratio and lim.r_ratio == pytest.approx(1.0, abs=1e-3)
        else:
            assert lim.fault_ratio > 1.1 and lim.r_ratio > 1.5, lim


def test_exact_local_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, rec = _record("paper6_reference", tmp_path, steps=15)
    out_json = tmp_path / "exact.json"
    assert main(["exact", str(rec.path), "--local", "--json", str(out_json)]) == 0
    out = capsys.readouterr().out
    assert "the exchange's value at best" in out and "declared 0" in out
    doc = json.loads(out_json.read_text())
    rows = {r["node"]: r for r in doc["local_over_central"]}
    assert rows[3]["fault_ratio"] is None and rows[1]["fault_ratio"] > 1.0


def test_a_false_reference_declaration_is_attributed(tmp_path: Path) -> None:
    """Sensor 1 (which has a fault from step 20) declared a reference: its SAIM sector rests on |f| ≤ 0,
    so from the fault on its node-steps are not covered (its sector's premise, the declaration, broke),
    every miss is attributed and nothing is a violation."""
    text = (ROOT / "topologies" / "paper6.toml").read_text().replace('node_dir = "../nodes"', f'node_dir = "{tmp_path}"')
    for n in range(1, 7):
        prof = (ROOT / "nodes" / f"yaw{n}.toml").read_text()
        if n == 1:
            prof = prof.replace("rate = 0.2\nsize = 0.2", "size = 0.0")
        (tmp_path / f"yaw{n}.toml").write_text(prof)
    (tmp_path / "t.toml").write_text(text)
    sc = load_topology(tmp_path / "t.toml", case="saim", steps=40)
    assert sc.node(1).fault_size == 0.0 and sc.node(1).fault_rate is None
    s = run_inmemory(sc, "paper", seed=0).summary
    assert s.violations_total == 0
    own = s.node_steps_not_covered.get("sector", 0) + s.node_steps_not_covered.get("fault bound", 0)
    assert own > 0, s.node_steps_not_covered
    assert s.misses_assumption_broken_total == s.node_steps_evaluated - s.node_steps_contained
