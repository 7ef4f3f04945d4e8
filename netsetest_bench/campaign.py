"""The campaign figures (``netsetest bench --only campaign``, issue 43's targets): what ``netsetest campaign``
costs and buys, measured with the campaign's own code (netsetest/campaign/: the file, the engines, the store).

- ``throughput``: a paper6 campaign (both cases and signal families, the SDP, 80 steps) on the local pool with
  1 worker, with 2, and on a Dask cluster of 2 single-threaded workers on this machine (a scheduler and two
  ``dask worker`` processes, the same cores), in turn, ``reps`` times; runs per second of each, medians; the
  ratios 2 workers / 1 (target ≥ 1.8) and cluster / 2 local workers (target ≥ 0.9).  A run's CPU is beside
  its wall time: on a machine other jobs load, the wall ratio shows the cores the campaign got, not what it
  can do, and the CPU per run (the same in every arm when the pool adds nothing) says which.
- ``overhead``: the same runs one after the other in this process (``RunSpec.execute``: the run ``netsetest
  run --mode inmemory`` makes, without the interpreter's start) against the 1-worker campaign of them, in
  turn: the CPU the campaign spends outside the runs (its process and its workers' beyond what the runs took)
  per run's CPU (target ≤ 5 %: what a run costs more in a campaign, whatever else loads the machine), and the
  campaign's wall per run over the direct one, less 1 (the same where the machine is quiet; here the cores'
  share the other jobs leave decides it).
- ``big``: the 1 000-run paper6 campaign (both cases and signal families, every real-time estimator, 80
  steps) on the local pool: its wall time, CPU, the load around it; every worker's resident memory sampled
  as it goes (after the first tenth of the runs, at the end: target flat); then ``netsetest campaign`` on
  the finished results again, as a user resumes (a process of its own: start, the file, the keys read,
  nothing to run), its wall time (target ≤ 5 s).  ``--quick`` runs a tenth of it.
"""

from __future__ import annotations

import os
import socket
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from netsetest.campaign.engines import DASK_ENV, LocalPool
from netsetest.campaign.runner import Tally, run_campaign, tasks_of
from netsetest.campaign.spec import load_campaign
from netsetest.campaign.store import Store
from netsetest_bench.config import BenchConfig
from netsetest_bench.figures.campaign import Arms, Big, Campaign, CampaignRun, Direct, Resume, Throughput
from netsetest_bench.figures.campaign import load as load_figures
from netsetest_bench.render import fill

ESTIMATORS = ("sdp", "zonotope", "interval", "strip", "setprop")  # every real-time node estimator of `compare`
MEMORY_SAMPLES = 10  # worker memory sampled this many times over the big campaign
CLUSTER_START_S = 60.0  # a scheduler and two workers ready within this, or the cluster figures are None


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "?"


def _file(tmp: Path, name: str, runs: int, estimators: tuple[str, ...], steps: int) -> Path:
    """A paper6 campaign of ``runs`` runs: both cases and signal families, ``estimators``, seeds to fill it; one
    ``[[runs]]`` table per seed, so the runs go seed by seed, every estimator in each (a worker's memory after
    the first seeds has met every estimator's code: what grows after that is what a run leaves behind)."""
    per_seed = 4 * len(estimators)
    est = ", ".join(f'"{e}"' for e in estimators)
    table = f'[[runs]]\ntopology = "paper6"\nestimator = [{est}]\ncase = ["nsnim", "saim"]\nsignals = ["paper", "worst"]\nsteps = {steps}\n'
    path = tmp / f"{name}.toml"
    path.write_text(f'name = "{name}"\n' + "".join(f"{table}seeds = {s}\n" for s in range(max(1, runs // per_seed))))
    return path


def _cpu_of(pids: list[int]) -> float:
    import psutil

    total = 0.0
    for pid in pids:
        try:
            t = psutil.Process(pid).cpu_times()
            total += t.user + t.system
        except psutil.Error:
            pass
    return total


def _rss_mb(pids: list[int]) -> dict[int, float]:
    import psutil

    out = {}
    for pid in pids:
        try:
            out[pid] = psutil.Process(pid).memory_info().rss / 2**20
        except psutil.Error:
            pass
    return out


def _campaign(path: Path, out: Path, engine: Any, sample_every: int = 0, pids: list[int] | None = None) -> CampaignRun:
    """Run the campaign at ``path`` into a fresh ``out`` on ``engine``: wall, CPU, its runs' own CPU and wall,
    and (``sample_every`` runs) the local pool's workers' resident memory; ``pids``: the engine's processes (a
    Dask cluster's scheduler, nannies, workers), their CPU over the campaign."""
    c = load_campaign(path)
    store = Store(out)
    samples: list[dict[int, float]] = []
    worker_cpu: dict[int, float] = {}

    def on_progress(t: Tally) -> None:
        pids = list(getattr(getattr(engine, "_pool", None), "_processes", {}) or {})
        if pids:
            worker_cpu.update({p: c for p in pids if (c := _cpu_of([p]))})
        if sample_every and t.done and t.done % sample_every == 0:
            samples.append(_rss_mb(pids))

    load = _load()
    procs0 = _cpu_of(pids or [])
    cpu0, t0 = time.process_time(), time.perf_counter()
    tally = run_campaign(c, store, engine, on_progress)
    wall, cpu_main = time.perf_counter() - t0, time.process_time() - cpu0
    if pids:
        worker_cpu = {0: _cpu_of(pids) - procs0}
    table = store.table()
    store.close()
    per_run = {}  # run key → (wall, CPU) in its worker (a run's rows, one per node, all carry its times)
    for key, w, cp in zip(table.column("run_key").to_pylist(), table.column("wall_s").to_pylist(), table.column("cpu_s").to_pylist()):
        per_run[key] = (w, cp)
    return CampaignRun(
        runs=tally.done,
        errors=tally.errors,
        failed=tally.failed,
        wall_s=wall,
        runs_per_s=tally.done / wall if wall else None,
        cpu_main_s=cpu_main,
        run_wall_s=sum(w for w, _ in per_run.values()),
        run_cpu_s=sum(cp for _, cp in per_run.values()),
        worker_cpu_s=sum(worker_cpu.values()) or None,
        runs_per_cpu_s=tally.done / (cpu_main + sum(worker_cpu.values())) if worker_cpu else None,  # every process's CPU: what load cannot change
        cores_used=(cpu_main + sum(worker_cpu.values())) / wall if worker_cpu and wall else None,  # the share of the cores it got
        memory_mb=samples,
        load=load,
    )


def _direct(path: Path) -> Direct:
    """The campaign's runs one after the other in this process, as ``netsetest run --mode inmemory`` makes each."""
    c = load_campaign(path)
    load = _load()
    cpu0, t0 = time.process_time(), time.perf_counter()
    for t in tasks_of(c, set()):
        t.spec.execute(keep=False)
    return Direct(runs=len(c.runs), wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - cpu0, load=load)


class _LocalDask:
    """A Dask scheduler and ``workers`` single-threaded workers as processes of their own on this machine."""

    def __init__(self, tmp: Path, workers: int) -> None:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        self.address = f"tcp://127.0.0.1:{port}"
        env = {
            **os.environ,
            **DASK_ENV,  # as docs/campaign.md starts them
            "MALLOC_ARENA_MAX": "2",
            "DASK_TEMPORARY_DIRECTORY": str(tmp),
        }  # its scratch and locks in the part's directory
        py = sys.executable
        self.procs = [
            subprocess.Popen(
                [py, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", str(port), "--dashboard-address", ":0", "--no-show"],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                env=env,
            )
        ]
        for n in range(workers):
            argv = [py, "-m", "distributed.cli.dask_worker", self.address, "--nthreads", "1", "--no-dashboard", "--local-directory", str(tmp / f"dask{n}")]
            self.procs.append(
                subprocess.Popen([*argv, "--preload", "netsetest.campaign.worker"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
            )
        from distributed import Client

        with Client(self.address, timeout=CLUSTER_START_S) as c:
            c.wait_for_workers(workers, timeout=CLUSTER_START_S)

    def pids(self) -> list[int]:
        """The scheduler's, the nannies' and the workers' (each nanny's child) process ids."""
        import psutil

        return [q.pid for p in self.procs for q in [psutil.Process(p.pid), *psutil.Process(p.pid).children(recursive=True)]]

    def close(self) -> None:
        for p in reversed(self.procs):
            p.terminate()
        for p in self.procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def _median(values: list[float | None]) -> float | None:
    vals = [v for v in values if v is not None]
    return statistics.median(vals) if vals else None


def _ratio(a: float | None, b: float | None) -> float | None:
    return a / b if a and b else None


def _arms(path: Path, tmp: Path, runs: int, reps: int) -> tuple[Arms, str | None]:
    """Every arm ``reps`` times, in turn (the local pool with 1 and 2 workers, a Dask cluster of 2, the runs one by one
    in this process); why the cluster did not start (None: it did)."""
    engines: dict[str, list[CampaignRun]] = {"local_1": [], "local_2": [], "cluster_2": []}
    direct: list[Direct] = []
    cluster_error = None
    for rep in range(reps):
        for arm in (*engines, "direct"):
            out = tmp / f"{arm}-{rep}"
            _log(f"campaign: {arm}, rep {rep + 1} of {reps}, {runs} runs (load {_load()})")
            if arm == "direct":
                direct.append(_direct(path))
            elif arm == "cluster_2":
                try:
                    cluster = _LocalDask(tmp, 2)
                except Exception as exc:  # no distributed (the cluster extra), or the cluster did not start: no cluster figures
                    cluster_error = f"{type(exc).__name__}: {exc}"
                    continue
                try:
                    from netsetest.campaign.engines import DaskCluster

                    engines[arm].append(_campaign(path, out, DaskCluster(cluster.address), pids=cluster.pids()))
                finally:
                    cluster.close()
            else:
                engines[arm].append(_campaign(path, out, LocalPool(int(arm[-1]))))
    return Arms(**engines, direct=direct), cluster_error


def _throughput(tmp: Path, runs: int, reps: int) -> Throughput:
    """The arms' medians and their ratios (module doc)."""
    arms, cluster_error = _arms(_file(tmp, "throughput", runs, ("sdp",), 80), tmp, runs, reps)
    per_s = {arm: _median([r.runs_per_s for r in rows]) for arm, rows in arms.engines()}
    cpu = {arm: _median([r.runs_per_cpu_s for r in rows]) for arm, rows in arms.engines()}
    local_1, local_2, cluster_2 = (per_s[a] for a, _ in arms.engines())
    cpu_1, cpu_2, cpu_cluster = (cpu[a] for a, _ in arms.engines())
    overhead_wall = [c.wall_s / d.wall_s - 1 for c, d in zip(arms.local_1, arms.direct)]
    overhead_cpu = [(c.cpu_main_s + (c.worker_cpu_s or c.run_cpu_s) - c.run_cpu_s) / c.run_cpu_s for c in arms.local_1 if c.run_cpu_s]
    return Throughput(
        runs=runs,
        reps=reps,
        arms=arms,
        cluster_error=cluster_error,
        runs_per_s=per_s,
        ratio_2_over_1=_ratio(local_2, local_1),
        ratio_cluster_over_local=_ratio(cluster_2, local_2),
        runs_per_cpu_s=cpu,
        cpu_ratio_2_over_1=_ratio(cpu_2, cpu_1),
        cpu_ratio_cluster_over_local=_ratio(cpu_cluster, cpu_2),
        cores_used={arm: _median([r.cores_used for r in rows]) for arm, rows in arms.engines()},
        cpu_per_run_s={arm: _median([r.run_cpu_s / r.runs for r in rows if r.runs]) for arm, rows in arms.engines()},
        overhead_wall_pct=100 * statistics.median(overhead_wall) if overhead_wall else None,
        overhead_cpu_pct=100 * statistics.median(overhead_cpu) if overhead_cpu else None,
    )


def _resume(path: Path, out: Path) -> Resume:
    """``netsetest campaign`` on finished results, as a user starts it again: its wall time and what it said."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "netsetest", "campaign", str(path), "--out", str(out), "--quiet"], capture_output=True, text=True)
    return Resume(
        wall_s=time.perf_counter() - t0,
        exit_code=proc.returncode,
        nothing_to_run=" 0 to run" in proc.stderr,
        files=len(list((out / "runs").rglob("*.parquet"))),
    )


def _big(tmp: Path, runs: int) -> Big:
    path = _file(tmp, "big", runs, ESTIMATORS, 80)
    _log(f"campaign: the {runs}-run paper6 campaign, every estimator, both cases and signal families (load {_load()})")
    pool = LocalPool()
    fig = _campaign(path, tmp / "big", pool, sample_every=max(1, runs // MEMORY_SAMPLES))
    load_after = _load()
    samples = fig.memory_mb
    first, last = (samples[0], samples[-1]) if samples else ({}, {})
    return Big(
        runs=fig.runs,
        errors=fig.errors,
        failed=fig.failed,
        wall_s=fig.wall_s,
        runs_per_s=fig.runs_per_s,
        cpu_main_s=fig.cpu_main_s,
        run_wall_s=fig.run_wall_s,
        run_cpu_s=fig.run_cpu_s,
        worker_cpu_s=fig.worker_cpu_s,
        runs_per_cpu_s=fig.runs_per_cpu_s,
        cores_used=fig.cores_used,
        memory_mb=samples,
        workers=pool.workers,
        load_before=fig.load,
        load_after=load_after,
        memory_growth_mb=max((last[p] - first[p] for p in first if p in last), default=None),
        memory_first_mb=max(first.values(), default=None),
        memory_last_mb=max(last.values(), default=None),
        resume=_resume(path, tmp / "big"),
    )


def campaign_figures(cfg: BenchConfig, tmp: Path) -> Campaign:
    """Every figure of the part (module doc)."""
    return Campaign(
        throughput=_throughput(tmp, cfg.campaign_runs, cfg.campaign_reps),
        big=_big(tmp, cfg.campaign_big_runs),
        cpus=len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
    )


def _meets(v: float | None, target: float, above: bool) -> str | None:
    """yes or no (None: not measured, the template's dash)."""
    return None if v is None else ("yes" if (v >= target if above else v <= target) else "no")


@dataclass(frozen=True)
class Met:
    """Each target's verdict (:func:`_meets`)."""

    ratio_2_over_1: str | None
    ratio_cluster_over_local: str | None
    cpu_ratio_2_over_1: str | None
    cpu_ratio_cluster_over_local: str | None
    overhead_cpu_pct: str | None
    resume_s: str | None


def campaign_markdown(doc: dict | Campaign) -> str:
    """The targets' table, then what each arm measured (templates/campaign.md)."""
    r = load_figures(doc) if isinstance(doc, dict) else doc  # (a dict: as the file holds it)
    t, b, T = r.throughput, r.big, "campaign"
    met = Met(
        ratio_2_over_1=_meets(t.ratio_2_over_1, 1.8, True),
        ratio_cluster_over_local=_meets(t.ratio_cluster_over_local, 0.9, True),
        cpu_ratio_2_over_1=_meets(t.cpu_ratio_2_over_1, 0.9, True),
        cpu_ratio_cluster_over_local=_meets(t.cpu_ratio_cluster_over_local, 0.9, True),
        overhead_cpu_pct=_meets(t.overhead_cpu_pct, 5.0, False),
        resume_s=_meets(b.resume.wall_s, 5.0, False),
    )
    lines = [fill(T, "head", t=t, b=b, met=met, estimators=", ".join(ESTIMATORS), cpus=r.cpus)]
    for arm, rows in t.arms.engines():
        lines.append(
            fill(
                T,
                "arm-row",
                name=arm.replace("_", ", "),
                runs_per_s=t.runs_per_s.get(arm),
                runs_per_cpu_s=t.runs_per_cpu_s.get(arm),
                cores=t.cores_used.get(arm),
                cpu_per_run_s=t.cpu_per_run_s.get(arm),
                reps=", ".join(fill(T, "rep", x=x) for x in rows) or fill(T, "missing"),
            )
        )
    lines.append(fill(T, "direct-row", reps=", ".join(fill(T, "rep", x=x) for x in t.arms.direct)))
    if t.cluster_error:
        lines.append(fill(T, "cluster-error", error=t.cluster_error))
    return "\n".join(lines) + "\n"
