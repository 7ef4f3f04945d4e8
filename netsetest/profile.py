"""Where a role process's CPU goes, per phase of its own thread (off unless asked; for the benchmark).

``NETSETEST_PROFILE=DIR`` in a role process's environment turns it on: the bus and the node charge
the CPU time of the calling thread (``time.thread_time_ns``, robust to other work on the machine,
unlike wall time) to named phases, and a node writes ``DIR/node-<id>.json`` when it ends.  Off, every
hook is one ``is None`` test.  Phases (:data:`PHASES`):

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
callbacks decode) as ``threads``: a phase is charged only on the role's own thread (the one that imported
this module), since ``other`` is that thread's CPU less its phases.  ``messages`` counts, per step, the
payloads the bus took from the transport (``received``, on any thread; those dropped before decoding too)
and those it published (``sent``): the per-message budget of the benchmark (``netsetest bench --only
node``) divides by them.  Counted from the node's first solved step to its last, so start-up is left out.
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from collections import Counter
from pathlib import Path

ENV = "NETSETEST_PROFILE"
PHASES = ("wait", "decode", "handle", "solve", "build", "encode", "put")
MESSAGES = ("received", "sent")


class PhaseProfile:
    """CPU nanoseconds of the calling thread per phase (single-threaded use: the role's own thread)."""

    def __init__(self) -> None:
        self.cpu_ns: Counter[str] = Counter()
        self.calls: Counter[str] = Counter()
        self.messages: Counter[str] = Counter()  # MESSAGES, whatever the thread
        self._owner = threading.get_ident()  # the role's thread: the one that imports this module
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

    def write(self, name: str, steps: int) -> None:
        """Write the report to ``$NETSETEST_PROFILE/<name>.json`` (a failure to write only warns)."""
        directory = os.environ.get(ENV)
        if not directory:
            return
        try:
            Path(directory, f"{name}.json").write_text(json.dumps(self.report(steps)))
        except OSError as exc:
            print(f"[profile] cannot write {name}.json in {directory}: {exc}", file=sys.stderr, flush=True)


#: The process's profile, or None (the default): set from the environment once, at import.
PROFILE: PhaseProfile | None = PhaseProfile() if os.environ.get(ENV) else None
