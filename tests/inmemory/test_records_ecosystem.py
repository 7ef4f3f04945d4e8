"""Records in the tools users already have: MCAP (Foxglove) and per-node Parquet / CSV tables (pandas)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from netsetest.cli.main import main
from netsetest.config.schema import load_topology
from netsetest.records import mcap_io
from netsetest.records.export import COLUMNS
from netsetest.records.record import RecordError, load_record, save_record
from netsetest.records.truth import truth_json
from netsetest.runtime.inmemory import run_inmemory

ROOT = Path(__file__).resolve().parents[2]
STEPS = 10


@pytest.fixture(scope="module")
def streamed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    """The same run streamed by the collector to ``.mcap`` as it goes (and kept in memory)."""
    path = tmp_path_factory.mktemp("stream") / "streamed.mcap"
    res = run_inmemory(load_topology(ROOT / "topologies" / "paper6_lossy.toml", steps=STEPS), record=str(path), keep=True)
    return path, res


@pytest.fixture(scope="module")
def records(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One in-memory run saved as JSON and as MCAP (the same parts)."""
    res = run_inmemory(load_topology(ROOT / "topologies" / "paper6_lossy.toml", steps=STEPS))
    d = tmp_path_factory.mktemp("rec")
    out = {"json": d / "run.json", "mcap": d / "run.mcap"}
    for p in out.values():
        save_record(p, res.meta, res.parts["truth"], res.parts["nodes"], res.summary)
    return out


def _same_record(a, b) -> None:
    assert a.meta == b.meta and a.truth == b.truth and a.summary == b.summary
    assert a.raw_nodes == b.raw_nodes
    assert sorted(a.nodes) == sorted(b.nodes)
    for i in a.nodes:
        for f in ("steps", "xhat", "P", "rho", "contained", "assumptions_ok", "solve_ms"):
            assert np.array_equal(getattr(a.nodes[i], f), getattr(b.nodes[i], f)), (i, f)
        assert np.array_equal(a.nodes[i].E, b.nodes[i].E, equal_nan=True)


def test_mcap_record_matches_the_json_record(records: dict[str, Path], tmp_path: Path) -> None:
    a, b = load_record(records["json"]), load_record(records["mcap"])
    _same_record(a, b)
    assert a.summary.losses_total > 0  # the lossy scenario: drops are in the record
    # converting a loaded record gives the same again
    mcap_io.write_mcap(a, tmp_path / "converted.mcap")
    _same_record(a, load_record(tmp_path / "converted.mcap"))


def test_mcap_channels_schemas_and_bounds_read_with_the_mcap_reader(records: dict[str, Path]) -> None:
    rec = load_record(records["json"])
    ids = rec.meta.node_ids
    counts: dict[str, int] = {}
    with open(records["mcap"], "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None and summary.chunk_indexes  # indexed: Foxglove seeks without a full scan
        for schema, channel, message in reader.iter_messages():
            assert channel.message_encoding == "json" and schema is not None and schema.encoding == "jsonschema"
            doc = json.loads(schema.data)
            assert doc["title"] == schema.name == mcap_io.schema_of(channel.topic)
            msg = json.loads(message.data)
            unknown = set(msg) - set(doc["properties"])
            if channel.topic != mcap_io.TOPIC_VERDICT and channel.topic != mcap_io.TOPIC_META:
                assert not unknown, (channel.topic, unknown)  # every field is described by its schema
            assert set(doc["required"]) <= set(msg), channel.topic
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic.endswith("/state"):
                i = int(channel.topic.split("/")[2])
                tr = rec.nodes[i]
                n = int(np.flatnonzero(tr.steps == msg["step"])[0])
                for name, j in mcap_io.COMPONENTS:
                    lo, hi = tr.bounds(j)
                    assert msg[f"{name}_lower"] == pytest.approx(lo[n], rel=1e-15, abs=1e-15)
                    assert msg[f"{name}_upper"] == pytest.approx(hi[n], rel=1e-15, abs=1e-15)
                assert message.log_time == rec.meta.started_ns + round(msg["step"] * rec.meta.tau_s * 1e9)
            if channel.topic.endswith("/drops"):
                i = int(channel.topic.split("/")[2])
                entry = next(e for e in rec.raw_nodes[str(i)] if e["step"] == msg["step"])
                assert msg["missing"] == entry["missing"] and msg["used"] == entry["used"]
    K = STEPS + 1
    want = {mcap_io.TOPIC_META: 1, mcap_io.TOPIC_TRUTH: K, mcap_io.TOPIC_VERDICT: 1}
    for i in ids:
        want |= {mcap_io.state_topic(i): K, mcap_io.input_topic(i): K, mcap_io.drops_topic(i): K}
    assert counts == want


def test_streaming_writer_flushes_every_message_and_unfinished_file_is_partial(records: dict[str, Path], tmp_path: Path) -> None:
    rec = load_record(records["json"])
    path = tmp_path / "live.mcap"
    w = mcap_io.McapRecordWriter(path)
    sizes = [path.stat().st_size]
    w.meta(rec.meta)
    sizes.append(path.stat().st_size)
    for t in rec.truth[:3]:
        w.truth(t)
        sizes.append(path.stat().st_size)
        for i in rec.meta.node_ids:
            w.state(i, rec.raw_nodes[str(i)][t["step"]])
            sizes.append(path.stat().st_size)
    assert all(b > a for a, b in zip(sizes, sizes[1:])), sizes  # each call reached the file
    part = load_record(path)  # no verdict yet: the run did not finish
    assert part.partial and part.summary is None and part.last_complete_step == rec.truth[2]["step"]
    assert all(len(part.raw_nodes[str(i)]) == 3 for i in rec.meta.node_ids)
    for t in rec.truth[3:]:
        w.truth(t)
        for i in rec.meta.node_ids:
            w.state(i, rec.raw_nodes[str(i)][t["step"]])
    w.summary(rec.summary)
    w.close()
    _same_record(rec, load_record(path))


def test_mcap_non_finite_numbers_become_null(records: dict[str, Path], tmp_path: Path) -> None:
    rec = load_record(records["json"])
    nodes = json.loads(json.dumps(rec.raw_nodes))
    nodes["2"][1]["solve_ms"] = math.nan
    path = tmp_path / "nan.mcap"
    save_record(path, rec.meta, rec.truth, nodes, rec.summary)
    with open(path, "rb") as fh:
        for _, channel, message in make_reader(fh).iter_messages(topics=[mcap_io.state_topic(2)]):
            json.loads(message.data, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert load_record(path).raw_nodes["2"][1]["solve_ms"] is None


def test_foreign_and_cut_mcap_raise_record_error(records: dict[str, Path], tmp_path: Path) -> None:
    data = records["mcap"].read_bytes()
    cases = {"cut_in_magic.mcap": data[:5], "garbage.mcap": b"not an mcap file at all"}
    for name, content in cases.items():
        p = tmp_path / name
        p.write_bytes(content)
        with pytest.raises(RecordError, match=str(p)):
            load_record(p)
    assert main(["inspect", str(tmp_path / "garbage.mcap")]) == 2


def test_run_record_mcap_from_the_cli(tmp_path: Path) -> None:
    p = tmp_path / "cli.mcap"
    assert main(["run", str(ROOT / "topologies" / "paper6.toml"), "--mode", "inmemory", "--steps", "4", "--record", str(p), "--quiet"]) == 0
    rec = load_record(p)
    assert [int(k) for k in rec.nodes[1].steps] == list(range(5)) and rec.summary.violations_total == 0


# ------------------------------------------------------------------------------------ export


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_export_tables_round_trip_with_pandas(fmt: str, records: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pd = pytest.importorskip("pandas")
    out = tmp_path / fmt
    assert main(["export", str(records["mcap"]), f"--{fmt}", str(out)]) == 0
    rec = load_record(records["json"])
    files = capsys.readouterr().out.split()
    assert sorted(files) == sorted(str(out / f"node_{i}.{fmt}") for i in rec.nodes)
    for i in rec.nodes:
        df = pd.read_csv(out / f"node_{i}.csv") if fmt == "csv" else pd.read_parquet(out / f"node_{i}.parquet")
        assert tuple(df.columns) == COLUMNS
        rows = rec.state_rows(i)
        assert list(df["step"]) == [r["step"] for r in rows]
        assert df["contained"].dtype == bool and df["assumptions_ok"].dtype == bool
        for col in ("beta", "r", "fault"):
            for part in ("estimate", "lower", "upper", "true"):
                want = np.array([np.nan if r[f"{col}_{part}"] is None else r[f"{col}_{part}"] for r in rows], dtype=float)
                assert np.array_equal(df[f"{col}_{part}"].to_numpy(dtype=float), want, equal_nan=True), (i, col, part)
        assert np.array_equal(df["E"].to_numpy(dtype=float), rec.nodes[i].E, equal_nan=True)
        assert np.array_equal(df["rho"].to_numpy(), rec.nodes[i].rho)
        assert np.allclose(df["t"].to_numpy(), rec.nodes[i].steps * rec.meta.tau_s, rtol=0, atol=1e-12)
        assert list(df["status"]) == rec.nodes[i].status
        assert set(df["node"]) == {i}
    # the directory read at once (pandas, polars): the rows still say which node they are (they did not)
    together = pd.concat([pd.read_csv(p) for p in sorted(out.glob("*.csv"))]) if fmt == "csv" else pd.read_parquet(out)
    assert sorted(set(together["node"])) == sorted(rec.nodes) and len(together) == sum(len(t.steps) for t in rec.nodes.values())


def test_export_parquet_without_pyarrow_exits_2(
    records: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # import pyarrow now raises ImportError
    assert main(["export", str(records["json"]), "--parquet", str(tmp_path / "pq")]) == 2
    err = capsys.readouterr().err
    assert "pyarrow" in err and "netsetest[export]" in err and "Traceback" not in err


@pytest.mark.parametrize(
    "missing, argv",
    [
        ("mcap", ["run", str(ROOT / "topologies" / "paper6.toml"), "--mode", "inmemory", "--record", "{tmp}/r.mcap", "--quiet"]),
        ("mcap", ["inspect", "{tmp}/r.mcap"]),
        ("matplotlib", ["plot", "{tmp}/r.json", "--out", "{tmp}/figs"]),
    ],
)
def test_missing_optional_dependency_exits_2_before_any_work(
    missing: str, argv: list[str], records: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    if argv[0] != "run":  # run writes it (an existing record is refused before the missing extra is named)
        (tmp_path / "r.mcap").write_bytes(records["mcap"].read_bytes())
    (tmp_path / "r.json").write_bytes(records["json"].read_bytes())
    monkeypatch.setitem(sys.modules, missing, None)
    if missing == "matplotlib":
        monkeypatch.delitem(sys.modules, "netsetest.records.plots", raising=False)
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert f"needs {missing}" in err and "pip install 'netsetest[" in err and "Traceback" not in err
    assert not (tmp_path / "figs").exists()


def test_cvxpy_backend_without_cvxpy_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    from netsetest.estimator.sdp import LocalEstimator
    from netsetest.extras import MissingExtra

    sc = load_topology(ROOT / "topologies" / "paper6.toml", steps=2)
    monkeypatch.setitem(sys.modules, "cvxpy", None)
    with pytest.raises(MissingExtra, match=r"netsetest\[cvxpy\]"):
        LocalEstimator.for_node(sc, 1, backend="cvxpy")


def test_every_mcap_message_validates_against_its_json_schema(records: dict[str, Path]) -> None:
    """What Foxglove reads: each schema is valid JSON Schema (2020-12) and every message satisfies it."""
    jsonschema = pytest.importorskip("jsonschema")
    n = 0
    with open(records["mcap"], "rb") as fh:
        for schema, _, message in make_reader(fh).iter_messages():
            doc = json.loads(schema.data)
            jsonschema.Draft202012Validator.check_schema(doc)
            jsonschema.Draft202012Validator(doc).validate(json.loads(message.data))
            n += 1
    assert n > 100


def test_streamed_mcap_record_is_the_run_and_validates(streamed: tuple[Path, object]) -> None:
    """``--record run.mcap`` goes through the collector's sink: the file holds what the run kept in memory
    (contested, sector and sector_basis in every state, r and fault_ok in every truth), schema-valid."""
    jsonschema = pytest.importorskip("jsonschema")
    path, res = streamed
    rec = load_record(path)
    assert rec.meta == res.meta and rec.summary == res.summary and [truth_json(t) for t in rec.truth] == res.parts["truth"]  # (the file's keys)
    assert rec.raw_nodes == res.parts["nodes"]
    assert all({"contested", "sector", "sector_basis"} <= set(e) for es in rec.raw_nodes.values() for e in es)
    assert all({"r", "fault_ok"} <= set(t) for t in rec.truth)
    with open(path, "rb") as fh:
        for schema, _, message in make_reader(fh).iter_messages():
            doc = json.loads(schema.data)
            jsonschema.Draft202012Validator(doc).validate(json.loads(message.data))
            if schema.name == "netsetest.NodeState":
                assert set(json.loads(message.data)) - set(mcap_io.DERIVED_STATE_FIELDS) <= set(doc["properties"])


def test_a_finished_mcap_record_is_chunked_indexed_and_on_the_run_clock(tmp_path: Path) -> None:
    """It was written unchunked (Foxglove reads all of a long run to open it) with log times from the epoch
    (Foxglove showed 1970-01-01)."""
    pytest.importorskip("mcap")
    import time

    from mcap.reader import make_reader

    p = tmp_path / "r.mcap"
    t0 = time.time_ns()
    assert main(["run", str(ROOT / "topologies" / "paper6.toml"), "--mode", "inmemory", "--steps", "6", "--record", str(p), "--quiet"]) == 0
    t1 = time.time_ns()
    with open(p, "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None and summary.chunk_indexes and summary.statistics.message_count > 0
    start, end = summary.statistics.message_start_time, summary.statistics.message_end_time
    assert t0 <= start <= t1 and end - start == round(6 * 0.1 * 1e9)  # step k at start + k τs
    assert load_record(p).summary is not None
