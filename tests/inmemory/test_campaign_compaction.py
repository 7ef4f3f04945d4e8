"""A campaign's results compacted (netsetest/campaign/store.py, ``Store.compact``): every row kept exactly once,
pandas, polars and DuckDB read the dataset as it is before, after, and after a kill at each step of a compaction;
the next campaign cleans up after a killed one, and a campaign resumed on compacted results runs only the runs
not done yet.

The rows of the store's tests are made up (every column of rows.COLUMNS, values that tell the runs apart): what
is tested is the store, not the runs.  The resume runs a tiny campaign on the local pool.
"""

from __future__ import annotations

import errno
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from campaign_helpers import Rows, campaign_file_fixture, dataset
from netsetest.campaign import runner, store as store_module
from netsetest.campaign.engines import LocalPool
from netsetest.campaign.rows import COLUMNS
from netsetest.campaign.runner import Tally, run_campaign
from netsetest.campaign.spec import load_campaign
from netsetest.campaign.store import RUNS, WORK, Store
from netsetest.cli.main import main

pytest.importorskip("pyarrow")

NODES = 3
MAX_STEPS = 100  # a compaction of LAYOUT makes about 20 changes on disk
# partition → flushes of (run keys): a run's rows are written by one flush, as the campaign writes them
LAYOUT = {
    ("sdp", "nsnim"): [[f"s{i}" for i in range(8)], ["s8"], ["s9"], ["s10"]],  # 4 files, the first the largest
    ("interval", "saim"): [["i0"], ["i1", "i2"]],  # 2 files
    ("file", "nsnim"): [["f0", "f1"]],  # 1 file: nothing to compact
}
KILL_SCRIPT = """
import os, signal, sys
from pathlib import Path
import pyarrow.parquet as pq
from netsetest.campaign import store as s

out, kill_at, small = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
st = s.Store(out)  # opened before any step is counted
s.COMPACT_SMALL_BYTES = small
steps = 0

def step(f):  # every change the compaction makes on disk is a step; SIGKILL before step kill_at
    def counted(*a, **k):
        global steps
        if steps == kill_at:
            os.kill(os.getpid(), signal.SIGKILL)
        steps += 1
        return f(*a, **k)
    return counted

for name in ("mkdir", "link", "unlink", "rmdir", "rename", "replace"):
    setattr(os, name, step(getattr(os, name)))
s._exchange = step(s._exchange)
pq.ParquetWriter.write_table = step(pq.ParquetWriter.write_table)  # a kill between two: a merged file half written
st.compact()
print(steps)
"""


def _rows(key: str, estimator: str, case: str) -> list[dict]:
    """A made-up run's rows: every column, the run's key in each string, its node in each number."""
    kind = {"string": lambda n, c: f"{c}-{key}", "int64": lambda n, c: n, "float64": lambda n, c: n + 0.5, "bool": lambda n, c: False}
    return [{c.name: kind[c.type](n, c.name) for c in COLUMNS} | {"run_key": key, "estimator": estimator, "case": case, "node": n} for n in range(NODES)]


def _write(out: Path) -> Rows:
    """The results of LAYOUT, a file per flush and partition; the rows written."""
    st = Store(out)
    try:
        for (estimator, case), flushes in LAYOUT.items():
            for keys in flushes:
                for k in keys:
                    assert st.add(k, _rows(k, estimator, case))
                st.flush()
    finally:
        st.close()
    return dataset(out)


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Rows]:
    out = tmp_path_factory.mktemp("compaction") / "out"
    return out, _write(out)


def _copy(written: tuple[Path, Rows], tmp_path: Path) -> Path:
    out = tmp_path / "out"
    shutil.copytree(written[0], out)
    return out


def _files(out: Path) -> dict[tuple[str, str], list[Path]]:
    parts: dict[tuple[str, str], list[Path]] = {}
    for f in sorted((out / RUNS).rglob("*.parquet")):
        parts.setdefault((f.parent.parent.name.split("=")[1], f.parent.name.split("=")[1]), []).append(f)
    return parts


def assert_each_row_once(out: Path, want: Rows) -> None:
    """The dataset as it is: every row of ``want`` once with its values (pyarrow's dataset, as the store reads it),
    and pandas, polars and DuckDB count every row once."""
    import duckdb
    import pandas as pd
    import polars as pl

    got = dataset(out)  # a (run, node) twice fails here
    assert got.keys() == want.keys()
    assert all(got[k] == v for k, v in want.items())
    runs = out / RUNS
    df = pd.read_parquet(runs)
    assert len(df) == len(want) and len(df.groupby(["run_key", "node"])) == len(want)
    lf = pl.read_parquet(f"{runs}/**/*.parquet", hive_partitioning=True)
    assert lf.height == len(want) and lf.select(["run_key", "node"]).unique().height == len(want)
    q = f"select count(*), count(distinct (run_key, node)) from read_parquet('{runs}/**/*.parquet', hive_partitioning = true)"
    assert duckdb.sql(q).fetchall() == [(len(want), len(want))]


def test_compaction_keeps_every_row_once_in_one_file_per_partition(written: tuple[Path, Rows], tmp_path: Path) -> None:
    out = _copy(written, tmp_path)
    before = _files(out)
    assert {p: len(f) for p, f in before.items()} == {p: len(f) for p, f in LAYOUT.items()}
    st = Store(out)
    try:
        comp = st.compact()
    finally:
        st.close()
    assert (comp.files_before, comp.files_after, comp.partitions, comp.skipped) == (7, 3, 2, None)
    after = _files(out)
    assert {p: len(f) for p, f in after.items()} == dict.fromkeys(LAYOUT, 1)
    assert after[("file", "nsnim")] == before[("file", "nsnim")], "a partition of one file is left as it is"
    assert not list((out / WORK).iterdir()), "nothing left beside the dataset"
    assert_each_row_once(out, written[1])


def test_a_file_half_written_by_a_killed_flush_is_outside_the_dataset(written: tuple[Path, Rows], tmp_path: Path) -> None:
    """A flush writes each file in DIR/.work and renames it into its partition whole: what a kill leaves half
    written there is no reader's (polars and DuckDB read every file their glob matches, a hidden one too), and the
    next Store removes it."""
    out = _copy(written, tmp_path)
    (out / WORK / "0123.parquet").write_bytes(b"PAR1 half a file")
    assert_each_row_once(out, written[1])
    Store(out).close()
    assert not (out / WORK).exists()


def test_a_large_file_is_kept_as_it_is_and_the_small_ones_merged(written: tuple[Path, Rows], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = _copy(written, tmp_path)
    large = max(_files(out)[("sdp", "nsnim")], key=lambda f: f.stat().st_size)  # the flush of 8 runs
    assert sum(f.stat().st_size < large.stat().st_size for f in _files(out)[("sdp", "nsnim")]) == 3
    inode = large.stat().st_ino
    monkeypatch.setattr(store_module, "COMPACT_SMALL_BYTES", large.stat().st_size)  # this file and larger: left as they are
    st = Store(out)
    try:
        st.compact()
    finally:
        st.close()
    after = _files(out)[("sdp", "nsnim")]
    assert len(after) == 2 and [f.name for f in after if f.stat().st_ino == inode] == [large.name], "the large file, the same file, and the others' one"
    assert_each_row_once(out, written[1])


def test_a_filesystem_that_cannot_swap_directories_leaves_the_files_as_they_are(
    written: tuple[Path, Rows], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = _copy(written, tmp_path)
    before = _files(out)

    def no_exchange(a: Path, b: Path) -> None:
        raise OSError(errno.EINVAL, "cannot swap two directories in one step here (Invalid argument)")

    monkeypatch.setattr(store_module, "_exchange", no_exchange)
    st = Store(out)
    try:
        comp = st.compact()
    finally:
        st.close()
    assert comp.partitions == 0 and comp.files_after == comp.files_before == 7
    assert comp.skipped is not None and "cannot swap two directories" in comp.skipped and "estimator=" in comp.skipped
    assert _files(out) == before
    assert not list((out / WORK).iterdir()), "the unused merged files are removed"
    assert_each_row_once(out, written[1])


def _compact_killed_at(out: Path, step: int, small: int) -> str:
    """Compact ``out`` in a process of its own, SIGKILLed before its ``step``-th change on disk; its stdout (the
    number of steps, where it finished)."""
    proc = subprocess.run([sys.executable, "-c", KILL_SCRIPT, str(out), str(step), str(small)], capture_output=True, text=True, timeout=120)
    assert proc.returncode in (0, -signal.SIGKILL), proc.stderr
    return proc.stdout if proc.returncode == 0 else ""


@pytest.mark.timeout(600)
def test_a_kill_at_each_step_of_a_compaction_loses_no_row_and_counts_none_twice(written: tuple[Path, Rows], tmp_path: Path) -> None:
    """Every change a compaction makes on disk (a directory made, a file linked, each table written into the merged
    file, the swap, each old file removed), a SIGKILL just before it: the dataset as it is holds every row once for
    every reader; the next Store removes what the killed one left, and its compaction ends with a file per partition."""
    small = max(f.stat().st_size for f in _files(written[0])[("sdp", "nsnim")])  # the largest file, left as it is: a link made too
    step, total = 0, None
    while total is None:
        assert step < MAX_STEPS, "the compaction never ran to its end"
        out = tmp_path / f"k{step}"
        shutil.copytree(written[0], out)
        said = _compact_killed_at(out, step, small)
        if said:
            total = int(said)
            assert step == total, "killed before each step, then one run to its end"
        assert_each_row_once(out, written[1])
        st = Store(out)
        try:
            assert st.written == {k for k, _ in written[1]}
            assert not (out / WORK).exists(), "the killed compaction's work is removed"
            comp = st.compact()
        finally:
            st.close()
        assert comp.skipped is None and {p: len(f) for p, f in _files(out).items()} == dict.fromkeys(LAYOUT, 1)
        assert_each_row_once(out, written[1])
        shutil.rmtree(out)
        step += 1
    # at least: made 2 directories, linked 1 file, wrote 2 + 3 tables, swapped 2, removed 2 + 4 files and 2 directories
    assert total >= 2 + 1 + 5 + 2 + 8, f"{total} steps"


CAMPAIGN = """
name = "resume"
[grid]
topology = "paper6"
estimator = ["sdp", "interval"]
case = ["nsnim", "saim"]
seeds = "0-2"
steps = 3
"""


campaign_file = campaign_file_fixture(CAMPAIGN)


def test_a_campaign_resumed_on_compacted_results_runs_only_what_is_not_done(
    campaign_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Interrupted after five runs with a file per run (an interrupted campaign is not compacted at its end), then
    ``netsetest campaign`` again: it compacts the results first, runs only the runs not done, every run once, and
    compacts again at the end (a file per estimator × case); a third start has nothing to run."""
    c = load_campaign(campaign_file)
    monkeypatch.setattr(runner, "FLUSH_RUNS", 1)  # a file per run and partition: many small files

    def stop_after_5(t: Tally) -> None:
        if t.done >= 5:
            raise KeyboardInterrupt

    out = tmp_path / "out"
    st = Store(out)
    first = run_campaign(c, st, LocalPool(2), stop_after_5)
    st.close()
    assert first.interrupted and first.done == 5 and [x.files_after for x in first.compactions] == [0], "interrupted: not compacted at the end"
    assert len(dataset(out)) == 5 * 6 and len(_all_files(out)) == 5, "a file per run"
    assert main(["campaign", str(campaign_file), "--out", str(out), "--workers", "2", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert f"{len(c.runs)} runs, 5 already done, {len(c.runs) - 5} to run" in err and f"ran {len(c.runs) - 5} run(s)" in err, err
    assert "compacted the results, 5 files into" in err and err.count("compacted the results") == 2, err
    rows = dataset(out)  # a run twice fails here
    assert {k for k, _ in rows} == {p.key for p in c.runs} and len(rows) == len(c.runs) * 6
    assert len(_all_files(out)) == 4, "a file per estimator × case"
    assert main(["campaign", str(campaign_file), "--out", str(out), "--dry-run"]) == 0
    assert f"{len(c.runs)} already in {out}, 0 to run" in capsys.readouterr().out


def _all_files(out: Path) -> list[Path]:
    return sorted((out / RUNS).rglob("*.parquet"))
