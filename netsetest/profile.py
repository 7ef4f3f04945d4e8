"""Where a role process's CPU goes, per phase of its own thread (off unless asked; for the benchmark).

A node's ``--profile DIR`` (``netsetest run --profile DIR`` passes it to every node; runtime/rolespec.py) turns it
on: an observer (:func:`observe_bus`, :func:`observe_node`) wraps the bus's and the node's methods of each phase on
their instances, so that they charge the CPU time of the calling thread (``time.thread_time_ns``, robust to other
work on the machine, unlike wall time) to named phases, and the node writes ``DIR/node-<id>.json`` when it ends
(:meth:`PhaseProfile.write`).  Off, nothing is wrapped and the hot path has no profiling code at all.  Phases (:data:`PHASES`):

- ``wait``: blocking for the next message — the CPU of going to sleep and of being woken (the
  Condition, the futex, taking the GIL back); ``calls`` counts the blocking waits, i.e. wake-ups;
- ``decode``: msgpack and validation of a received payload (``messages.decode``);
- ``handle``: the role's handler of a valid message (context checks, plausibility, buffering);
- ``solve``: the estimator's step (data, conic solve, certification);
- ``build``: building the published ``NodeState`` (validated);
- ``encode``: msgpack of a published message;
- ``put``: handing the payload to the transport (Zenoh's ``Publisher.put`` in the caller's thread).

What the thread used outside these is reported as ``other`` (the role's loop, deciding to step,
bookkeeping); what the process's other threads used (Zenoh's runtime, subscriber callbacks, and what those
callbacks decode) as ``threads``: a phase is charged only on the role's own thread (the one that made the
:class:`PhaseProfile`), since ``other`` is that thread's CPU less its phases.  ``messages`` counts, per step, the
payloads the bus took from the transport (``received``, on any thread; those dropped before decoding too)
and those it published (``sent``): the per-message budget of the benchmark (``netsetest bench --only
node``) divides by them.  Counted from the node's first solved step to its last, so start-up is left out.
"""

from __future__ import annotations

import json
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from netsetest.messages import encode

if TYPE_CHECKING:  # (types only: the observer wraps what it is handed)
    from netsetest.bus.base import Bus, Handler, Screen
    from netsetest.roles.node import Node

PHASES = ("wait", "decode", "handle", "solve", "build", "encode", "put")
MESSAGES = ("received", "sent")


class PhaseProfile:
    """CPU nanoseconds of the calling thread per phase (single-threaded use: the role's own thread)."""

    def __init__(self) -> None:
        self.cpu_ns: Counter[str] = Counter()
        self.calls: Counter[str] = Counter()
        self.messages: Counter[str] = Counter()  # MESSAGES, whatever the thread
        self._owner = threading.get_ident()  # the role's thread: the one that makes the profile
        self._window: tuple[int, int, float] | None = None  # thread CPU, process CPU, wall at the start

    @staticmethod
    def now() -> int:
        return time.thread_time_ns()

    def add(self, phase: str, t0: int) -> int:
        """Charge the thread CPU since ``t0`` to ``phase``; returns now (the next phase's ``t0``).  On
        another thread (a subscriber callback) nothing is charged: that CPU is the process's ``threads``."""
        t = time.thread_time_ns()
        if threading.get_ident() != self._owner:
            return t
        self.cpu_ns[phase] += t - t0
        self.calls[phase] += 1
        return t

    def count(self, what: str) -> None:
        """One more message ``what`` (:data:`MESSAGES`), on any thread."""
        self.messages[what] += 1  # Counter += is one dict update under the GIL: safe from a callback thread

    def start_window(self) -> None:
        """Forget what was charged so far (start-up) and start the measured window."""
        self.cpu_ns.clear()
        self.calls.clear()
        self.messages.clear()
        self._window = (time.thread_time_ns(), time.process_time_ns(), time.monotonic())

    @property
    def started(self) -> bool:
        return self._window is not None

    def report(self, steps: int) -> dict:
        """Per-phase CPU over the window, in ms per step (``steps``: steps stepped in the window)."""
        if self._window is None or steps <= 0:
            return {"steps": 0}
        thread0, process0, wall0 = self._window
        thread_ns = time.thread_time_ns() - thread0
        process_ns = time.process_time_ns() - process0
        per_step = lambda ns: ns / 1e6 / steps  # noqa: E731  # a one-line local helper
        phases = {p: {"ms_per_step": per_step(self.cpu_ns[p]), "calls_per_step": self.calls[p] / steps} for p in PHASES}
        phases["other"] = {"ms_per_step": per_step(thread_ns - sum(self.cpu_ns.values())), "calls_per_step": 0.0}
        phases["threads"] = {"ms_per_step": per_step(process_ns - thread_ns), "calls_per_step": 0.0}
        return {
            "steps": steps,
            "wall_s": time.monotonic() - wall0,
            "thread_ms_per_step": per_step(thread_ns),
            "process_ms_per_step": per_step(process_ns),
            "phases": phases,
            "messages_per_step": {m: self.messages[m] / steps for m in MESSAGES},
        }

    def write(self, directory: str, name: str, steps: int) -> None:
        """Write the report to ``directory/<name>.json`` (a failure to write only warns: the run is not the profile's)."""
        try:
            Path(directory, f"{name}.json").write_text(json.dumps(self.report(steps)))
        except OSError as exc:
            print(f"[profile] cannot write {name}.json in {directory}: {exc}", file=sys.stderr, flush=True)


def _timed(prof: PhaseProfile, phase: str, fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` charging its calling thread's CPU to ``phase``."""

    def timed(*args: Any, **kwargs: Any) -> Any:
        t = prof.now()
        try:
            return fn(*args, **kwargs)
        finally:
            prof.add(phase, t)

    return timed


def observe_bus(bus: Bus, prof: PhaseProfile) -> None:
    """Profile ``bus`` (before anything subscribes): its publishing (``encode``, ``put``: the transport's send), its
    decoding, every handler's run (``handle``), its blocking waits (``wait``) and the messages it takes and sends.
    The instance's own methods are wrapped; the class is untouched."""
    send, decoded, arrived, subscribe, wait = bus._send, bus._decoded, bus._arrived, bus.subscribe, bus._inbox.wait

    def publish(key: str, msg: Any) -> None:
        prof.count("sent")
        t = prof.now()
        payload = encode(msg)
        t = prof.add("encode", t)
        send(key, payload)
        prof.add("put", t)

    def counted() -> None:
        arrived()
        prof.count("received")

    def observed_subscribe(key_expr: str, handler: Handler, lazy: bool = False, screen: Screen | None = None) -> None:
        subscribe(key_expr, _timed(prof, "handle", handler), lazy, screen)

    bus.publish = publish  # type: ignore[method-assign]  # the instance's own, wrapped
    bus._decoded = _timed(prof, "decode", decoded)  # type: ignore[method-assign]  # (likewise)
    bus._arrived = counted  # type: ignore[method-assign]  # (likewise)
    bus.subscribe = observed_subscribe  # type: ignore[method-assign]  # (likewise)
    bus._inbox.wait = _timed(prof, "wait", wait)  # type: ignore[method-assign]  # (likewise)


def observe_node(node: Node, prof: PhaseProfile) -> Callable[[], int]:
    """Profile ``node``: its estimator's steps (``solve``: the step and the part prepared before its readings) and the
    building of its state (``build``), from its first solved step on (:meth:`PhaseProfile.start_window` when it has
    one); returns how many steps it has stepped in the window."""
    est = node.estimator
    est.step = _timed(prof, "solve", est.step)  # type: ignore[method-assign]  # the instance's own, wrapped
    est.prepare = _timed(prof, "solve", est.prepare)  # type: ignore[method-assign]  # (likewise)
    node._built = _timed(prof, "build", node._built)  # type: ignore[method-assign]  # (likewise)
    try_step, first = node.try_step, [0]

    def observed_try_step(now: float | None = None) -> bool:
        stepped = try_step(now)
        if stepped and node.k >= 1 and not prof.started:
            prof.start_window()  # from the first solved step: start-up and step 0 left out
            first[0] = node.k
        return stepped

    node.try_step = observed_try_step  # type: ignore[method-assign]  # (likewise)
    return lambda: node.k - first[0] if prof.started else 0
