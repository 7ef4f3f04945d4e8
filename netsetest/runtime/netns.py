"""Network namespaces as stand-in hosts on one machine (``ip netns``, root only).

The benchmark's run across "hosts" (bench/scaleout.py) and tests/process/test_zenoh_netns.py build their
namespaces here.  A :class:`Namespaces` creates namespaces ``<tag>-<name>`` (loopback up), joins two of
them with a veth pair whose two ends are created inside the namespaces (nothing appears in the host's
namespace), and deletes every namespace it created (:meth:`Namespaces.delete`, after a failure too: the
caller's ``finally``).  :func:`exec_prefix` is the argv prefix that runs a command inside one.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid

IP_TIMEOUT_S = 20.0
IFNAME_MAX = 15  # Linux's limit on an interface name (IFNAMSIZ − 1)


class NamespaceError(RuntimeError):
    """An ``ip`` command failed (the command and its message)."""


def unavailable() -> str | None:
    """Why this process cannot create network namespaces (None: it can try)."""
    if os.geteuid() != 0:
        return "network namespaces need root (ip netns add)"
    if shutil.which("ip") is None:
        return "iproute2 (`ip`) is not installed"
    return None


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    out = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=IP_TIMEOUT_S, check=False)
    if check and out.returncode != 0:
        raise NamespaceError(f"`ip {' '.join(args)}` failed: {out.stderr.strip()}")
    return out


def exec_prefix(ns: str) -> list[str]:
    """The argv prefix that runs a command in namespace ``ns``."""
    return ["ip", "netns", "exec", ns]


def identify(pid: int) -> str:
    """The namespace process ``pid`` runs in ('' : the host's, or the process is gone)."""
    return _ip("netns", "identify", str(pid), check=False).stdout.strip()


class Namespaces:
    """Namespaces made by this object (:attr:`created`), removed again by :meth:`delete`."""

    def __init__(self, prefix: str) -> None:
        self.tag = prefix + uuid.uuid4().hex[:5]  # unique per object: runs side by side do not collide
        self.created: list[str] = []
        self._links = 0

    def add(self, name: str) -> str:
        """A new namespace ``<tag>-<name>`` with its loopback up; its full name."""
        ns = f"{self.tag}-{name}"
        _ip("netns", "add", ns)
        self.created.append(ns)
        _ip("-n", ns, "link", "set", "lo", "up")
        return ns

    def link(self, a: str, addr_a: str, b: str, addr_b: str) -> None:
        """A veth pair between namespaces ``a`` and ``b`` with addresses ``addr_a`` and ``addr_b`` (CIDR)."""
        self._links += 1
        ea, eb = f"{self.tag}a{self._links}", f"{self.tag}b{self._links}"
        assert len(ea) <= IFNAME_MAX and len(eb) <= IFNAME_MAX, "a namespace tag too long for interface names"
        _ip("-n", a, "link", "add", ea, "type", "veth", "peer", "name", eb, "netns", b)  # both ends inside the namespaces
        for ns, end, addr in ((a, ea, addr_a), (b, eb, addr_b)):
            _ip("-n", ns, "addr", "add", addr, "dev", end)
            _ip("-n", ns, "link", "set", end, "up")

    def delete(self) -> list[str]:
        """Delete every namespace this object created (their veth pairs go with them); the names of those
        still there afterwards (empty: all gone)."""
        for ns in reversed(self.created):
            _ip("netns", "del", ns, check=False)
        left = sorted(set(_ip("netns", "list", check=False).stdout.split()) & set(self.created))
        self.created.clear()
        return left
