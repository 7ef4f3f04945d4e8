"""Several "hosts": network namespaces joined by veth pairs to the router's namespace.

Layout (created by the test, removed in its finalizer; nothing is added to the host's namespace)::

    <tag>-r   netsetest router, listening on 10.210.{1,2,3}.1:7447
    <tag>-vc  vehicle + collector   10.210.1.2/30  <->  10.210.1.1/30 (router side)
    <tag>-na  nodes 1, 2, 3         10.210.2.2/30  <->  10.210.2.1/30
    <tag>-nb  nodes 4, 5, 6         10.210.3.2/30  <->  10.210.3.1/30

Every role runs in client mode against the router address on its own link.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid

import pytest
from zenoh_helpers import (
    PAPER6,
    ProcessGuard,
    cli,
    launch_clients,
    new_run_id,
    read_json,
    role_names,
    wait_for,
    wait_roles,
)

pytestmark = pytest.mark.zenoh

PORT = 7447


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=20, check=check)


class Namespaces:
    def __init__(self, guard: ProcessGuard) -> None:
        self.tag = "zt" + uuid.uuid4().hex[:5]
        self.router = f"{self.tag}-r"
        self.hosts = {f"{self.tag}-vc": 1, f"{self.tag}-na": 2, f"{self.tag}-nb": 3}  # namespace → subnet 10.210.x.0/30
        self.created: list[str] = []
        guard.finalizers.append(self.delete)  # runs after the guard has killed every process

    def create(self) -> None:
        for ns in [self.router, *self.hosts]:
            _ip("netns", "add", ns)
            self.created.append(ns)
            _ip("-n", ns, "link", "set", "lo", "up")
        for ns, x in self.hosts.items():
            rside, hside = f"{self.tag}r{x}", f"{self.tag}h{x}"
            # both ends are created inside the namespaces: nothing appears in the host's namespace
            _ip("-n", self.router, "link", "add", rside, "type", "veth", "peer", "name", hside, "netns", ns)
            _ip("-n", self.router, "addr", "add", f"10.210.{x}.1/30", "dev", rside)
            _ip("-n", self.router, "link", "set", rside, "up")
            _ip("-n", ns, "addr", "add", f"10.210.{x}.2/30", "dev", hside)
            _ip("-n", ns, "link", "set", hside, "up")

    def router_addr(self, ns: str) -> str:
        return f"10.210.{self.hosts[ns]}.1"

    def delete(self) -> None:
        for ns in reversed(self.created):
            _ip("netns", "del", ns, check=False)
        left = set(_ip("netns", "list", check=False).stdout.split()) & set(self.created)
        self.created.clear()
        assert not left, f"namespaces left behind: {left}"

    @staticmethod
    def identify(pid: int) -> str:
        return _ip("netns", "identify", str(pid), check=False).stdout.strip()


@pytest.fixture
def netns(procs):
    if os.geteuid() != 0:
        pytest.skip("network namespaces need root (ip netns add)")
    if shutil.which("ip") is None:
        pytest.skip("iproute2 (`ip`) is not installed")
    nets = Namespaces(procs)
    try:
        nets.create()
    except subprocess.CalledProcessError as exc:
        pytest.skip(f"cannot set up network namespaces here: `{' '.join(exc.cmd)}` failed: {exc.stderr.strip()}")
    return nets


@pytest.mark.timeout(120)
def test_zenoh_multi_host_namespaces(procs, netns, tmp_path) -> None:
    steps = 10
    vc, na, nb = netns.hosts
    placement = {"vehicle": vc, "collector": vc, "node1": na, "node2": na, "node3": na, "node4": nb, "node5": nb, "node6": nb}
    assert set(placement) == set(role_names())
    exec_in = {name: ["ip", "netns", "exec", ns] for name, ns in placement.items()}

    listen = [f"tcp/{netns.router_addr(ns)}:{PORT}" for ns in netns.hosts]
    router = procs.start("router", ["ip", "netns", "exec", netns.router, *cli("router", *(a for e in listen for a in ("--listen", e)))])
    wait_for(lambda: "listening on" in procs.stderr("router") or router.poll() is not None, 30, 0.1, "the router")
    assert router.poll() is None, procs.logs()

    run_id = new_run_id()
    summary_path = tmp_path / "summary.json"
    endpoints = {name: f"tcp/{netns.router_addr(ns)}:{PORT}" for name, ns in placement.items()}
    launch_clients(procs, PAPER6, run_id, steps, summary_path, endpoints, exec_in)
    # each process really runs in its namespace
    assert wait_for(lambda: netns.identify(router.pid) == netns.router, 10, 0.1, "router namespace")
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
    host_links = _ip("-o", "link", "show").stdout
    assert netns.tag not in host_links
