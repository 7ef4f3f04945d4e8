"""One run of a campaign, in whichever process runs it (a local pool's worker, a Dask worker): :func:`execute`.

The run is ``RunSpec.execute`` (``netsetest run --mode inmemory``), its verdict the collector's summary; a
run that raises is an outcome with its error, never an exception out of here (failures are data).  Nothing
is written here: the outcome goes back to the campaign's process, which alone writes the dataset and the
records, so a worker on another host needs only the topology files (the same values: checked by digest).

A worker imports the run's code (:data:`PRELOAD`) once, before its first run: the local pool's fork server
does, and a Dask worker started with ``--preload netsetest.campaign.worker`` does in :func:`dask_setup`
(without it each Dask worker's first run pays about 0.45 s of CPU for the imports).
"""

from __future__ import annotations

import importlib
import os
import socket
import time
import traceback
from dataclasses import dataclass
from typing import TYPE_CHECKING

from netsetest.runtime.runspec import RunSpec

if TYPE_CHECKING:
    from netsetest.analysis.exact import ExactComparison
    from netsetest.records.meta import RunMeta
    from netsetest.records.summary import RunSummary

# with these an SDP run imports nothing more (scipy.linalg: Clarabel's solve imports it at the first of some
# problems, in a SAIM run); another estimator's module loads at its first run in each worker
PRELOAD = ("netsetest.campaign.worker", "netsetest.runtime.inmemory", "netsetest.analysis.exact", "scipy.linalg")
CAUSE_MAX = 500  # characters of an error kept in a row (the replay command reproduces the whole traceback)


@dataclass(frozen=True)
class RunTask:
    """What a worker is sent: the run, what to compute, and whether to bring its record back."""

    key: str
    spec: RunSpec
    settings_digest: str  # the campaign's files' values: a worker loading other files refuses the run
    figures: tuple[str, ...]
    exact_fault_bounds: str
    record: bool


@dataclass(frozen=True)
class RunOutcome:
    """A run's result as a worker returns it (``summary`` None: ``error`` says why)."""

    key: str
    summary: RunSummary | None
    exact: ExactComparison | None  # "exact" figures asked for: every node's widths over the exact limit
    error: str | None
    record: tuple[RunMeta, list, dict] | None  # (meta, truth, node entries) when asked: the campaign writes the file
    wall_s: float
    cpu_s: float
    worker: str  # host:pid


def dask_setup(worker: object) -> None:
    """Dask's hook for a ``--preload`` module, called as the worker starts: the run's code imported now (module doc)."""
    for name in PRELOAD:
        importlib.import_module(name)


def _worker() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def execute(task: RunTask) -> RunOutcome:
    """Run ``task`` and compute its figures; any exception becomes the outcome's error (type: message, where)."""
    t0, c0 = time.perf_counter(), time.thread_time()  # the run's own CPU: a Dask worker's other threads run beside it
    try:
        sc = task.spec.load()
        if sc.settings_digest != task.settings_digest:
            raise RuntimeError(f"the topology files here differ from the campaign's (settings digest {sc.settings_digest}, expected {task.settings_digest})")
        keep = task.record or "exact" in task.figures
        res = task.spec.execute(keep=keep, scenario=sc)
        exact = None
        if "exact" in task.figures:
            from netsetest.analysis.exact import compare_record, exact_bounds
            from netsetest.records.record import record_from_parts

            assert res.parts is not None  # keep: the record is in memory
            rec = record_from_parts(res.meta, res.parts["truth"], res.parts["nodes"], res.summary)
            exact = compare_record(rec, exact_bounds(sc, rec, task.exact_fault_bounds))  # type: ignore[arg-type]  # one of FaultBounds: the campaign file was checked
        record = (res.meta, res.parts["truth"], res.parts["nodes"]) if task.record and res.parts is not None else None
        return RunOutcome(task.key, res.summary, exact, None, record, time.perf_counter() - t0, time.thread_time() - c0, _worker())
    except Exception as exc:  # a run's failure is a row of the campaign, whatever it is
        where = traceback.extract_tb(exc.__traceback__)[-1]
        error = f"{type(exc).__name__}: {exc} (at {os.path.basename(where.filename)}:{where.lineno})"
        return RunOutcome(task.key, None, None, error[:CAUSE_MAX], None, time.perf_counter() - t0, time.thread_time() - c0, _worker())
