"""A mixed network (nodes 1–3 SDP, 4 zonotope, 5 interval, 6 strip) over Zenoh (lockstep, mTLS) gives
its in-memory run: the same sets, bounds and verdicts node by node and step by step."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from run_helpers import mixed_topology
from zenoh_helpers import read_json, read_record, run_to_success

from netsetest.config.schema import load_topology
from netsetest.runtime.inmemory import run_inmemory

pytestmark = pytest.mark.zenoh

SEED, SIGNALS, STEPS, CASE = 2, "worst", 10, "saim"
TOL = 1e-9


def test_zenoh_mixed_equals_inmemory(tmp_path: Path) -> None:
    topo = mixed_topology(tmp_path)
    rec, summ = tmp_path / "record.json", tmp_path / "summary.json"
    args = [str(topo), "--steps", str(STEPS), "--case", CASE, "--seed", str(SEED), "--signals", SIGNALS, "--record", str(rec), "--summary-json", str(summ)]
    run_to_success(tmp_path / "logs", args, timeout=150)
    z = read_record(rec)
    m = run_inmemory(load_topology(topo, CASE, STEPS), SIGNALS, "scheduled", seed=SEED)
    assert z["truth"] == m.parts["truth"]
    assert sorted(z["nodes"]) == sorted(m.parts["nodes"])
    for i, zentries in z["nodes"].items():
        mentries = m.parts["nodes"][i]
        assert [e["step"] for e in zentries] == [e["step"] for e in mentries] == list(range(STEPS + 1))
        for ze, me in zip(zentries, mentries):
            np.testing.assert_allclose(ze["published"]["xhat"], me["published"]["xhat"], rtol=0, atol=TOL)
            np.testing.assert_allclose(ze["published"]["P"], me["published"]["P"], rtol=0, atol=TOL)
            np.testing.assert_allclose(ze["bounds"], me["bounds"], rtol=0, atol=TOL)  # every node's published set
            for f in ("status", "used", "contained", "assumptions_ok", "sector_basis"):
                assert ze[f] == me[f], f"node {i} step {ze['step']}: {f}"
    zs, ms = read_json(summ), m.summary.to_dict()  # the file against the in-memory object
    assert zs["violations_total"] == ms["violations_total"] == 0
    assert zs["node_steps_covered"] == ms["node_steps_covered"] > 0
    assert [r["estimator"] for r in zs["nodes"]] == [r["estimator"] for r in ms["nodes"]]
