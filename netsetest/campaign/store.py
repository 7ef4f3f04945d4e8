"""A campaign's results directory: the Parquet dataset of its rows, its records, and the lock that keeps it one writer's.

    DIR/runs/estimator=<name>/case=<case>/part-<id>.parquet   one row per run × node (rows.py), hive partitions
    DIR/records/<run key>.json.gz                             each run's record, when the campaign keeps them
    DIR/.lock                                                 held while a campaign writes DIR

pandas (``pd.read_parquet("DIR/runs")``), polars (``pl.read_parquet("DIR/runs/**/*.parquet", hive_partitioning=True)``)
and DuckDB (``read_parquet('DIR/runs/**/*.parquet', hive_partitioning = true)``) read the dataset as it is.

Each file is written under a name starting with '.' (which readers skip) and renamed into place once whole
(an atomic rename), and a run's rows all go to one file: after a crash at any moment, a run is in the
dataset with all its rows or not at all, and the next campaign runs it again.  The keys already written are
read once at start; a run is written at most once.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import signal
import threading
import uuid
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, TYPE_CHECKING

from netsetest.campaign.rows import COLUMNS, PARTITIONS
from netsetest.campaign.spec import CampaignError
from netsetest.extras import require

if TYPE_CHECKING:
    import pyarrow as pa

    from netsetest.records.meta import RunMeta
    from netsetest.records.summary import RunSummary

RUNS, RECORDS, LOCK = "runs", "records", ".lock"
PART_PREFIX, STAGING_PREFIX = "part-", ".part-"


@contextlib.contextmanager
def _no_interrupt() -> Iterator[None]:
    """SIGINT held back (delivered when the block ends) where the main thread runs it; elsewhere nothing to hold."""
    main = threading.current_thread() is threading.main_thread()
    if main:
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        if main:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _schema() -> pa.Schema:
    import pyarrow as pa

    return pa.schema([(c.name, getattr(pa, c.type)()) for c in COLUMNS if c.name not in PARTITIONS])


class Store:
    """The results directory of one campaign process (module doc); :meth:`close` releases it."""

    def __init__(self, out: str | Path) -> None:
        require("pyarrow", "netsetest campaign (its Parquet dataset)")
        self.root = Path(out)
        self.runs = self.root / RUNS
        try:
            self.runs.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CampaignError(f"{self.root}: cannot create the results directory: {exc.strerror}") from None
        self._lock = self._locked()
        for leftover in self.root.rglob(f"{STAGING_PREFIX}*"):  # a file a killed campaign never renamed: its runs were never counted
            leftover.unlink()
        self.written: set[str] = self.keys()
        self.pending: list[dict] = []

    def _locked(self) -> IO[bytes]:
        fh = open(self.root / LOCK, "ab")
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.close()
            raise CampaignError(f"{self.root}: another campaign is writing these results") from None
        return fh

    def files(self) -> list[Path]:
        return sorted(self.runs.rglob(f"{PART_PREFIX}*.parquet"))

    def keys(self) -> set[str]:
        """The run keys in the dataset (CampaignError naming a file that is not one of its Parquet files)."""
        import pyarrow as pa

        if not self.files():
            return set()
        try:
            return set(self.dataset().to_table(columns=["run_key"]).column(0).to_pylist())
        except (pa.ArrowException, OSError) as exc:
            raise CampaignError(f"{self.runs}: a damaged results file ({exc}); move it away, and its runs run again") from None

    def dataset(self):  # pyarrow.dataset.Dataset
        import pyarrow.dataset as ds

        return ds.dataset(self.runs, format="parquet", partitioning="hive")

    def add(self, key: str, rows: list[dict]) -> bool:
        """Queue a run's rows for the next :meth:`flush`; False (nothing queued) if the run is already in."""
        if key in self.written:
            return False
        self.written.add(key)
        self.pending += rows
        return True

    def flush(self) -> int:
        """Write the queued rows, one file per partition, each renamed into place once whole; the rows written."""
        if not self.pending:
            return 0
        import pyarrow as pa
        import pyarrow.parquet as pq

        schema = _schema()
        groups: dict[tuple, list[dict]] = {}
        for row in self.pending:
            groups.setdefault(tuple(row[p] for p in PARTITIONS), []).append(row)
        with _no_interrupt():  # a Ctrl-C between a rename and forgetting its rows would write them twice
            for values, rows in groups.items():
                where = self.runs.joinpath(*(f"{p}={v}" for p, v in zip(PARTITIONS, values)))
                where.mkdir(parents=True, exist_ok=True)
                name = f"{uuid.uuid4().hex}.parquet"
                staging = where / f"{STAGING_PREFIX}{name}"
                pq.write_table(pa.Table.from_pylist(rows, schema=schema), staging)
                os.replace(staging, where / f"{PART_PREFIX}{name}")
            n = len(self.pending)
            self.pending = []
        return n

    def save_record(self, key: str, meta: RunMeta, truth: list, nodes: dict, summary: RunSummary | None) -> Path:
        """The run's record as DIR/records/<key>.json.gz, renamed into place once whole."""
        from netsetest.records.record import save_record

        where = self.root / RECORDS
        where.mkdir(exist_ok=True)
        path = where / f"{key}.json.gz"
        staging = where / f"{STAGING_PREFIX}{key}.json.gz"
        save_record(staging, meta, truth, nodes, summary)
        os.replace(staging, path)
        return path

    def table(self, keys: Iterable[str] | None = None):  # pyarrow.Table
        """Every row of the dataset (``keys``: of these runs only), partition columns included."""
        import pyarrow as pa
        import pyarrow.dataset as ds

        if not self.files():
            return _schema().empty_table()
        d = self.dataset()
        flt = None if keys is None else ds.field("run_key").isin(pa.array(sorted(set(keys)), pa.string()))
        return d.to_table(filter=flt)

    def close(self) -> None:
        self.flush()
        self._lock.close()
