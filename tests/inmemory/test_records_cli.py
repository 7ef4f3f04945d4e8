"""The run record, the summary JSON and the ``inspect`` / ``plot`` commands, on short in-memory runs."""

from __future__ import annotations

import gzip
import json
import re
from pathlib import Path

import numpy as np
import pytest

from netsetest.cli.main import main
from netsetest.records.plots import plot_records
from netsetest.records.record import RecordError, load_record
from netsetest.records.summary import NodeSummary, RunSummary
from netsetest.runtime.report import exit_code, format_table

ROOT = Path(__file__).resolve().parents[2]
TOPOLOGY = str(ROOT / "topologies" / "paper6.toml")
PNG = b"\x89PNG\r\n\x1a\n"
FIGS = ("fig5_measurements.png", "fig6_states.png", "fig7_faults.png", "fault_detection.png", "fig8_E.png")


@pytest.fixture(scope="module")
def nsnim(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("nsnim")
    rec, summ = d / "run.json", d / "summary.json"
    rc = main(["run", TOPOLOGY, "--mode", "inmemory", "--steps", "12", "--record", str(rec), "--summary-json", str(summ), "--quiet"])
    assert rc == 0
    return {"record": rec, "summary": summ}


@pytest.fixture(scope="module")
def saim(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("saim")
    rec, summ = d / "run.json.gz", d / "summary.json"
    rc = main(["run", TOPOLOGY, "--mode", "inmemory", "--case", "saim", "--steps", "8", "--record", str(rec), "--summary-json", str(summ), "--quiet"])
    assert rc == 0
    return {"record": rec, "summary": summ}


# ------------------------------------------------------------------------------------ record


def _check_record(path: Path, steps: int, summary_path: Path) -> None:
    rec = load_record(path)
    K = steps + 1  # steps 0..steps
    assert len(rec.truth) == K
    assert sorted(rec.nodes) == rec.meta.node_ids == [1, 2, 3, 4, 5, 6]
    for i, tr in rec.nodes.items():
        assert tr.steps.shape == (K,) and list(tr.steps) == list(range(K))
        assert tr.xhat.shape == (K, 3) and tr.P.shape == (K, 3, 3)
        for a in (tr.rho, tr.E, tr.contained, tr.assumptions_ok, tr.solve_ms):
            assert a.shape == (K,)
        assert len(tr.status) == K
        assert tr.contained.dtype == bool and tr.assumptions_ok.dtype == bool
        for n, k in enumerate(tr.steps):
            t = rec.truth_at(int(k))
            e = np.r_[t["x"], t["faults"][i]] - tr.xhat[n]
            E = float(e @ np.linalg.solve(tr.P[n], e))
            assert abs(E - tr.E[n]) <= 1e-12 * max(1.0, E), (i, k)
            assert tr.contained[n] == (tr.E[n] <= tr.rho[n])
    assert rec.summary is not None and rec.summary.to_dict() == json.loads(summary_path.read_text())


def test_record_round_trip(nsnim: dict[str, Path]) -> None:
    _check_record(nsnim["record"], 12, nsnim["summary"])


def test_gzip_record_round_trip(saim: dict[str, Path], nsnim: dict[str, Path], tmp_path: Path) -> None:
    assert saim["record"].read_bytes()[:2] == b"\x1f\x8b"
    _check_record(saim["record"], 8, saim["summary"])
    assert load_record(saim["record"]).meta.case == "saim"
    # gzip is detected by content too: a compressed record under a .json name loads the same
    z = tmp_path / "copy.json"
    z.write_bytes(gzip.compress(nsnim["record"].read_bytes()))
    a, b = load_record(z), load_record(nsnim["record"])
    assert a.summary == b.summary and np.array_equal(a.nodes[2].P, b.nodes[2].P)


def _legacy_doc(path: Path) -> dict:
    """The same record in the version-1 layout (one JSON document) that older netsetest wrote."""
    rec = load_record(path)
    return {
        "format": "netsetest-record",
        "version": 1,
        "meta": rec.meta.to_dict(),
        "truth": rec.truth,
        "nodes": rec.raw_nodes,
        "summary": rec.summary.to_dict(),
    }


def test_legacy_document_record_loads(nsnim: dict[str, Path], tmp_path: Path) -> None:
    new = load_record(nsnim["record"])
    for name, data in (
        ("old.json", json.dumps(_legacy_doc(nsnim["record"])).encode()),
        ("old.json.gz", gzip.compress(json.dumps(_legacy_doc(nsnim["record"])).encode())),
    ):
        p = tmp_path / name
        p.write_bytes(data)
        old = load_record(p)
        assert not old.partial and old.summary == new.summary and old.truth == new.truth
        assert old.last_complete_step == new.last_complete_step == 12
        assert np.array_equal(old.nodes[4].P, new.nodes[4].P)


def test_bad_records_raise(nsnim: dict[str, Path], saim: dict[str, Path], tmp_path: Path) -> None:
    data = json.dumps(_legacy_doc(nsnim["record"])).encode()
    cases = {
        "truncated.json": data[: len(data) // 2],  # a version-1 document is all or nothing
        "truncated.json.gz": saim["record"].read_bytes()[:200],
        "garbage.json": b"\x00\x01 not json",
        "noformat.json": json.dumps({"version": 1, "meta": {}, "truth": [], "nodes": {}, "summary": {}}).encode(),
        "list.json": b"[1, 2, 3]",
        "no-meta-line.json": b'{"kind": "truth", "entry": {"step": 0}}\n',
        "bad-middle-line.json": nsnim["record"].read_bytes().replace(b"\n", b"\nnot json\n", 1),
    }
    for name, content in cases.items():
        p = tmp_path / name
        p.write_bytes(content)
        with pytest.raises(RecordError, match=re.escape(str(p))):
            load_record(p)
    with pytest.raises(RecordError, match="not found"):
        load_record(tmp_path / "absent.json")


@pytest.mark.parametrize("kind", ["corrupt-gzip", "nodes-not-a-dict"])
def test_corrupt_gzip_and_malformed_structure_raise_record_error(kind: str, nsnim: dict[str, Path], tmp_path: Path) -> None:
    p = tmp_path / "bad.json.gz"
    if kind == "corrupt-gzip":
        z = bytearray(gzip.compress(json.dumps(_legacy_doc(nsnim["record"])).encode()))
        z[200:260] = bytes(b ^ 0xFF for b in z[200:260])  # flipped bits inside the deflate stream
        p.write_bytes(bytes(z))
    else:
        p.write_text(json.dumps({"format": "netsetest-record", "version": 1, "meta": {}, "truth": [], "nodes": [], "summary": {}}))
    with pytest.raises(RecordError, match=re.escape(str(p))):
        load_record(p)


def test_inspect_bad_file_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / "bad.json"
    p.write_text('{"format": "netsetest-rec')
    assert main(["inspect", str(p)]) == 2
    err = capsys.readouterr().err
    assert str(p) in err and "netsetest inspect" in err
    assert "Traceback" not in err


# ------------------------------------------------------------------------------------ summary


def test_summary_json_fields(nsnim: dict[str, Path]) -> None:
    s = json.loads(nsnim["summary"].read_text())
    assert s["mode"] == "inmemory" and s["variant"] == "scheduled"
    assert s["case"] == "nsnim" and s["signals"] == "paper" and s["steps"] == 12
    assert s["violations_total"] == 0
    assert [n["id"] for n in s["nodes"]] == [1, 2, 3, 4, 5, 6]
    for n in s["nodes"]:
        for key in ("id", "max_E", "violations", "assumption_violations", "fault_bound_mean_width", "solve_ms_median", "fallbacks"):
            assert key in n, key
        assert 0.0 <= n["max_E"] <= 1.0
        assert n["violations"] == 0 and n["fault_bound_mean_width"] > 0 and n["solve_ms_median"] > 0
        rows = load_record(nsnim["record"]).state_rows(n["id"])  # the state widths are the published intervals' mean
        assert n["r_mean_width"] == pytest.approx(np.mean([r["r_upper"] - r["r_lower"] for r in rows]))
        assert n["beta_mean_width"] == pytest.approx(np.mean([r["beta_upper"] - r["beta_lower"] for r in rows]))


def test_summary_is_typed_and_round_trips(nsnim: dict[str, Path]) -> None:
    """In code the summary is a RunSummary; its dict is the --summary-json object, key for key, in order."""
    rec = load_record(nsnim["record"])
    s = rec.summary
    assert isinstance(s, RunSummary) and all(isinstance(n, NodeSummary) for n in s.nodes)
    text = nsnim["summary"].read_text()
    assert json.dumps(s.to_dict(), indent=2) + "\n" == text
    assert RunSummary.from_dict(json.loads(text)) == s and s.node(3).id == 3 and s.fallbacks == 0
    assert exit_code(s) == 0 and "contained on 78 of 78 node-steps" in format_table(s)


def test_summary_of_an_older_record_loads(nsnim: dict[str, Path], tmp_path: Path) -> None:
    """Fields added since a record was written take their defaults (an older record still loads)."""
    doc = _legacy_doc(nsnim["record"])
    for key in ("sector_failures_total", "node_steps_contested", "node_steps_not_covered", "drops", "objective", "clock"):
        del doc["summary"][key]
    for n in doc["summary"]["nodes"]:
        del n["estimator"], n["sector_failures"], n["steps_contested"]
    p = tmp_path / "older.json"
    p.write_text(json.dumps(doc))
    s = load_record(p).summary
    assert s is not None and s.objective is None and s.drops == {} and s.node_steps_contested == 0
    assert {n.estimator for n in s.nodes} == {"sdp"} and s.violations_total == 0
    assert "case nsnim" in format_table(s)


@pytest.mark.parametrize(
    ("where", "value", "field"),
    [
        ("summary", "0", "summary.violations_total"),
        ("summary", True, "summary.violations_total"),
        ("node", "x", "summary.nodes[2].fallbacks"),
        ("node", [1], "summary.nodes[2].fallbacks"),
    ],
)
def test_a_mistyped_summary_field_is_a_malformed_record(where: str, value: object, field: str, nsnim: dict[str, Path], tmp_path: Path) -> None:
    doc = _legacy_doc(nsnim["record"])
    if where == "summary":
        doc["summary"]["violations_total"] = value
    else:
        doc["summary"]["nodes"][2]["fallbacks"] = value
    p = tmp_path / "mistyped.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(RecordError, match=re.escape(field)):
        load_record(p)


# ------------------------------------------------------------------------------------ inspect


def test_inspect_table(nsnim: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(nsnim["record"]), "--node", "2"]) == 0
    out = capsys.readouterr().out
    rows = [ln.split() for ln in out.splitlines() if re.match(r"^\s*\d+\s", ln)]
    assert [int(r[0]) for r in rows] == list(range(13))
    ref = load_record(nsnim["record"]).fault_rows(2)
    for r, want in zip(rows, ref):
        f_true, f_est, lo, hi, E = (float(v) for v in r[1:6])
        assert f_true == pytest.approx(want["fault_true"], abs=6e-5)
        assert f_est == pytest.approx(want["fault_estimate"], abs=6e-5)
        assert lo == pytest.approx(want["fault_lower"], abs=6e-5)
        assert hi == pytest.approx(want["fault_upper"], abs=6e-5)
        assert E == pytest.approx(want["E"], abs=6e-4)
        assert r[6] == want["fdi"]  # detected | healthy | undecided (docs/fdi.md)
        assert r[7] == want["status"]


def test_inspect_json(nsnim: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(nsnim["record"]), "--node", "2", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["step"] for r in rows] == list(range(13))
    rec = load_record(nsnim["record"])
    for r in rows:
        for key in (
            "step",
            "fault_estimate",
            "fault_lower",
            "fault_upper",
            "fault_true",
            "E",
            "contained",
            "status",
            "beta_estimate",
            "beta_lower",
            "beta_upper",
            "beta_true",
            "r_estimate",
            "r_lower",
            "r_upper",
            "r_true",
        ):
            assert key in r, key
        t = rec.truth_at(r["step"])
        assert r["beta_true"] == t["x"][0] and r["r_true"] == t["x"][1] and r["fault_true"] == t["faults"][2]
        if r["contained"]:  # inside the ellipsoid ⇒ every coordinate inside x̂ ± √(ρ P_ii)
            for name in ("beta", "r", "fault"):
                assert r[f"{name}_lower"] - 1e-12 <= r[f"{name}_true"] <= r[f"{name}_upper"] + 1e-12, (r["step"], name)
    assert any(r["contained"] for r in rows)


def test_inspect_state_shows_every_interval_and_the_cut_it_rests_on(nsnim: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    """``inspect --state``: β, r and f per step with the true value and the cut each interval rests on; the SDP's
    β and r rest on its region or its ellipsoid from step 1 and on the region alone once it has closed in (step 5 of
    this run: until then the trace ellipsoid, published since ``bank`` solves once (issue 45), is narrower in β), and
    the printed ends are the record's."""
    assert main(["inspect", str(nsnim["record"]), "--node", "2", "--state"]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if re.match(r"^\s*\d+\s", ln)]
    rows = load_record(nsnim["record"]).state_rows(2)
    assert len(lines) == len(rows) == 13
    for ln, want in zip(lines, rows):
        ends = [float(v) for pair in re.findall(r"\[\s*(-?[\d.]+),\s*(-?[\d.]+)\]", ln) for v in pair]
        assert ends == pytest.approx([want[f"{n}_{s}"] for n in ("beta", "r", "fault") for s in ("lower", "upper")], abs=6e-5)
        for name in ("beta", "r", "fault"):
            assert want[f"{name}_rests_on"] in ln
    assert all(r[f"{c}_rests_on"] in ("region", "ellipsoid") for r in rows[1:] for c in ("beta", "r"))
    assert all(r["beta_rests_on"] == r["r_rests_on"] == "region" for r in rows[5:])
    tr = load_record(nsnim["record"]).nodes[2]
    for c in (0, 1):  # β, r: the region narrower than the ellipsoid once it has closed in
        e_lo, e_hi = tr.ellipsoid_bounds(c)
        lo, hi = tr.bounds(c)
        assert np.all(hi[5:] - lo[5:] < e_hi[5:] - e_lo[5:])


def test_every_published_interval_carries_the_cuts_that_made_it(saim: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    """The cuts' names travel from the node (NodeState.cuts) to the record, ``inspect --json``, the summary and the
    API, and ``rests_on`` is read from them (no bounds compared downstream): every row names its β, r, f cuts, a β or
    r interval rests on the region exactly where the region cut narrowed it, and the summary counts what the rows name."""
    from netsetest.api import result_of
    from netsetest.sets import CUT_NAMES

    rec = load_record(saim["record"])
    assert main(["inspect", str(saim["record"]), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    summary = RunSummary.from_dict(json.loads(saim["summary"].read_text()))
    for node, node_rows in rows.items():
        counts: dict[str, int] = {}
        for r in node_rows:
            for name in ("beta", "r", "fault"):
                cuts = r[f"{name}_cuts"]
                assert isinstance(cuts, list) and set(cuts) <= set(CUT_NAMES), (node, r["step"], cuts)
                for c in cuts:
                    counts[c] = counts.get(c, 0) + 1
            assert all(r[f"{c}_rests_on"] == ("region" if "region" in r[f"{c}_cuts"] else "ellipsoid") for c in ("beta", "r"))
            assert r["fault_rests_on"] == ("fault range" if r["fault_cuts"] else "ellipsoid")
        assert counts == next(n for n in summary.nodes if n.id == int(node)).cuts
        assert [list(c[2]) for c in result_of(rec).nodes[int(node)].cuts] == [r["fault_cuts"] for r in node_rows]
    assert any(r["fault_cuts"] for rs in rows.values() for r in rs)  # SAIM: the region and the size cut narrow the fault


def test_inspect_unknown_node(nsnim: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(nsnim["record"]), "--node", "99"]) == 2
    assert "no node 99" in capsys.readouterr().err


# ------------------------------------------------------------------------------------ plot


def _assert_pngs(paths: list[Path]) -> None:
    for p in paths:
        assert p.is_file(), p
        data = p.read_bytes()
        assert len(data) > 1000 and data[:8] == PNG, p


def test_plot_one_record(nsnim: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "figs"
    assert main(["plot", str(nsnim["record"]), "--out", str(out)]) == 0
    _assert_pngs([out / f for f in FIGS])
    assert sorted(capsys.readouterr().out.split()) == sorted(str(out / f) for f in FIGS)


def test_plot_two_records(nsnim: dict[str, Path], saim: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "figs"
    assert main(["plot", str(nsnim["record"]), str(saim["record"]), "--out", str(out)]) == 0
    expected = [out / "fig8_E.png"] + [out / f"{c}_paper_{f}" for c in ("nsnim", "saim") for f in FIGS[:4]]
    _assert_pngs(expected)
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in expected)


def test_plot_missing_node_nan_E_and_truncation(nsnim: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    doc = _legacy_doc(nsnim["record"])
    nodes = doc["nodes"]
    nodes["3"] = nodes["3"][:5]  # node 3 stopped reporting after step 4
    for e in nodes["2"][2:4]:
        e["E"] = None  # truth unknown
    nodes["2"][5].update(E=7.5, contained=False, assumptions_ok=False)  # a miss after a broken assumption
    nodes["7"] = nodes["1"]  # a node the truth knows nothing about
    doc["meta"]["node_ids"] = list(range(1, 8))
    p = tmp_path / "edited.json"
    p.write_text(json.dumps(doc))
    rec = load_record(p)
    assert np.isnan(rec.nodes[2].E[2]) and len(rec.nodes[3].steps) == 5
    monkeypatch.setattr("netsetest.records.plots.MAX_PANELS", 4)  # 7 nodes > 4 panels: truncated (cheaply)
    files = plot_records([rec], str(tmp_path / "figs"))
    assert sorted(Path(f).name for f in files) == sorted(FIGS)
    _assert_pngs([Path(f) for f in files])
