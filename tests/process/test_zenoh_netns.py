"""Several "hosts": network namespaces joined by veth pairs to the router's namespace.

Layout (created by the test, removed in its finalizer; nothing is added to the host's namespace)::

    <tag>-r   netsetest router, listening on 10.210.{1,2,3}.1:7447
    <tag>-vc  vehicle + collector   10.210.1.2/30  <->  10.210.1.1/30 (router side)
    <tag>-na  nodes 1, 2, 3         10.210.2.2/30  <->  10.210.2.1/30
    <tag>-nb  nodes 4, 5, 6         10.210.3.2/30  <->  10.210.3.1/30

Every role runs in client mode against the router address on its own link.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest
from netsetest_bench.scaleout import scaleout_run
from netsetest_bench.topologies import ring_topology
from netsetest.runtime import netns
from zenoh_helpers import (
    PAPER6,
    ProcessGuard,
    cli,
    launch_clients,
    new_run_id,
    pids_with_arg,
    read_json,
    role_names,
    wait_for,
    wait_roles,
)

pytestmark = pytest.mark.zenoh

PORT = 7447


class Star:
    """The test's namespaces (netsetest/runtime/netns.py): the router's, joined to each host's by a veth pair."""

    def __init__(self, guard: ProcessGuard) -> None:
        self.nets = netns.Namespaces("zt")
        self.tag = self.nets.tag
        guard.finalizers.append(self.delete)  # runs after the guard has killed every process
        self.router = self.nets.add("r")
        self.hosts = {self.nets.add(name): x for name, x in (("vc", 1), ("na", 2), ("nb", 3))}  # namespace → subnet 10.210.x.0/30
        for ns, x in self.hosts.items():
            self.nets.link(self.router, f"10.210.{x}.1/30", ns, f"10.210.{x}.2/30")

    def router_addr(self, ns: str) -> str:
        return f"10.210.{self.hosts[ns]}.1"

    def delete(self) -> None:
        left = self.nets.delete()
        assert not left, f"namespaces left behind: {left}"


@pytest.fixture
def star(procs):
    if (why := netns.unavailable()) is not None:
        pytest.skip(why)
    try:
        return Star(procs)
    except netns.NamespaceError as exc:
        pytest.skip(f"cannot set up network namespaces here: {exc}")


@pytest.mark.timeout(120)
def test_zenoh_multi_host_namespaces(procs, star, tmp_path) -> None:
    steps = 10
    vc, na, nb = star.hosts
    placement = {"vehicle": vc, "collector": vc, "node1": na, "node2": na, "node3": na, "node4": nb, "node5": nb, "node6": nb}
    assert set(placement) == set(role_names())
    exec_in = {name: netns.exec_prefix(ns) for name, ns in placement.items()}

    listen = [f"tcp/{star.router_addr(ns)}:{PORT}" for ns in star.hosts]
    router = procs.start("router", [*netns.exec_prefix(star.router), *cli("router", *(a for e in listen for a in ("--listen", e)))])
    wait_for(lambda: "listening on" in procs.stderr("router") or router.poll() is not None, 30, 0.1, "the router")
    assert router.poll() is None, procs.logs()

    run_id = new_run_id()
    summary_path = tmp_path / "summary.json"
    endpoints = {name: f"tcp/{star.router_addr(ns)}:{PORT}" for name, ns in placement.items()}
    launch_clients(procs, PAPER6, run_id, steps, summary_path, endpoints, exec_in)
    # each process really runs in its namespace
    assert wait_for(lambda: netns.identify(router.pid) == star.router, 10, 0.1, "router namespace")
    for name, ns in placement.items():
        proc = procs.procs[name]
        wait_for(lambda: proc.poll() is not None or netns.identify(proc.pid) == ns, 10, 0.05, f"{name} in {ns}")

    codes = wait_roles(procs, 100)
    assert codes == {n: 0 for n in codes}, f"{codes}\n{procs.logs()}"
    s = read_json(summary_path)
    assert s["steps_completed"] == steps and s["violations_total"] == 0 and s["nodes_missing"] == []
    for row in s["nodes"]:
        assert row["steps_reported"] == steps + 1 and row["violations"] == 0, row

    # the host's namespace got no interface of ours
    host_links = subprocess.run(["ip", "-o", "link", "show"], capture_output=True, text=True, check=True).stdout
    assert star.tag not in host_links


@pytest.mark.timeout(300)
def test_scaleout_bench_runs_across_two_namespaces_and_cleans_up(tmp_path) -> None:
    """The benchmark's run across two "hosts" (bench/scaleout.py) at a tiny size: secured, a router in each
    namespace, the ring's nodes split between them, every step checked, nothing left behind; and a run cut
    short (its timeout) leaves no process and no namespace either."""
    if (why := netns.unavailable()) is not None:
        pytest.skip(why)
    topo = ring_topology(tmp_path, 4, 6)
    row = scaleout_run(tmp_path, topo, 2, 6, timeout=200.0)
    assert row["error"] is None, row
    assert row["exit_codes"] == {n: 0 for n in ["collector", "node1", "node2", "node3", "node4", "vehicle"]}, row
    assert (row["steps_completed"], row["violations"], row["nodes_missing"], row["security"]) == (6, 0, [], "mtls+acl"), row
    assert row["step_rate"] > 0 and set(row["cpu_ms_per_step_by_host"]) == {"a", "b"}, row
    cut = scaleout_run(tmp_path, topo, 2, 6, timeout=0.5)
    assert "did not end within" in cut["error"] and cut["step_rate"] is None and None in cut["exit_codes"].values(), cut
    existing = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, check=True).stdout.split()
    for r in (row, cut):
        assert not pids_with_arg(r["run_id"]), f"processes of {r['run_id']} left behind"
        assert len(r["namespaces"]) == 2 and not set(r["namespaces"]) & set(existing), r


@pytest.mark.timeout(180)
def test_scaleout_bench_stopped_by_sigterm_leaves_nothing_behind(tmp_path) -> None:
    """SIGTERM to the benchmark in the middle of a namespaced run (as Ctrl-C): its role processes and routers
    are stopped, its namespaces deleted, its temporary directory removed."""
    if (why := netns.unavailable()) is not None:
        pytest.skip(why)
    script = (
        "import sys, tempfile\n"
        "from dataclasses import replace\n"
        "from pathlib import Path\n"
        "from netsetest_bench.config import QUICK\n"
        "from netsetest_bench.scaleout import scaleout_figures\n"
        "with tempfile.TemporaryDirectory(dir=sys.argv[1]) as d:\n"
        "    try:\n"
        "        scaleout_figures(replace(QUICK, scaleout_nodes=4, scaleout_steps=100000, scaleout_reps=1), Path(d))\n"
        "    except KeyboardInterrupt:\n"
        "        print('interrupted', flush=True)\n"
    )
    before = set(subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, check=True).stdout.split())

    def ours() -> set[str]:  # the namespaces made since the test began
        listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout.split()
        return {ns for ns in listed if ns.startswith("nsb")} - before

    bench = subprocess.Popen([sys.executable, "-c", script, str(tmp_path)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert wait_for(lambda: bool(ours()) or bench.poll() is not None, 60, 0.1, "the run's namespace")
        made = ours()
        run_ids = {p.name for p in tmp_path.glob("*/scale-*")}
        assert made and run_ids and bench.poll() is None
        time.sleep(3.0)  # its roles are up and stepping
        bench.send_signal(signal.SIGTERM)
        out, _ = bench.communicate(timeout=60)
    finally:
        if bench.poll() is None:
            bench.kill()
    assert "interrupted" in out
    assert not made & set(subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, check=True).stdout.split())
    assert not any(pids_with_arg(r) for r in run_ids), "processes of the run left behind"
    assert not list(tmp_path.iterdir())
