"""A campaign's results directory: the Parquet dataset of its rows, its records, and the lock that keeps it one writer's.

    DIR/runs/estimator=<name>/case=<case>/part-<id>.parquet   one row per run × node (rows.py), hive partitions
    DIR/records/<run key>.json.gz                             each run's record, when the campaign keeps them
    DIR/.lock                                                 held while a campaign writes DIR
    DIR/.work/                                                files and partitions being written, outside the dataset

pandas (``pd.read_parquet("DIR/runs")``), polars (``pl.read_parquet("DIR/runs/**/*.parquet", hive_partitioning=True)``)
and DuckDB (``read_parquet('DIR/runs/**/*.parquet', hive_partitioning = true)``) read the dataset as it is.

Each file is written in ``DIR/.work`` and renamed into its partition once whole (an atomic rename; polars and
DuckDB read every file their glob matches, a hidden one too, so nothing half written is ever under ``DIR/runs``),
and a run's rows all go to one file: after a crash at any moment, a run is in the dataset with all its rows or
not at all, and the next campaign runs it again.  The keys already written are read once at start; a run is
written at most once.

Every flush adds a file per partition, so a long campaign leaves many small files (519 for 804 runs), and every
reader, the resume's read of the keys first, opens each one.  :meth:`Store.compact` rewrites a partition's small
files into one.  The partition as it will be (the new file, and hard links to the files left as they are) is
built in ``DIR/.work/<id>/``, outside the dataset, and swapped with the partition's directory in one step
(renameat2's RENAME_EXCHANGE: a reader lists the old partition or the new one, never both, never neither); then
the old files, now in ``DIR/.work/<id>/``, are removed.  A kill at any moment leaves each run once in the
dataset, and whatever is left in ``DIR/.work`` (a file not renamed into place, the new files not swapped in, or the
old ones swapped out) holds no run the dataset lacks: the next :class:`Store` removes it.  Where the filesystem cannot swap two
directories the files stay as they are (:attr:`Compaction.skipped` says why).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fcntl
import os
import shutil
import signal
import threading
import time
import uuid
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING

from netsetest.campaign.rows import COLUMNS, PARTITIONS
from netsetest.campaign.spec import CampaignError
from netsetest.extras import require

if TYPE_CHECKING:
    import pyarrow as pa

    from netsetest.records.meta import RunMeta
    from netsetest.records.summary import RunSummary

RUNS, RECORDS, LOCK, WORK = "runs", "records", ".lock", ".work"
PART_PREFIX, STAGING_PREFIX = "part-", ".part-"
COMPACT_SMALL_BYTES = 64 * 2**20  # a file under this size is rewritten with its partition's others; a larger one is left as it is
AT_FDCWD, RENAME_EXCHANGE = -100, 2  # <fcntl.h>, <linux/fs.h>: renameat2's paths as given, the two swapped


@dataclass(frozen=True)
class Compaction:
    """What :meth:`Store.compact` did: the dataset's files before and after, the partitions it rewrote, its wall
    time, and why it stopped where it did not finish (``skipped``: the filesystem cannot swap two directories, a
    disk full, …; what it had not swapped in is as it was)."""

    files_before: int
    files_after: int
    partitions: int
    wall_s: float
    skipped: str | None = None


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
        shutil.rmtree(self.root / WORK, ignore_errors=True)  # what a killed campaign never renamed or swapped in: no run the dataset lacks
        for leftover in self.root.rglob(f"{STAGING_PREFIX}*"):  # a record a killed campaign never renamed (and a file of an older version's)
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
        (self.root / WORK).mkdir(exist_ok=True)
        with _no_interrupt():  # a Ctrl-C between a rename and forgetting its rows would write them twice
            for values, rows in groups.items():
                where = self.runs.joinpath(*(f"{p}={v}" for p, v in zip(PARTITIONS, values)))
                where.mkdir(parents=True, exist_ok=True)
                name = f"{uuid.uuid4().hex}.parquet"
                staging = self.root / WORK / name
                pq.write_table(pa.Table.from_pylist(rows, schema=schema), staging)
                os.replace(staging, where / f"{PART_PREFIX}{name}")
            n = len(self.pending)
            self.pending = []
        return n

    def compact(self) -> Compaction:
        """Rewrite each partition's small files into one, a partition at a time, each swapped in whole (module doc);
        what is queued is written first."""
        self.flush()
        t0, before, rewritten = time.monotonic(), self.files(), 0
        for part in sorted({f.parent for f in before}):
            small = sorted(f for f in part.glob(f"{PART_PREFIX}*.parquet") if f.stat().st_size < COMPACT_SMALL_BYTES)
            if len(small) < 2:
                continue
            work = self.root / WORK / uuid.uuid4().hex
            try:
                _compact(part, small, work)  # Ctrl-C, a kill: the dataset as it was or compacted, ``work`` left to the next Store
            except (OSError, ValueError) as exc:  # ValueError: a file of other columns (another version's) to merge
                shutil.rmtree(work, ignore_errors=True)  # before the swap the new files, after it the old ones
                return Compaction(len(before), len(self.files()), rewritten, time.monotonic() - t0, f"{part.relative_to(self.root)}: {exc}")
            rewritten += 1
        return Compaction(len(before), len(self.files()), rewritten, time.monotonic() - t0)

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


def _compact(part: Path, small: list[Path], work: Path) -> None:
    """The partition ``part`` with its ``small`` files merged into one: built in ``work`` (its other files hard-linked),
    swapped with ``part``, and the old files (then in ``work``) removed."""
    import pyarrow.parquet as pq

    work.mkdir(parents=True)
    for f in part.iterdir():
        if f not in small:
            os.link(f, work / f.name)  # a large file, kept as it is: a second name, not a copy
    merged = work / f"{PART_PREFIX}{uuid.uuid4().hex}.parquet"
    schema = _schema()
    with pq.ParquetWriter(merged, schema) as writer:  # a file at a time: memory for one file, not the partition
        for f in small:
            writer.write_table(pq.ParquetFile(f).read())  # ValueError where its columns are not this version's
    rows = sum(pq.ParquetFile(f).metadata.num_rows for f in small)
    if pq.ParquetFile(merged).metadata.num_rows != rows:  # read back: the file is whole before it replaces any
        raise OSError(f"the merged file holds {pq.ParquetFile(merged).metadata.num_rows} rows, its {len(small)} files {rows}")
    _fsync(merged)
    _fsync(work)
    _exchange(work, part)
    shutil.rmtree(work)


def _fsync(path: Path) -> None:
    """``path`` (a file or a directory) on the disk: a merged file replaces finished runs' only copy."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _exchange(a: Path, b: Path) -> None:
    """Swap the directories ``a`` and ``b`` in one step: renameat2(2) with RENAME_EXCHANGE (Linux 3.15, glibc 2.28);
    OSError where the system or the filesystem cannot (nothing moved then)."""
    renameat2 = getattr(ctypes.CDLL(None, use_errno=True), "renameat2", None)
    if renameat2 is None:
        raise OSError(errno.ENOSYS, "this system cannot swap two directories in one step (no renameat2: Linux 3.15 and glibc 2.28 have it)")
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if renameat2(AT_FDCWD, os.fsencode(a), AT_FDCWD, os.fsencode(b), RENAME_EXCHANGE) != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"cannot swap two directories in one step here ({os.strerror(err)})")
