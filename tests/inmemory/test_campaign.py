"""``netsetest campaign`` on the local pool: the same rows as the same runs one by one, every run exactly once
after a worker is killed mid-campaign and after Ctrl-C and a resume, failures as rows.

Runs are tiny (a few steps) to keep the suite's CPU small: what is tested is the campaign, not the runs.
How rows are compared (floats within a bound, not to the bit): tests/campaign_helpers.py.
"""

from __future__ import annotations

import dataclasses
import html
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import campaign_helpers
from campaign_helpers import Rows, assert_same_rows, campaign_file_fixture, dataset
from netsetest.campaign.engines import LocalPool
from netsetest.campaign.rows import COLUMNS, ERROR
from netsetest.campaign.runner import run_campaign, tasks_of
from netsetest.campaign.spec import load_campaign
from netsetest.campaign.store import Store
from netsetest.records.record import load_record

pytest.importorskip("pyarrow")

CAMPAIGN = """
name = "test"
[grid]
topology = "paper6"
estimator = ["sdp", "interval"]
case = ["nsnim", "saim"]
seeds = "0-1"
steps = 4
[[runs]]
topology = "paper6_reference"
seeds = [5, 6]
fault_scale = [0.5, 1.0]
steps = 12  # past exact.FROM_STEP: widths over exact exist
[compute]
figures = ["verdict", "widths", "detection", "exact"]
"""


campaign_file = campaign_file_fixture(CAMPAIGN)


@pytest.fixture(scope="module")
def one_by_one(campaign_file: Path) -> Rows:
    return campaign_helpers.one_by_one(campaign_file)


def test_two_workers_give_the_rows_of_the_runs_one_by_one(campaign_file: Path, one_by_one: dict, tmp_path: Path) -> None:
    c = load_campaign(campaign_file)
    assert len(c.runs) == 2 * 2 * 2 + 2 * 2  # the grid and the list
    store = Store(tmp_path / "out")
    tally = run_campaign(c, store, LocalPool(2))
    store.close()
    assert (tally.done, tally.errors, tally.interrupted) == (len(c.runs), 0, False)
    got = dataset(tmp_path / "out")
    assert_same_rows(got, one_by_one)
    assert {r["worker"] for r in got.values()} - {""}, "the rows say which worker ran them"
    assert_readers_read(tmp_path / "out" / "runs", len(got))
    assert_report(campaign_file, tmp_path / "out", got)
    ratios = [r[f"{c}_over_exact"] for r in got.values() for c in ("beta", "r", "fault") if r[f"{c}_over_exact"] is not None]
    assert len(ratios) >= 4 * 6 * 2 and min(ratios) >= 1 - 1e-6, "widths over exact of the 12-step runs, never narrower"


def assert_report(campaign: Path, out: Path, rows: Rows) -> None:
    """``campaign --report`` on finished results runs nothing and writes the summary table and the page: a line per
    estimator, case and signal family, the worst runs with their replay commands."""
    pytest.importorskip("bokeh")
    proc = subprocess.run(
        [sys.executable, "-m", "netsetest", "campaign", str(campaign), "--out", str(out), "--report"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0 and "0 to run" in proc.stderr, proc.stderr
    table = (out / "summary.md").read_text()
    groups = {(r["estimator"], r["case"], r["signals"]) for r in rows.values()}
    assert sum(line.startswith(("| sdp |", "| interval |", "| file |")) for line in table.splitlines()) == len(groups)
    page = (out / "report.html").read_text()
    assert "width over exact: fault" in page and "detection delay against the fault" in page
    replays = {r["replay"] for r in rows.values()}
    assert sum(html.escape(cmd) in page for cmd in replays) == min(len(replays), 20), "the worst runs are listed with their replay commands"


def assert_readers_read(runs: Path, rows: int) -> None:
    """pandas, polars and DuckDB read the dataset as it is, the partitions as columns."""
    import duckdb
    import pandas as pd
    import polars as pl

    names = [c.name for c in COLUMNS]
    df = pd.read_parquet(runs)
    assert len(df) == rows and sorted(df.columns) == sorted(names)
    lf = pl.read_parquet(f"{runs}/**/*.parquet", hive_partitioning=True)
    assert lf.height == rows and sorted(lf.columns) == sorted(names)
    counts = duckdb.sql(f"select estimator, \"case\", count(*) from read_parquet('{runs}/**/*.parquet', hive_partitioning = true) group by all").fetchall()
    assert sum(n for *_, n in counts) == rows and {e for e, *_ in counts} == {"sdp", "interval", "file"}


def test_a_worker_killed_mid_campaign_loses_no_run_and_counts_none_twice(campaign_file: Path, one_by_one: dict, tmp_path: Path) -> None:
    c = load_campaign(campaign_file)
    pool = LocalPool(2)
    killed: list[int] = []

    def kill_one(t) -> None:  # after the first run is back the other worker is mid-run: SIGKILL a worker
        if t.done == 1 and not killed:
            pid = next(iter(pool._pool._processes))  # type: ignore[union-attr]  # started: a run is back
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    store = Store(tmp_path / "out")
    tally = run_campaign(c, store, pool, kill_one)
    store.close()
    assert killed and (tally.done, tally.errors) == (len(c.runs), 0)
    assert_same_rows(dataset(tmp_path / "out"), one_by_one)


def test_a_local_worker_is_one_thread(campaign_file: Path) -> None:
    """Two workers on two cores scale only if neither starts threads of its own beside its run: OpenBLAS starts
    one per extra core unless told otherwise (docs/campaign.md#why-2-workers-gave-116-here); every worker is one
    thread, sampled as each run comes back."""
    psutil = pytest.importorskip("psutil")
    pool = LocalPool(2)
    threads: dict[int, int] = {}
    try:
        for _ in pool.outcomes(tasks_of(load_campaign(campaign_file), set())[:4]):
            for pid in pool._pool._processes:  # type: ignore[union-attr]  # started: a run is back
                threads[pid] = max(threads.get(pid, 0), psutil.Process(pid).num_threads())
    finally:
        pool.close()
    assert len(threads) == 2 and set(threads.values()) == {1}, f"threads per worker: {threads}"


PRELOADED_RUNS = """
import sys
from pathlib import Path
from netsetest.campaign.runner import tasks_of
from netsetest.campaign.spec import load_campaign
from netsetest.campaign.worker import dask_setup, execute
dask_setup(None)
c = load_campaign(Path(sys.argv[1]))
before = set(sys.modules)
for t in tasks_of(c, set()):
    assert execute(t).error is None
print(*sorted(set(sys.modules) - before))
"""


def test_a_worker_that_preloaded_imports_nothing_in_its_sdp_runs(tmp_path: Path) -> None:
    """What the fork server and a Dask worker's ``--preload`` import (worker.PRELOAD, dask_setup) is all an SDP run
    needs, both cases and signal families: no run pays an import (about 0.45 s of CPU in a worker's first run)."""
    path = tmp_path / "sdp.toml"
    path.write_text('[grid]\ntopology = "paper6"\nestimator = "sdp"\ncase = ["nsnim", "saim"]\nsignals = ["paper", "worst"]\nsteps = 3\n')
    proc = subprocess.run([sys.executable, "-c", PRELOADED_RUNS, str(path)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == [], f"imported by the runs: {proc.stdout}"


def test_a_run_that_fails_is_a_row_with_its_cause_and_the_campaign_goes_on(campaign_file: Path, tmp_path: Path) -> None:
    c = load_campaign(campaign_file)
    broken = dataclasses.replace(c.runs[0], info=dataclasses.replace(c.runs[0].info, settings_digest="0" * 16))  # the worker finds other files
    c = dataclasses.replace(c, runs=(broken, *c.runs[1:3]), records=True)  # and each run's record kept
    store = Store(tmp_path / "out")
    tally = run_campaign(c, store, LocalPool(2))
    store.close()
    assert (tally.done, tally.errors) == (3, 1)
    rows = dataset(tmp_path / "out")
    bad = [r for r in rows.values() if r["run_key"] == broken.key]
    assert len(bad) == len(broken.info.node_ids)
    assert all(r["verdict"] == ERROR and "differ from the campaign's" in r["cause"] and r["replay"].startswith("netsetest run ") for r in bad)
    assert all(r["verdict"] == "PASS" for r in rows.values() if r["run_key"] != broken.key)
    records = sorted((tmp_path / "out" / "records").iterdir())
    assert [p.name for p in records] == sorted(f"{p.key}.json.gz" for p in c.runs[1:]), "a record per run that ran, none for the error"
    for path in records:
        rec = load_record(path)
        assert rec.summary is not None and not rec.partial
        row = rows[(path.name.removesuffix(".json.gz"), 1)]
        assert (rec.summary.node(1).steps_covered, rec.summary.node(1).fault_bound_mean_width) == (row["steps_covered"], row["fault_width"])


def _campaign_cli(campaign: Path, out: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "netsetest", "campaign", str(campaign), "--out", str(out), "--workers", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group: Ctrl-C as a terminal sends it, to the group
    )


def test_ctrl_c_saves_what_is_done_and_a_resume_runs_the_rest_once(campaign_file: Path, one_by_one: dict, tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = _campaign_cli(campaign_file, out)
    assert proc.stderr is not None
    for line in proc.stderr:  # the progress lines (stderr is not a terminal: one per run here)
        if line.startswith("campaign: 2/"):
            break
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    deadline = time.monotonic() + 10
    while True:  # nothing of the campaign outlives it (its workers, the fork server)
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        assert time.monotonic() < deadline, "a process of the interrupted campaign is still running"
        time.sleep(0.1)
    first = {k for k, _ in dataset(out)}
    assert 2 <= len(first) < len({k for k, _ in one_by_one}), "interrupted mid-campaign"
    proc = _campaign_cli(campaign_file, out)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert f"{len(first)} already done" in err
    assert_same_rows(dataset(out), one_by_one)
    proc = _campaign_cli(campaign_file, out)  # finished: nothing runs again
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0 and "0 to run" in err
