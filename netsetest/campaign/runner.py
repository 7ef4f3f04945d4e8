"""A campaign from start to end: the runs not yet in its results go to an engine, each outcome becomes rows.

Rows are written every ``FLUSH_S`` seconds or ``FLUSH_RUNS`` runs, and at the end; on Ctrl-C (a
KeyboardInterrupt here) the engine is stopped, what came back is written, and :func:`run_campaign`
returns with ``interrupted`` set: the next campaign on the same directory runs only the rest.  The
results are compacted (store.py, :meth:`Store.compact`) before the runs, where an earlier session left
its files as they were (a Ctrl-C, a crash), and once every run is back.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from netsetest.campaign.engines import Engine
from netsetest.campaign.rows import ERROR, rows_of
from netsetest.campaign.spec import Campaign
from netsetest.campaign.store import Compaction, Store
from netsetest.campaign.worker import RunTask

FLUSH_S = 10.0  # a crash loses at most this much finished work (its runs run again on resume)
FLUSH_RUNS = 200  # nor more runs than this: a few files per flush keep resume's read of the keys fast


@dataclass
class Tally:
    """Where a campaign stands: ``total`` runs, ``skipped`` already in the results when it started, ``done``
    this time (of them ``failed``: a verdict other than PASS, and ``errors``: no verdict at all); the results'
    compactions (before the runs, and after them unless interrupted)."""

    total: int
    skipped: int
    done: int = 0
    failed: int = 0
    errors: int = 0
    interrupted: bool = False
    started: float = 0.0
    compactions: list[Compaction] = field(default_factory=list)

    @property
    def todo(self) -> int:
        return self.total - self.skipped

    def eta_s(self) -> float | None:
        """Seconds left at this campaign's pace so far (None before the first run is back)."""
        if not self.done:
            return None
        return (time.monotonic() - self.started) / self.done * (self.todo - self.done)


def tasks_of(c: Campaign, keys: set[str]) -> list[RunTask]:
    """The tasks of the campaign's runs whose key is not in ``keys``, in the file's order."""
    return [RunTask(p.key, p.spec, p.info.settings_digest, c.figures, c.exact_fault_bounds, c.records) for p in c.runs if p.key not in keys]


def run_campaign(c: Campaign, store: Store, engine: Engine, progress: Callable[[Tally], None] | None = None) -> Tally:
    """Run what ``store`` does not hold yet (module doc); the engine is closed and the rows written whatever happens."""
    tasks = tasks_of(c, store.written)
    planned = {p.key: p for p in c.runs}
    tally = Tally(total=len(c.runs), skipped=len(c.runs) - len(tasks), started=time.monotonic())
    if progress is not None:
        progress(tally)
    last_flush, unflushed = time.monotonic(), 0
    try:
        tally.compactions.append(store.compact())  # on resume: what an interrupted session left in many files
        for o in engine.outcomes(tasks):
            p = planned[o.key]
            rows = rows_of(c, p, o)
            if not store.add(o.key, rows):  # the engine ran it twice (a worker lost after it finished): counted once
                continue
            if o.record is not None:
                store.save_record(o.key, *o.record, o.summary)
            tally.done += 1
            tally.errors += rows[0]["verdict"] == ERROR
            tally.failed += rows[0]["verdict"] != ERROR and rows[0]["exit_code"] != 0
            unflushed += 1
            if unflushed >= FLUSH_RUNS or time.monotonic() - last_flush >= FLUSH_S:
                store.flush()
                last_flush, unflushed = time.monotonic(), 0
            if progress is not None:
                progress(tally)
    except KeyboardInterrupt:
        tally.interrupted = True
    finally:
        engine.close()
        store.flush()
    if not tally.interrupted:
        try:
            tally.compactions.append(store.compact())
        except KeyboardInterrupt:  # the results are whole either way; the next session compacts them
            tally.interrupted = True
    return tally
