"""Damaged and truncated records: every record tool either works or exits 2 with one line naming the
file and the damage, never a traceback; a dropped, repeated or moved line is found (per-line sequence
numbers), not silently loaded.  Includes the Hypothesis fuzzer of ``load_record`` (arbitrary bytes and
mutated lines; ``NETSETEST_FUZZ_EXAMPLES`` for a long run)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from netsetest.cli.main import main
from netsetest.records.errors import RecordError
from netsetest.records.record import load_record

ROOT = Path(__file__).resolve().parents[2]
STEPS = 6
EXAMPLES = int(os.environ.get("NETSETEST_FUZZ_EXAMPLES", "0")) or None


@pytest.fixture(scope="module")
def lines(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    d = tmp_path_factory.mktemp("rec")
    path = d / "r.json"
    assert (
        main(["run", str(ROOT / "topologies" / "paper6.toml"), "--mode", "inmemory", "--steps", str(STEPS), "--seed", "3", "--record", str(path), "--quiet"])
        == 0
    )
    return path.read_text().splitlines()


def _write(tmp_path: Path, name: str, lines: list[str], tail: str = "\n") -> Path:
    p = tmp_path / name
    p.write_text("\n".join(lines) + tail)
    return p


def _tools(path: Path, out: Path) -> list[list[str]]:
    return [["inspect", str(path)], ["inspect", str(path), "--json"], ["exact", str(path)], ["export", str(path), "--csv", str(out)]]


def _exits_cleanly(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(argv)
    err = capsys.readouterr().err
    assert code in (0, 2), (argv, code, err)
    assert "Traceback" not in err
    return code, err


def test_every_truncation_loads_as_partial_or_is_refused(lines: list[str], tmp_path: Path, capsys) -> None:
    """Cut at every line boundary and in the middle of every line: load_record gives a partial record
    (whose node tracks stop at its last complete step) or a RecordError; the tools exit 0 or 2 (`exact`
    raised IndexError on 85 of 114 records cut mid-step)."""
    for n in range(1, len(lines)):
        for tail in ("\n", "\n" + lines[n][: len(lines[n]) // 2]):
            p = _write(tmp_path, "cut.json", lines[:n], tail)
            try:
                rec = load_record(p)
            except RecordError:
                continue
            assert rec.partial
            for track in rec.nodes.values():
                assert all(int(k) <= rec.last_complete_step for k in track.steps)
            if n % 7 == 3:  # the tools on a sample of cut points (exact solves a program per bound)
                for argv in _tools(p, tmp_path / f"csv{n}"):
                    _exits_cleanly(argv, capsys)


@pytest.mark.parametrize("damage", ["dropped", "repeated", "moved"])
def test_a_dropped_repeated_or_moved_line_is_damage(lines: list[str], tmp_path: Path, damage: str, capsys) -> None:
    i = len(lines) // 2
    bad = {
        "dropped": lines[:i] + lines[i + 1 :],
        "repeated": lines[: i + 1] + [lines[i]] + lines[i + 1 :],
        "moved": lines[:i] + [lines[i + 1], lines[i]] + lines[i + 2 :],
    }[damage]
    p = _write(tmp_path, "bad.json", bad)
    with pytest.raises(RecordError, match="damaged record"):
        load_record(p)
    for argv in _tools(p, tmp_path / "csv"):
        code, err = _exits_cleanly(argv, capsys)
        assert code == 2 and "damaged record" in err and str(p) in err


def test_records_without_line_numbers_are_still_checked_for_order(lines: list[str], tmp_path: Path) -> None:
    """A record written before sequence numbers loads; a repeated step in it is still found."""
    old = [json.dumps({k: v for k, v in json.loads(x).items() if k != "seq"}, separators=(",", ":")) for x in lines]
    assert load_record(_write(tmp_path, "old.json", old)).summary is not None
    truths = [n for n, x in enumerate(old) if '"kind":"truth"' in x]
    repeated = old[: truths[2] + 1] + [old[truths[2]]] + old[truths[2] + 1 :]
    with pytest.raises(RecordError, match="damaged record"):
        load_record(_write(tmp_path, "old_bad.json", repeated))


@pytest.mark.parametrize("where", ["step", "node", "rho", "seed"])
def test_huge_integers_are_refused_or_harmless(lines: list[str], tmp_path: Path, where: str, capsys) -> None:
    """An integer ≥ 2⁶³ gave OverflowError tracebacks in inspect, plot, exact and export."""
    out = [json.loads(x) for x in lines]
    state = next(o for o in out if o["kind"] == "state")
    if where == "seed":
        out[0]["meta"]["seed"] = 2**64
    elif where == "node":
        state["node"] = 2**64
    else:
        state["entry"][where] = 2**64
    p = _write(tmp_path, "huge.json", [json.dumps(o) for o in out])
    for argv in _tools(p, tmp_path / "csv"):
        _exits_cleanly(argv, capsys)


FUZZ = settings(
    max_examples=EXAMPLES or 120,
    derandomize=EXAMPLES is None,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


@FUZZ
@given(st.binary(max_size=400))
def test_load_record_arbitrary_bytes(tmp_path_factory: pytest.TempPathFactory, data: bytes) -> None:
    p = tmp_path_factory.mktemp("fz") / "r.json"
    p.write_bytes(data)
    try:
        load_record(p)
    except RecordError:
        pass


_JSON = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-(2**70), max_value=2**70) | st.floats() | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3),
    max_leaves=10,
)


@FUZZ
@given(st.data())
def test_load_record_mutated_lines(lines: list[str], tmp_path_factory: pytest.TempPathFactory, data: st.DataObject) -> None:
    """A real record with one to three values replaced anywhere (any JSON value, huge integers included):
    a Record or a RecordError, nothing else."""
    objs = [json.loads(x) for x in lines]
    for _ in range(data.draw(st.integers(1, 3))):
        o = objs[data.draw(st.integers(0, len(objs) - 1))]
        target = o.get("entry") or o.get("meta") or o.get("summary") or o
        if isinstance(target, dict) and target:
            key = data.draw(st.sampled_from(sorted(target)))
            target[key] = data.draw(_JSON)
    p = tmp_path_factory.mktemp("fz") / "r.json"
    p.write_text("\n".join(json.dumps(o) for o in objs) + "\n")
    try:
        load_record(p)
    except RecordError:
        pass


# ------------------------------------------------------------------------------------ MCAP


@pytest.fixture(scope="module")
def mcap_record(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int, int]:
    """A finished MCAP record (chunked, zstd) and the offset and length of its first chunk's record."""
    from mcap.reader import make_reader

    path = tmp_path_factory.mktemp("mcap") / "r.mcap"
    assert (
        main(["run", str(ROOT / "topologies" / "paper6.toml"), "--mode", "inmemory", "--steps", str(STEPS), "--seed", "3", "--record", str(path), "--quiet"])
        == 0
    )
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None and summary.chunk_indexes and summary.chunk_indexes[0].compression == "zstd"
    chunk = summary.chunk_indexes[0]
    return path, chunk.chunk_start_offset, chunk.chunk_length


# a chunk record's fields before its compressed data: opcode 1, record length 8, start and end time 8 + 8,
# uncompressed size 8, uncompressed CRC 4, compression "zstd" 4 + 4, compressed length 8
CHUNK_HEADER = 1 + 8 + 8 + 8 + 8 + 4 + 4 + 4 + 8


def _flipped(data: bytes, positions: list[int]) -> bytes:
    out = bytearray(data)
    for i in positions:
        out[i] ^= 0xFF
    return bytes(out)


@pytest.mark.parametrize("where", [0.25, 0.5, 0.9])
def test_flipped_bytes_in_a_compressed_mcap_chunk_are_damage(mcap_record: tuple[Path, int, int], tmp_path: Path, where: float, capsys) -> None:
    """Flipped bytes inside a zstd chunk gave an uncaught zstandard.ZstdError in inspect, plot, exact
    and export (80 tracebacks on 16 of 27 damaged files): a damaged record, exit 2, like a JSONL one."""
    path, start, length = mcap_record
    data = path.read_bytes()
    i = start + CHUNK_HEADER + int(where * (length - CHUNK_HEADER))
    p = tmp_path / "bad.mcap"
    p.write_bytes(_flipped(data, [i, i + 1, i + 2]))
    with pytest.raises(RecordError, match="damaged record"):
        load_record(p)
    for argv in [*_tools(p, tmp_path / "csv"), ["plot", str(p), "--out", str(tmp_path / "png")]]:
        code, err = _exits_cleanly(argv, capsys)
        assert code == 2 and "damaged record" in err and str(p) in err, (argv, err)
        assert len(err.strip().splitlines()) == 1, err


@FUZZ
@given(st.data())
def test_load_record_mcap_with_flipped_chunk_bytes(mcap_record: tuple[Path, int, int], tmp_path_factory: pytest.TempPathFactory, data: st.DataObject) -> None:
    """One to four bytes flipped in a chunk's compressed data: "damaged record" (its CRC, or zstd, finds
    it), never a partial record read up to the damage, nor another exception."""
    path, start, length = mcap_record
    raw = path.read_bytes()
    positions = data.draw(st.lists(st.integers(start + CHUNK_HEADER, start + length - 1), min_size=1, max_size=4, unique=True))
    p = tmp_path_factory.mktemp("fz") / "r.mcap"
    p.write_bytes(_flipped(raw, positions))
    with pytest.raises(RecordError, match="damaged record"):
        load_record(p)
