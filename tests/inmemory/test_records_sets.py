"""Records carry every set the collector judges (issue 32): beside the published ellipsoid, the set a node
continues from (``own_xhat``, ``own_P``) and its region (``own_region``), in JSON Lines and MCAP; ``inspect
--json`` shows them; the judgement can be rechecked from the record alone; older records (without them) load."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from netsetest.cli.main import main
from netsetest.config.schema import load_topology
from netsetest.polygon import Polygon
from netsetest.records.record import load_record, save_record
from netsetest.runtime.inmemory import RunResult, run_inmemory

STEPS = 12
OWN = ("own_xhat", "own_P", "own_region")


@dataclass(frozen=True)
class Recorded:
    res: RunResult
    jsonl: Path
    mcap: Path
    dir: Path


@pytest.fixture(scope="module")
def records(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    """paper6_reference (its nodes keep a region and continue from cut sets), recorded as JSON Lines and MCAP."""
    pytest.importorskip("mcap")
    d = tmp_path_factory.mktemp("sets")
    sc = load_topology("paper6_reference", case="nsnim", steps=STEPS)
    res = run_inmemory(sc, "worst", "scheduled", 0, record=str(d / "run.jsonl"), keep=True)
    save_record(d / "run.mcap", res.meta, res.parts["truth"], res.parts["nodes"], res.summary)
    return Recorded(res, d / "run.jsonl", d / "run.mcap", d)


def test_the_records_carry_the_region_and_the_set_continued_from(records: Recorded) -> None:
    res = records.res
    entries = [e for node in res.parts["nodes"].values() for e in node]
    assert any("own_region" in e for e in entries) and any("own_xhat" in e for e in entries)
    for e in entries:
        assert ("own_xhat" in e) == ("own_P" in e)
    for path in (records.jsonl, records.mcap):
        rec = load_record(path)
        for key, node in res.parts["nodes"].items():
            raw = rec.raw_nodes[key]
            tr = rec.nodes[int(key)]
            for n, e in enumerate(node):
                for k in OWN:
                    assert raw[n].get(k) == e.get(k), (path, key, n, k)  # as the collector judged them
                if "own_region" in e:
                    assert tr.own_region is not None and np.array_equal(tr.own_region[n], np.reshape(e["own_region"], (-1, 2)))
                if "own_xhat" in e:
                    assert tr.own_xhat is not None and tr.own_P is not None
                    assert np.array_equal(tr.own_xhat[n], e["own_xhat"]) and np.array_equal(tr.own_P[n].reshape(-1), e["own_P"])


def test_the_judgement_can_be_rechecked_from_the_record(records: Recorded) -> None:
    """Where the step was judged: the truth's x is in the recorded region iff the collector found the set the
    node continues from containing it (the region is judged with it); the recorded own ellipsoid holds it."""
    rec = load_record(records.jsonl)
    checked = 0
    for key, entries in rec.raw_nodes.items():
        for e in entries:
            if not e["judged"] or "own_region" not in e:
                continue
            t = rec.truth_at(e["step"])
            assert t is not None
            x = np.array(t["x"], dtype=float)
            inside = Polygon(np.reshape(e["own_region"], (-1, 2))).contains(x)
            if "own_xhat" in e:
                d = np.r_[x, t["faults"][key]] - np.array(e["own_xhat"])
                inside = inside and float(d @ np.linalg.solve(np.reshape(e["own_P"], (3, 3)), d)) <= e["rho"] * (1 + 1e-9)
            assert inside == e["continues_contained"], (key, e["step"])
            checked += 1
    assert checked > 0


def test_inspect_json_shows_them(records: Recorded, capsys: pytest.CaptureFixture[str]) -> None:
    for path in (records.jsonl, records.mcap):
        assert main(["inspect", str(path), "--json"]) == 0
        rows = json.loads(capsys.readouterr().out)
        raw = load_record(path).raw_nodes
        for key, node_rows in rows.items():
            for r, e in zip(node_rows, raw[key], strict=True):
                assert r["own_region"] == (None if "own_region" not in e else np.reshape(e["own_region"], (-1, 2)).tolist())
                assert r["own_xhat"] == e.get("own_xhat") and r["own_P"] == e.get("own_P")
        assert any(r["own_region"] is not None for node_rows in rows.values() for r in node_rows)


@pytest.mark.parametrize("suffix", ["jsonl", "mcap"])
def test_a_record_written_without_them_still_loads(records: Recorded, suffix: str, capsys: pytest.CaptureFixture[str]) -> None:
    res = records.res
    old = {k: [{f: v for f, v in e.items() if f not in OWN} for e in node] for k, node in res.parts["nodes"].items()}
    path = records.dir / f"old.{suffix}"
    save_record(path, res.meta, res.parts["truth"], old, res.summary)
    rec = load_record(path)
    new = load_record(records.jsonl)
    for i, tr in rec.nodes.items():
        assert tr.own_xhat is None and tr.own_P is None and tr.own_region is None
        assert np.array_equal(tr.P, new.nodes[i].P) and np.array_equal(tr.continues_contained, new.nodes[i].continues_contained)
    assert main(["inspect", str(path), "--node", "3", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows and all(r["own_region"] is None and r["own_xhat"] is None and r["own_P"] is None for r in rows)


def test_a_malformed_region_is_a_malformed_record(records: Recorded, tmp_path: Path) -> None:
    from netsetest.records.record import RecordError

    res = records.res
    bad = {k: [{**e, "own_region": [0.0, 1.0, 2.0]} if "own_region" in e else e for e in node] for k, node in res.parts["nodes"].items()}
    path = tmp_path / "bad.jsonl"
    save_record(path, res.meta, res.parts["truth"], bad, res.summary)
    with pytest.raises(RecordError, match="own_region"):
        load_record(path)
