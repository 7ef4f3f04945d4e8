"""The Zenoh bus (eclipse-zenoh 1.x): one session per process, msgpack payloads, reliable and blocking.

Session configuration is explicit and short:

- ``peer`` (the embedded default, one host): multicast scouting off, the process listens on its own
  endpoint and connects to the endpoints of the other processes (a full mesh on loopback, no router);
- ``client``: connects to one or more routers (several hosts, containers);
- ``router``: a Python session that routes for clients (``netsetest router``, and the router a secured
  ``netsetest run`` hosts in its parent process).

A user's own Zenoh configuration file (JSON5) can be the base; the settings netsetest needs (mode,
endpoints, scouting, and the security settings of netsetest/runtime/security.py) are inserted on top.
Shared memory is off: it would move payloads outside the (authenticated, encrypted) links.

Subscribers' callbacks run on a Python thread zenoh-python starts per subscriber (fed by Zenoh's rx
thread); they screen, decode and queue the message and wake the role (a payload its screen turns away is
never decoded: bus/base.py).  A lazy subscription (see netsetest/bus/base.py)
has no callback: Zenoh's rx thread puts its samples into a ring buffer of ``MAX_PER_KEY`` (the oldest
dropped when full, so a flood never blocks reception of other keys), which the next pump empties — no
Python thread, no wake-up; the role's own thread screens and decodes those in :meth:`Bus.pump`, and
dispatches everything there.  Close the bus explicitly: a process that
exits with an open session can hang.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from typing import Literal

import zenoh

from netsetest.bus.base import MAX_PER_KEY, Bus, Handler, Screen

ZenohMode = Literal["peer", "client", "router"]

# RUST_BACKTRACE=1 (a developer's shell; this project's machines) also makes every Rust error *value*
# capture a backtrace (std::backtrace, through anyhow): Zenoh builds one for each link it closes, and each
# capture walks the stack through the library's unwind tables, ≈1.2 MB that stay resident — the node's
# peak RSS was reached at session close (docs/performance-history.md, *Imports and memory*).  netsetest never shows
# those backtraces; panics keep theirs (RUST_BACKTRACE).  Set here, before this process opens a session
# (no Zenoh thread reads the environment yet); a value the user exported wins.
RUST_ERROR_BACKTRACE_ENV = "RUST_LIB_BACKTRACE"
os.environ.setdefault(RUST_ERROR_BACKTRACE_ENV, "0")


# How long a session's links outlive a silent peer (Zenoh's ``transport/link/tx/lease``, its default 10 s): each side
# closes a link after the *other* side's announced lease without a message from it.  A process stopped longer
# (SIGSTOP, a loaded or swapping machine) had its session closed by the router, and every message in flight to
# it was lost: a collector paused for 10 s never caught up; paused past 60 s, the run ended "vehicle gone"
# (issue 41).  A run's roles and router announce the run's ``--stall-limit`` (runtime/timeouts.py STALL_LIMIT_S);
# this is the lease of the other sessions netsetest opens (echo, watch, view, the benchmark's).  A role that
# dies closes its links with its sockets at once, and a silent role is detected by netsetest's own timeouts
# (the vehicle's node timeout, the collector's idle timeout), not by the lease.
LEASE_S = 60.0


class BusError(RuntimeError):
    """The transport could not be set up (bad endpoint, port in use, router unreachable)."""


def zenoh_config(
    mode: ZenohMode,
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    connect_timeout_s: float = 10.0,
    base_file: str | None = None,
    settings: Mapping[str, object] | None = None,
    lease_s: float = LEASE_S,
) -> zenoh.Config:
    """A Zenoh configuration with multicast scouting off, explicit endpoints, the lease ``lease_s`` and ``settings``
    (path → value).

    ``base_file``: a user's Zenoh configuration (JSON5) to start from (its lease is replaced: a run's roles must
    announce the run's stall limit).
    """
    try:
        cfg = zenoh.Config.from_file(base_file) if base_file else zenoh.Config()
    except zenoh.ZError as exc:
        raise BusError(f"cannot read the Zenoh configuration {base_file}: {exc}") from None
    cfg.insert_json5("mode", json.dumps(mode))
    cfg.insert_json5("scouting/multicast/enabled", "false")  # runs on one host must not find each other
    cfg.insert_json5("scouting/delay", "0")  # else open() blocks 0.5 s while a peer is not up yet
    cfg.insert_json5("transport/shared_memory/enabled", "false")
    cfg.insert_json5("transport/link/tx/lease", str(round(lease_s * 1000)))
    if listen or not base_file:
        cfg.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if connect or not base_file:
        cfg.insert_json5("connect/endpoints", json.dumps(list(connect)))
    # peers start in any order: retry unreachable endpoints quickly (the default backoff starts at 1 s)
    cfg.insert_json5("connect/retry", '{"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2}')
    if mode == "client":  # wait for the router rather than fail at once
        cfg.insert_json5("connect/timeout_ms", str(int(connect_timeout_s * 1000)))
    for path, value in (settings or {}).items():
        try:
            cfg.insert_json5(path, json.dumps(value))
        except zenoh.ZError as exc:
            raise BusError(f"invalid Zenoh setting {path}: {exc}") from None
    return cfg


def open_session(cfg: zenoh.Config, what: str) -> zenoh.Session:
    try:
        return zenoh.open(cfg)
    except zenoh.ZError as exc:
        raise BusError(f"cannot open a Zenoh {what}: {exc}") from None


class ZenohBus(Bus):
    def __init__(
        self,
        mode: ZenohMode = "peer",
        listen: Sequence[str] = (),
        connect: Sequence[str] = (),
        base_file: str | None = None,
        settings: Mapping[str, object] | None = None,
        lease_s: float = LEASE_S,
    ) -> None:
        super().__init__()
        cfg = zenoh_config(mode, listen, connect, base_file=base_file, settings=settings, lease_s=lease_s)
        self.session = open_session(cfg, f"{mode} session (listen {list(listen)}, connect {list(connect)})")
        self._subs: list[zenoh.Subscriber] = []
        self._lazy: list[tuple[str, zenoh.Subscriber, Handler, Screen | None]] = []  # (exact key, ring-buffered subscriber, handler, screen)
        self._pubs: dict[str, zenoh.Publisher] = {}
        self._closed = False

    def subscribe(self, key_expr: str, handler: Handler, lazy: bool = False, screen: Screen | None = None) -> None:
        if lazy:
            if "*" in key_expr or "$" in key_expr:
                raise ValueError(f"a lazy subscription needs an exact key (its ring buffer is per key): {key_expr}")
            sub = self.session.declare_subscriber(key_expr, zenoh.handlers.RingChannel(MAX_PER_KEY))
            self._subs.append(sub)
            self._lazy.append((key_expr, sub, handler, screen))
            return

        def on_sample(sample: zenoh.Sample) -> None:
            self._enqueue(str(sample.key_expr), sample.payload.to_bytes(), handler, screen)

        self._subs.append(self.session.declare_subscriber(key_expr, on_sample))

    def _collect_lazy(self) -> None:
        for key, sub, handler, screen in self._lazy:
            for _ in range(MAX_PER_KEY):  # what the ring holds at most: this loop ends under a flood too
                sample = sub.try_recv()
                if sample is None:
                    break
                self._enqueue(key, sample.payload.to_bytes(), handler, screen)

    def declare_publisher(self, key: str) -> None:
        """Roles declare the keys they will publish at start-up: the declarations reach the router and the
        subscribers then, not in the first step's burst (a hundred nodes take step 0 at once)."""
        self._publisher(key)

    def _publisher(self, key: str) -> zenoh.Publisher:
        """The key's publisher, declared once (by :meth:`declare_publisher` or at the first put)."""
        pub = self._pubs.get(key)
        if pub is None:
            # lockstep needs every message: reliable transport, and block rather than drop when congested
            pub = self.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE)
            self._pubs[key] = pub
        return pub

    def _send(self, key: str, payload: bytes) -> None:
        self._publisher(key).put(payload)

    def send_raw(self, key: str, payload: bytes) -> None:
        """Publish arbitrary bytes (tests inject malformed messages with it)."""
        self._send(key, payload)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for sub in self._subs:
            sub.undeclare()
        for pub in self._pubs.values():
            pub.undeclare()
        self.session.close()
