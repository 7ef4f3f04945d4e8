"""Observing a running run from outside: a Zenoh session that only subscribes (``netsetest echo`` and
``netsetest watch``) and the per-node table ``watch`` shows.

The observer is one more Zenoh peer (or client): it connects to an endpoint of the run (a router, or a
role's ``--listen`` endpoint; gossip brings it to the other peers), or is configured completely by a
Zenoh configuration file (``--zenoh-config``), or — a secured run — is an mTLS client of the run's
router with the ``observer`` certificate of the run's credentials (``--credentials``), which the
router's access control lets receive every key of the run and publish none.  It never publishes.  Payloads are decoded with :func:`netsetest.messages.decode`; one that fails validation is
shown as such, never repaired.
"""

from __future__ import annotations

import json
import queue
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from netsetest.bus import keys
from netsetest.bus.zenoh_bus import BusError, ZenohMode, zenoh_config
from netsetest.messages import BadMessage, End, Message, NodeInput, NodeState, Truth, decode
from netsetest.roles.fdi import classify
from netsetest.roles.judge import Containment, Judge
from netsetest.runtime.security import ObserverAccess, client_settings

ANY_RUN = "*"
PENDING_STEPS = 50  # how far back a state still waits for its truth (and a truth for its states)


def observed_key(run_id: str | None, key: str | None) -> str:
    """The key expression to subscribe to: ``key`` as given when it starts with the root
    (``netsetest/…``), else relative to the run (``node/3/state`` → ``netsetest/<run>/node/3/state``);
    no key: everything of the run.  No run id: every run (``*``)."""
    if key and (key == keys.ROOT or key.startswith(keys.ROOT + "/")):
        return key
    return f"{keys.ROOT}/{run_id or ANY_RUN}/{key.strip('/') if key else '**'}"


def observer_config(mode: ZenohMode, connect: Sequence[str], config_file: str | None, access: ObserverAccess | None = None) -> zenoh.Config:
    """The observer's Zenoh configuration.

    ``access`` (``--credentials``): an mTLS client of the run's router with the observer certificate,
    connecting to ``connect`` or else the endpoints the run left with its credentials.  Else the run's
    configuration file when given (``connect`` endpoints are added to it), else the same configuration
    the roles use, connecting to ``connect``."""
    if access is not None:
        endpoints = list(connect) or list(access.connect)
        if not endpoints:
            raise BusError("--credentials: no router endpoint in the credentials directory; give it with --connect")
        try:
            return zenoh_config("client", (), endpoints, base_file=config_file, settings=client_settings(access.identity))
        except zenoh.ZError as exc:
            raise BusError(f"bad --connect endpoint in {endpoints}: {_short(exc)}") from None
    if config_file is None:
        try:
            return zenoh_config(mode, (), connect)
        except zenoh.ZError as exc:
            raise BusError(f"bad --connect endpoint in {list(connect)}: {_short(exc)}") from None
    if not Path(config_file).is_file():
        raise BusError(f"{config_file}: file not found")
    try:
        cfg = zenoh.Config.from_file(config_file)
    except (zenoh.ZError, OSError, ValueError) as exc:
        raise BusError(f"{config_file}: not a usable Zenoh configuration ({_short(exc)})") from None
    if connect:
        try:
            cfg.insert_json5("connect/endpoints", json.dumps(list(connect)))
        except zenoh.ZError as exc:
            raise BusError(f"bad --connect endpoint in {list(connect)}: {_short(exc)}") from None
    return cfg


def _short(exc: Exception) -> str:
    """Zenoh's error text without its source locations, on one line."""
    return " ".join(str(exc).split(" at /")[0].split())[:300]


@dataclass(frozen=True)
class Observed:
    """One received sample: its key and the decoded message, or why it could not be decoded."""

    key: str
    message: Message | None
    error: str | None = None

    def as_json(self) -> dict:
        if self.message is None:
            return {"key": self.key, "undecodable": self.error}
        return {"key": self.key, **self.message.model_dump(mode="json")}


class Observer:
    """A subscribe-only Zenoh session; :meth:`get` returns the next decoded sample (or None on timeout)."""

    def __init__(self, key_expr: str, config: zenoh.Config) -> None:
        try:
            self._session = zenoh.open(config)
        except zenoh.ZError as exc:
            raise BusError(f"cannot open a Zenoh session: {_short(exc)}") from None
        self._samples: queue.Queue[tuple[str, bytes]] = queue.Queue()
        self._sub = self._session.declare_subscriber(key_expr, lambda s: self._samples.put((str(s.key_expr), s.payload.to_bytes())))
        self._closed = False

    def backlog(self) -> int:
        """Samples received and not yet taken (the live view drops frames above a bound)."""
        return self._samples.qsize()

    def get(self, timeout: float) -> Observed | None:
        try:
            key, payload = self._samples.get(timeout=timeout)
        except queue.Empty:
            return None
        try:
            return Observed(key, decode(payload))
        except BadMessage as exc:
            return Observed(key, None, str(exc))

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._sub.undeclare()
        self._session.close()


# ------------------------------------------------------------------------------------ watch


@dataclass
class NodeRow:
    """What ``watch`` shows for one node: its latest published step and running counts."""

    id: int
    step: int | None = None
    status: str = "-"
    fault_lower: float | None = None
    fault_upper: float | None = None
    E: float | None = None  # eᵀP⁻¹e of step E_step, the latest whose truth is known (None: none seen)
    E_step: int | None = None
    contained: bool | None = None  # the published set of step E_step held the truth (the collector's rule: Judge.containment)
    certain_miss: bool = False  # ... and if not, it certainly missed it (a point truth; a recorded drive's box: disjoint)
    judged: int = 0  # node-steps heard with their truth
    missed: int = 0  # of them, those whose published set certainly missed the truth
    undecided: int = 0  # of them, neither held nor missed (a recorded drive's reference box overlaps the set: docs/your-log.md)
    rho: float | None = None
    lost: int = 0  # in-neighbour messages the loss model dropped on the way to this node (NodeInput.lost_from)
    dropped: int = 0  # messages this node has dropped as invalid (its own counter)
    missing: int = 0  # expected neighbour messages that did not arrive, summed over steps
    deadline_misses: int = 0  # steps published after their deadline (real-time clock)
    fdi: str = "-"  # the latest step's detection status (roles/fdi.py; tolerance 0: watch has no topology)
    first_detection: int | None = None


@dataclass
class LiveTable:
    """Per-node rows built from NodeState and NodeInput messages (and Truth, when the observer may see it,
    for E).

    Only the last :data:`PENDING_STEPS` steps wait for their counterpart (a state for its truth or the
    other way round), so an observer that never sees the truth (access control) stays small."""

    rows: dict[int, NodeRow] = field(default_factory=dict)
    truth: dict[int, Truth] = field(default_factory=dict)
    pending: dict[int, dict[int, NodeState]] = field(default_factory=dict)  # node → step → state
    ended: End | None = None
    judged: list[tuple[int, int, Containment]] | None = None  # a list: every node-step judged, (node, step, containment), for its reader to take

    def update(self, msg: Message | None) -> None:
        if isinstance(msg, NodeState):
            row = self.rows.setdefault(msg.node, NodeRow(msg.node))
            if row.step is None or msg.step >= row.step:
                row.step, row.status, row.rho = msg.step, msg.status, msg.published.rho
                lo, hi = msg.published.bounds()  # a set estimator's own set; the SDP's ellipsoid ∩ its fault range ∩ its region
                row.fault_lower, row.fault_upper = float(lo[2]), float(hi[2])
                row.fdi = classify(row.fault_lower, row.fault_upper)
                if row.fdi == "detected" and (row.first_detection is None or msg.step < row.first_detection):
                    row.first_detection = msg.step
                row.dropped = max(row.dropped, msg.dropped)
            row.missing += len(msg.missing)
            row.deadline_misses += msg.late
            pend = self.pending.setdefault(msg.node, {})
            pend[msg.step] = msg
            for k in [k for k in pend if k < msg.step - PENDING_STEPS]:
                del pend[k]
            self._evaluate(msg.node, msg.step)
        elif isinstance(msg, NodeInput):
            self.rows.setdefault(msg.node, NodeRow(msg.node)).lost += len(msg.lost_from)
        elif isinstance(msg, Truth):
            self.truth[msg.step] = msg
            for k in [k for k in self.truth if k < msg.step - PENDING_STEPS]:
                del self.truth[k]
            for i in list(self.rows):
                self._evaluate(i, msg.step)
        elif isinstance(msg, End):
            self.ended = msg

    def _evaluate(self, node: int, step: int) -> None:
        st, tr = self.pending.get(node, {}).get(step), self.truth.get(step)
        if st is None or tr is None or node not in tr.faults:
            return
        del self.pending[node][step]
        row = self.rows[node]
        c = Judge.containment(node, st, tr)  # the collector's rule: the ellipsoid ∩ the region ∩ the fault range (or the set estimator's set)
        row.judged += 1
        row.missed += c.missed
        row.undecided += not c.contained and not c.missed
        if row.E_step is None or step >= row.E_step:  # the latest step whose truth is known
            row.E, row.E_step, row.contained, row.certain_miss = c.E, step, c.contained, c.missed
        if self.judged is not None:
            self.judged.append((node, step, c))

    @property
    def complete(self) -> bool:
        """The run ended and every node seen has shown its state of the last step."""
        return self.ended is not None and all(r.step is not None and r.step >= self.ended.steps for r in self.rows.values())

    def sorted_rows(self) -> list[NodeRow]:
        return [self.rows[i] for i in sorted(self.rows)]
