"""Records carry both sets the collector judges (issues 32 and 28): the set a node published and the one it continues
from (``published``, ``continues``: netsetest/proven.py's ProvenSet, as sent), in JSON Lines and MCAP; ``inspect
--json`` shows them; the judgement can be rechecked from the record alone; records written before issue 28 (the
published ellipsoid as xhat, P, rho with fault_range, own_xhat, own_P and own_region beside it: the committed ones in
tests/fixtures/records_v0, recorded with the code before it) and older ones (without the own sets) load, with the same
bounds and verdicts."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import msgspec
import numpy as np
import pytest

from netsetest.cli.main import main
from netsetest.config.schema import load_topology
from netsetest.models.sensor import augmented
from netsetest.proven import ProvenSet, continued_set, proven_sets
from netsetest.records.record import load_record, save_record
from netsetest.runtime.inmemory import RunResult, run_inmemory

STEPS = 12
V0 = Path(__file__).resolve().parents[1] / "fixtures" / "records_v0"  # netsetest run … --steps 6 --seed 0 --mode inmemory, before issue 28
V0_RUNS = ("paper6_nsnim", "paper6_saim", "paper6_reference", "paper6_zonotope")
V0_SETS = ("own_xhat", "own_P", "own_region", "fault_range")  # beside xhat, P, rho: the seven fields of the form before issue 28


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


def test_the_records_carry_the_published_set_and_the_set_continued_from(records: Recorded) -> None:
    res = records.res
    entries = [e for node in res.parts["nodes"].values() for e in node]
    assert all("region" in e["published"] for e in entries) and any("continues" in e for e in entries)
    assert all(set(e["continues"]) == {"xhat", "P", "rho"} for e in entries if "continues" in e)  # its region: the published one's
    for path in (records.jsonl, records.mcap):
        rec = load_record(path)
        for key, node in res.parts["nodes"].items():
            raw = rec.raw_nodes[key]
            tr = rec.nodes[int(key)]
            for n, e in enumerate(node):
                for k in ("published", "continues"):
                    assert raw[n].get(k) == e.get(k), (path, key, n, k)  # as the collector judged them
                pub = msgspec.convert(e["published"], ProvenSet)
                assert tr.published[n] == pub
                cont = None if "continues" not in e else msgspec.convert(e["continues"], ProvenSet)
                assert tr.continues[n] == (None if cont is None else continued_set(pub, cont))
                assert tr.xhat[n].tolist() == pub.xhat and tr.P[n].reshape(-1).tolist() == pub.P and tr.rho[n] == pub.rho


def test_the_judgement_can_be_rechecked_from_the_record(records: Recorded) -> None:
    """Where the step was judged: ProvenSet.contains of the recorded sets against the recorded truth gives the
    collector's verdicts, and the recorded bounds are the published set's."""
    rec = load_record(records.jsonl)
    checked = 0
    for i, tr in rec.nodes.items():
        raw = rec.raw_nodes[str(i)]
        for n, e in enumerate(raw):
            assert np.array_equal(np.stack(tr.published[n].bounds(), axis=1), e["bounds"])
            if not e["judged"]:
                continue
            t = rec.truth_at(e["step"])
            assert t is not None
            xbar = augmented(np.array(t["x"], dtype=float), t["faults"][i])
            assert tr.published[n].contains(xbar) == e["contained"], (i, e["step"])
            cont = tr.continues[n] if tr.continues[n] is not None else tr.published[n]
            assert cont.contains(xbar) == e["continues_contained"], (i, e["step"])
            checked += 1
    assert checked > 0


def test_a_region_moved_off_the_truth_is_recorded_as_a_miss(records: Recorded) -> None:
    """The recheck above can fail: the recorded published set with its region moved 1 rad in β holds no truth."""
    rec = load_record(records.jsonl)
    tr, raw = rec.nodes[1], rec.raw_nodes["1"]
    n = next(n for n, e in enumerate(raw) if e["judged"] and e["contained"])
    t = rec.truth_at(raw[n]["step"])
    assert t is not None
    xbar = augmented(np.array(t["x"], dtype=float), t["faults"][1])
    pub = tr.published[n]
    assert pub.region is not None and pub.contains(xbar)
    moved = msgspec.structs.replace(pub, region=[v + (1.0 if j % 2 == 0 else 0.0) for j, v in enumerate(pub.region)])
    assert not ProvenSet(xhat=moved.xhat, P=moved.P, rho=moved.rho, region=moved.region, fault=moved.fault).contains(xbar)


def test_inspect_json_shows_them(records: Recorded, capsys: pytest.CaptureFixture[str]) -> None:
    for path in (records.jsonl, records.mcap):
        assert main(["inspect", str(path), "--json"]) == 0
        rows = json.loads(capsys.readouterr().out)
        raw = load_record(path).raw_nodes
        for key, node_rows in rows.items():
            for r, e in zip(node_rows, raw[key], strict=True):
                assert r["published"] == e["published"]
                pub, cont = proven_sets(e)
                assert r["continues"] == (None if cont is None else msgspec.to_builtins(cont))
        assert any(r["continues"] is not None and "region" in r["continues"] for node_rows in rows.values() for r in node_rows)


@pytest.mark.parametrize("run", V0_RUNS)
def test_a_record_written_before_issue_28_loads_with_the_same_bounds_and_verdicts(run: str, capsys: pytest.CaptureFixture[str]) -> None:
    """The committed records of the seven-field form (JSON Lines and MCAP): their sets convert to ProvenSets whose
    bounds are the bounds the collector wrote then, bit for bit, and whose membership gives the verdicts it wrote."""
    pytest.importorskip("mcap")
    jsonl, mcap = load_record(V0 / f"{run}.jsonl.gz"), load_record(V0 / f"{run}.mcap")
    sdp = run != "paper6_zonotope"
    for i, tr in jsonl.nodes.items():
        raw = jsonl.raw_nodes[str(i)]
        assert all("published" not in e for e in raw) and (not sdp or all("own_region" in e for e in raw))
        assert tr.published == mcap.nodes[i].published and tr.continues == mcap.nodes[i].continues
        for n, e in enumerate(raw):
            pub, cont = tr.published[n], tr.continues[n]
            assert pub.xhat == e["xhat"] and pub.P == e["P"] and pub.rho == e["rho"]
            if not sdp:  # a set estimator's set was not recorded then: its bounds are the recorded ones
                assert pub.is_ellipsoid and cont is None
                continue
            assert np.array_equal(np.stack(pub.bounds(), axis=1), e["bounds"]), (run, i, n)
            assert pub.fault == e.get("fault_range") and pub.region == e["own_region"]
            assert cont is not None and cont.xhat == e["own_xhat"] and cont.P == e["own_P"] and cont.region == e["own_region"] and cont.fault is None
            t = jsonl.truth_at(e["step"])
            assert t is not None and e["judged"]
            xbar = augmented(np.array(t["x"], dtype=float), t["faults"][i])
            assert pub.contains(xbar) == e["contained"] and cont.contains(xbar) == e["continues_contained"]
    assert main(["inspect", str(V0 / f"{run}.jsonl.gz"), "--node", "1", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["fault_lower"] for r in rows] == [e["bounds"][2][0] for e in jsonl.raw_nodes["1"]]


@pytest.mark.parametrize("suffix", ["jsonl", "mcap"])
def test_a_record_written_without_the_own_sets_still_loads(suffix: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Older still: the ellipsoid alone (no region, no set continued from, no fault range)."""
    pytest.importorskip("mcap")
    v0 = load_record(V0 / "paper6_reference.jsonl.gz")
    old = {k: [{f: v for f, v in e.items() if f not in V0_SETS} for e in node] for k, node in v0.raw_nodes.items()}
    path = tmp_path / f"old.{suffix}"
    save_record(path, v0.meta, v0.truth, old, v0.summary)
    rec = load_record(path)
    for i, tr in rec.nodes.items():
        assert all(p.is_ellipsoid for p in tr.published) and all(c is None for c in tr.continues)
        assert np.array_equal(tr.P, v0.nodes[i].P) and np.array_equal(tr.continues_contained, v0.nodes[i].continues_contained)
    assert main(["inspect", str(path), "--node", "3", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows and all(r["continues"] is None and set(r["published"]) == {"xhat", "P", "rho"} for r in rows)


@pytest.mark.parametrize(
    "change",
    [
        {"region": [0.0, 1.0, 2.0]},  # odd
        {"fault": [1.0, 0.0]},  # lo > hi
        {"P": [1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0]},  # not positive definite
    ],
    ids=["region-odd", "fault-reversed", "P-not-spd"],
)
def test_a_malformed_set_is_a_malformed_record(records: Recorded, tmp_path: Path, change: dict) -> None:
    from netsetest.records.record import RecordError

    res = records.res
    bad = {k: [{**e, "published": {**e["published"], **change}} for e in node] for k, node in res.parts["nodes"].items()}
    path = tmp_path / "bad.jsonl"
    save_record(path, res.meta, res.parts["truth"], bad, res.summary)
    with pytest.raises(RecordError, match="set"):
        load_record(path)


def test_the_api_hands_out_the_sets(records: Recorded) -> None:
    """netsetest.api's NodeSeries carries each step's ProvenSets; its bounds are theirs."""
    from netsetest.api import result_of

    res = result_of(load_record(records.jsonl))
    for node in res.nodes.values():
        assert len(node.published) == len(node.steps) == len(node.continues)
        for n, pub in enumerate(node.published):
            lo, hi = pub.bounds()
            assert np.array_equal(lo, node.lower[n]) and np.array_equal(hi, node.upper[n])
        assert any(c is not None for c in node.continues)


@pytest.mark.parametrize("run", V0_RUNS[:3])
def test_a_record_without_bounds_takes_them_from_its_sets(run: str) -> None:
    """Rows without ``bounds`` (records before they were written): NodeTrack.bounds are the recorded sets' (ProvenSet,
    the region and the fault range included), the very bounds the collector wrote beside them, bit for bit."""
    from netsetest.records.record import record_from_parts

    v0 = load_record(V0 / f"{run}.jsonl.gz")
    bare = {k: [{f: v for f, v in e.items() if f != "bounds"} for e in node] for k, node in v0.raw_nodes.items()}
    rec = record_from_parts(v0.meta, v0.truth, bare, v0.summary)
    for i, tr in rec.nodes.items():
        assert tr.set_bounds is None
        for c in range(3):
            want = v0.nodes[i].set_bounds
            assert want is not None
            lo, hi = tr.bounds(c)
            assert np.array_equal(lo, want[:, c, 0]) and np.array_equal(hi, want[:, c, 1]), (run, i, c)
