"""The bus interface the roles talk through; the in-memory and Zenoh buses implement it.

Delivery is pull-based: a transport queues raw payloads as they arrive (on any thread), and
:meth:`Bus.pump` decodes and dispatches them in the caller's thread, so a role never runs concurrently
with itself.  A payload that fails validation is dropped and counted in :attr:`Bus.dropped` (by
reason), never handed to a role.
"""

from __future__ import annotations

import queue
from abc import ABC, abstractmethod
from collections import Counter
from collections.abc import Callable

from netsetest.bus.keys import matches
from netsetest.messages import BadMessage, Message, decode, encode

Handler = Callable[[str, Message], None]


class Bus(ABC):
    def __init__(self) -> None:
        # SimpleQueue (C): half the CPU per blocking get of queue.Queue and half its wake-up latency
        self._inbox: queue.SimpleQueue[tuple[str, bytes, Handler]] = queue.SimpleQueue()
        self.dropped: Counter[str] = Counter()
        self.received = 0

    def publish(self, key: str, msg: Message) -> None:
        self._send(key, encode(msg))

    @abstractmethod
    def _send(self, key: str, payload: bytes) -> None: ...

    @abstractmethod
    def subscribe(self, key_expr: str, handler: Handler) -> None: ...

    def close(self) -> None:
        """Release transport resources (sessions, sockets); idempotent."""

    def _enqueue(self, key: str, payload: bytes, handler: Handler) -> None:
        self._inbox.put((key, payload, handler))

    def pump(self, timeout: float | None = 0.0, limit: int | None = None) -> int:
        """Dispatch queued messages; wait up to ``timeout`` s for the first one. Returns how many ran."""
        done = 0
        block = timeout is None or timeout > 0
        while limit is None or done < limit:
            try:
                key, payload, handler = self._inbox.get(block=block and done == 0, timeout=timeout if done == 0 else None)
            except queue.Empty:
                break
            self.received += 1
            try:
                msg = decode(payload)
            except BadMessage as exc:
                self.dropped[exc.reason] += 1
                continue
            handler(key, msg)
            done += 1
        return done

    def drop(self, reason: str) -> None:
        """Count a message a role rejected on context (wrong sender, stale step, bad shape matrix)."""
        self.dropped[reason] += 1


class MemoryBus(Bus):
    """One process, deterministic: publish appends to a FIFO queue; subscribers are matched by key."""

    def __init__(self) -> None:
        super().__init__()
        self._subs: list[tuple[str, Handler]] = []
        self._routes: dict[str, list[Handler]] = {}  # key → matching handlers (else O(N²) per step)

    def subscribe(self, key_expr: str, handler: Handler) -> None:
        self._subs.append((key_expr, handler))
        self._routes.clear()

    def _send(self, key: str, payload: bytes) -> None:
        handlers = self._routes.get(key)
        if handlers is None:
            handlers = self._routes[key] = [h for pattern, h in self._subs if matches(pattern, key)]
        for handler in handlers:
            self._enqueue(key, payload, handler)

    def inject(self, key: str, payload: bytes) -> None:
        """Deliver raw bytes as if from the network (tests of malformed messages)."""
        self._send(key, payload)
