"""``netsetest campaign --cluster``: a real Dask cluster (the scheduler and two workers, each a process of its
own) gives the rows of the same runs one by one, and a worker SIGKILLed mid-campaign loses no run and counts
none twice (Dask runs its tasks again on the other worker).

As root the processes stand on three "hosts" (network namespaces, netsetest/runtime/netns.py), each worker
joined to the scheduler's by a veth pair, the campaign itself beside the scheduler::

    <tag>-s   dask scheduler on 10.212.{1,2}.1:8786, netsetest campaign --cluster tcp://10.212.1.1:8786
    <tag>-a   dask worker 10.212.1.2/30  <->  10.212.1.1/30
    <tag>-b   dask worker 10.212.2.2/30  <->  10.212.2.1/30

Otherwise all on the loopback.  The runs are tiny (a few steps): what is tested is the cluster's bookkeeping.
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import pytest
from campaign_helpers import assert_same_rows, campaign_file_fixture, dataset, one_by_one
from zenoh_helpers import ProcessGuard, wait_for

from netsetest.campaign.engines import DASK_ENV
from netsetest.runtime import netns

pytest.importorskip("distributed")
pytest.importorskip("pyarrow")
pytestmark = pytest.mark.zenoh

CAMPAIGN = """
name = "cluster"
[grid]
topology = "paper6"
estimator = ["sdp", "interval"]
case = ["nsnim", "saim"]
seeds = "0-2"
steps = 5
"""
PORT = 8786
WORKER_ENV = {**DASK_ENV, "MALLOC_ARENA_MAX": "2"}  # as docs/campaign.md starts a worker


class Cluster:
    """The scheduler and two workers (in namespaces where this process may make them: module doc)."""

    def __init__(self, procs: ProcessGuard, tmp: Path) -> None:
        self.procs = procs
        self.prefix: dict[str, list[str]] = {"s": [], "a": [], "b": []}
        host = {"s": "127.0.0.1", "a": "127.0.0.1", "b": "127.0.0.1"}
        scheduler = {"a": "127.0.0.1", "b": "127.0.0.1"}  # the scheduler's address each worker reaches it at
        self.nets = None
        if netns.unavailable() is None:
            try:
                self.nets = netns.Namespaces("ct")
                procs.finalizers.append(self.delete)  # after every process is gone
                s = self.nets.add("s")
                self.prefix["s"] = netns.exec_prefix(s)
                for n, (name, x) in enumerate((("a", 1), ("b", 2))):
                    ns = self.nets.add(name)
                    self.nets.link(s, f"10.212.{x}.1/30", ns, f"10.212.{x}.2/30")
                    self.prefix[name], host[name], scheduler[name] = netns.exec_prefix(ns), f"10.212.{x}.2", f"10.212.{x}.1"
                host["s"] = "10.212.1.1"
            except netns.NamespaceError:
                self.delete()
                self.nets, self.prefix = None, {"s": [], "a": [], "b": []}
                host = {k: "127.0.0.1" for k in host}
                scheduler = {k: "127.0.0.1" for k in scheduler}
        port = PORT if self.nets is not None else _free_port()
        self.address = f"tcp://{host['s']}:{port}"
        env = {**os.environ, **WORKER_ENV}
        py = sys.executable
        listen = "0.0.0.0" if self.nets is not None else host["s"]  # in its namespace: both links
        procs.start(
            "scheduler",
            [*self.prefix["s"], py, "-m", "distributed.cli.dask_scheduler", "--host", listen, "--port", str(port), "--dashboard-address", ":0", "--no-show"],
            env=env,
        )
        for name in ("a", "b"):
            argv = [py, "-m", "distributed.cli.dask_worker", f"tcp://{scheduler[name]}:{port}", "--host", host[name], "--nthreads", "1", "--no-nanny"]
            argv += ["--no-dashboard", "--name", name, "--local-directory", str(tmp / f"dask-{name}")]
            argv += ["--preload", "netsetest.campaign.worker"]  # as docs/campaign.md starts a worker: the run's code imported at its start
            procs.start(f"worker-{name}", [*self.prefix[name], *argv], env=env)
        for name in ("a", "b"):
            wait_for(lambda: "Registered to" in procs.stderr(f"worker-{name}") or procs.procs[f"worker-{name}"].poll() is not None, 60, 0.2, f"worker {name}")
            assert procs.procs[f"worker-{name}"].poll() is None, procs.logs()

    def campaign(self, campaign: Path, out: Path) -> None:
        """``netsetest campaign --cluster`` beside the scheduler (its progress in the guard's log)."""
        argv = [sys.executable, "-m", "netsetest", "campaign", str(campaign), "--out", str(out), "--cluster", self.address]
        self.procs.start("campaign", [*self.prefix["s"], *argv])

    def delete(self) -> None:
        if self.nets is not None:
            left = self.nets.delete()
            assert not left, f"namespaces left behind: {left}"


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


campaign_file = campaign_file_fixture(CAMPAIGN)


@pytest.fixture
def cluster(procs: ProcessGuard, tmp_path: Path) -> Cluster:
    return Cluster(procs, tmp_path)


@pytest.mark.timeout(300)
def test_a_dask_cluster_gives_the_rows_of_the_runs_one_by_one_and_survives_a_lost_worker(
    procs: ProcessGuard, campaign_file: Path, cluster: Cluster, tmp_path: Path
) -> None:
    """Worker b is stopped (SIGSTOP) before the campaign starts: the runs the scheduler hands it wait, so the runs that
    come back first are worker a's, and the campaign cannot end before b goes on.  Once two runs are back, a is
    SIGKILLed (mid-campaign whatever the machine's load: b still holds runs) and b continues (SIGCONT): it runs its
    own runs, and again those a held.  Dask's work stealing takes no run from b while it is stopped: a steal
    needs the victim's answer."""
    want = one_by_one(campaign_file)
    out = tmp_path / "out"
    b = procs.procs["worker-b"].pid
    os.kill(b, signal.SIGSTOP)
    cluster.campaign(campaign_file, out)
    wait_for(lambda: "campaign: 2/" in procs.stderr("campaign") or procs.procs["campaign"].poll() is not None, 120, 0.05, "two runs back (worker a's)")
    assert procs.procs["campaign"].poll() is None, procs.logs()
    os.kill(procs.procs["worker-a"].pid, signal.SIGKILL)  # mid-campaign: its runs in flight go to worker b
    os.kill(b, signal.SIGCONT)
    assert procs.wait("campaign", 240) == 0, procs.logs()
    got = dataset(out)
    assert_same_rows(got, want)
    workers = {r["worker"] for r in got.values()}
    assert len(workers) == 2, f"both workers ran runs before one was lost: {workers}"
    if cluster.nets is not None:
        assert netns.identify(procs.procs["worker-b"].pid) == cluster.nets.created[-1]


def test_a_scheduler_that_is_not_there_is_one_line_and_exit_2_before_anything_is_written(
    campaign_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from netsetest.cli.main import main

    out = tmp_path / "out"
    assert main(["campaign", str(campaign_file), "--out", str(out), "--cluster", f"tcp://127.0.0.1:{_free_port()}"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("netsetest campaign: ") and err.count("\n") == 1 and "cannot reach a Dask scheduler there" in err, err
    assert not out.exists()
