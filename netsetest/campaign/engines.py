"""Where a campaign's runs go: a pool of local worker processes (the default), or an existing Dask cluster.

Both hand back each task's :class:`~netsetest.campaign.worker.RunOutcome` as it finishes
(:meth:`Engine.outcomes`), in any order; the campaign keys every outcome by its run key, so an engine that
runs a task twice (a worker lost after it finished) never counts it twice.

**Local pool** (:class:`LocalPool`): the standard library's ``ProcessPoolExecutor``, one worker per core,
started by a fork server that has imported the run's code (``worker.PRELOAD``) once (``multiprocessing``'s ``forkserver``: no
thread of this process is forked).  The pool holds one run per worker, so a worker that dies takes its own
run with it and the runs it was not yet given stay queued.  When one dies the executor is broken as a
whole: it is replaced, and every run that was in flight runs again, alone (one at a time), so the run that
kills its worker is told apart from its neighbours; a run whose worker died ``LOST_ALONE`` times while it
ran alone is an error row ("its worker died"), and the campaign goes on.

**Dask** (:class:`DaskCluster`, ``--cluster tcp://HOST:PORT``, the ``cluster`` extra): the scheduler of an
existing ``dask scheduler`` and its ``dask worker`` processes.  Dask re-runs a task whose worker is lost
elsewhere, and gives up on a task that killed ``distributed.scheduler.allowed-failures`` workers
(KilledWorker): that run is an error row.  Why Dask rather than Ray: docs/campaign.md.
"""

from __future__ import annotations

import multiprocessing
import os
import re
import socket
from collections import deque
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Protocol

from netsetest.campaign.spec import CampaignError
from netsetest.campaign.worker import PRELOAD, RunOutcome, RunTask, execute
from netsetest.extras import require

CONNECT_TIMEOUT_S = 10.0  # a scheduler that does not answer this soon is not there
ADDRESS_RE = re.compile(r"(?:(tcp|tls)://)?(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.-]+):(\d{1,5})")
LOST_ALONE = 2  # a run whose worker died this often while it ran alone is an error, not retried for ever
# The environment docs/campaign.md starts a Dask scheduler and its workers with: one BLAS thread, and Dask's
# clocks slowed (its event loops' tick, the memory and system monitors; the profiler off), which run whether
# tasks do or not: idle, a scheduler and two workers took 6.5 % of a core with Dask's defaults, 1.1 % with
# these (performance-history.md).  A worker's memory is checked every second instead of every 0.1 s.
DASK_ENV = {
    "OPENBLAS_NUM_THREADS": "1",
    "DASK_DISTRIBUTED__ADMIN__TICK__INTERVAL": "1s",
    "DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__INTERVAL": "2s",
    "DASK_DISTRIBUTED__WORKER__MEMORY__MONITOR_INTERVAL": "1s",
    "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False",
}


class Engine(Protocol):
    workers: int

    def outcomes(self, tasks: Sequence[RunTask]) -> Iterator[RunOutcome]:
        """Every task's outcome as it finishes (a task lost with its worker is run again)."""
        ...

    def close(self) -> None:
        """Stop what is still running (Ctrl-C): nothing of this engine outlives it."""
        ...


def default_workers() -> int:
    """One worker per core this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _died(task: RunTask, times: int) -> RunOutcome:
    return RunOutcome(task.key, None, None, f"its worker process died {times} times while running it alone (killed, or out of memory)", None, 0.0, 0.0, "")


class LocalPool:
    """``workers`` local processes (module doc)."""

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or default_workers()
        self._pool: ProcessPoolExecutor | None = None

    def _start(self) -> ProcessPoolExecutor:
        from netsetest.runtime.processes import ROLE_ENV  # a role's: one BLAS thread, two malloc arenas, unless the user set them

        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(list(PRELOAD))  # imported once, in the fork server
        added = [k for k in ROLE_ENV if k not in os.environ]
        os.environ.update({k: ROLE_ENV[k] for k in added})  # read by the fork server at its start, inherited by every worker
        try:
            pool = ProcessPoolExecutor(self.workers, mp_context=ctx, initializer=_ignore_sigint)
            pool.submit(int).result()  # the fork server starts now, with the workers' environment
        finally:
            for k in added:
                del os.environ[k]
        return pool

    def outcomes(self, tasks: Sequence[RunTask]) -> Iterator[RunOutcome]:
        queue: deque[RunTask] = deque(tasks)
        suspects: deque[RunTask] = deque()  # in flight when a worker died: each runs alone
        lost: dict[str, int] = {}
        running: dict[Future, RunTask] = {}
        self._pool = self._pool or self._start()
        while queue or suspects or running:
            if suspects and not running:
                t = suspects.popleft()
                running[self._pool.submit(execute, t)] = t
            while queue and not suspects and len(running) < self.workers:
                t = queue.popleft()
                running[self._pool.submit(execute, t)] = t
            alone = len(running) == 1
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            broken = False
            for f in done:
                task = running.pop(f)
                try:
                    yield f.result()
                except BrokenProcessPool:
                    broken = True
                    if alone:  # this run took its worker down
                        lost[task.key] = lost.get(task.key, 0) + 1
                        if lost[task.key] >= LOST_ALONE:
                            yield _died(task, lost[task.key])
                            continue
                    suspects.append(task)
            if broken:  # the executor is unusable: every other run in flight is lost too
                suspects.extend(running.values())
                running.clear()
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = self._start()

    def close(self) -> None:
        pool, self._pool = self._pool, None
        if pool is None:
            return
        processes = list(getattr(pool, "_processes", {}).values())  # the executor has no public way to stop a running task
        pool.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            p.terminate()
        for p in processes:
            p.join()


def _ignore_sigint() -> None:
    """Ctrl-C reaches the whole process group: the campaign's process handles it, its workers carry on until stopped."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


class DaskCluster:
    """An existing Dask distributed cluster (module doc); ``address`` its scheduler's, e.g. tcp://10.0.0.1:8786."""

    def __init__(self, address: str, connect_timeout_s: float = CONNECT_TIMEOUT_S) -> None:
        require("distributed", "netsetest campaign --cluster")
        from distributed import Client

        _, host, port = _parts(address)
        try:  # a plain TCP connection first: Dask's client would retry for its whole timeout, then leave its loop behind
            socket.create_connection((host.strip("[]"), port), timeout=connect_timeout_s).close()
            self._client = Client(address, timeout=connect_timeout_s, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise CampaignError(f"--cluster {address}: cannot reach a Dask scheduler there: {exc}") from None
        self.workers = max(1, sum(w.get("nthreads", 1) for w in self._client.scheduler_info()["workers"].values()))
        self._futures: list = []

    def outcomes(self, tasks: Sequence[RunTask]) -> Iterator[RunOutcome]:
        from distributed import as_completed

        by_key = {}
        for t in tasks:
            f = self._client.submit(execute, t, key=f"netsetest-run-{t.key}", pure=False, retries=0)
            by_key[f.key] = t
            self._futures.append(f)
        for f in as_completed(self._futures, loop=self._client.loop):
            task = by_key[f.key]
            try:
                yield f.result()
            except Exception as exc:  # KilledWorker: the run took down allowed-failures workers; anything else Dask raised
                yield RunOutcome(task.key, None, None, f"the cluster gave up on it: {type(exc).__name__}: {exc}"[:500], None, 0.0, 0.0, "")
            f.release()
        self._futures = []

    def close(self) -> None:
        if self._futures:
            self._client.cancel(self._futures)
            self._futures = []
        self._client.close()


def _parts(text: str) -> tuple[str, str, int]:
    m = ADDRESS_RE.fullmatch(text.strip())
    if m is None or not 0 < int(m[3]) < 65536:
        raise CampaignError(f"--cluster {text!r}: expected a Dask scheduler's address, tcp://HOST:PORT or tls://HOST:PORT (e.g. tcp://10.0.0.1:8786)")
    return m[1] or "tcp", m[2], int(m[3])


def cluster_address(text: str) -> str:
    """``--cluster``'s value, checked and written out in full (``HOST:PORT`` is ``tcp://HOST:PORT``); CampaignError otherwise."""
    scheme, host, port = _parts(text)
    return f"{scheme}://{host}:{port}"


def engine(cluster: str | None, workers: int | None) -> Engine:
    """The local pool (``workers`` processes, default one per core), or the Dask cluster at ``cluster``."""
    if cluster is not None:
        if workers is not None:
            raise CampaignError("--workers is the local pool's; a cluster has the workers it was started with")
        return DaskCluster(cluster_address(cluster))
    return LocalPool(workers)
