"""The bus interface the roles talk through; the in-memory and Zenoh buses implement it.

Delivery is pull-based: a transport decodes each payload as it arrives (on any thread) and queues the
message; :meth:`Bus.pump` dispatches them in the caller's thread, so a role never runs concurrently with
itself.  A payload that fails validation is dropped and counted in :attr:`Bus.dropped` (by reason),
never queued and never handed to a role: a flood of malformed or out-of-range messages takes no room
that a genuine message needs.

The inbox is bounded per key (:class:`Inbox`): at most ``MAX_PER_KEY`` messages wait on one key and at
most ``MAX_KEYS`` keys wait at once.  A role needs the earliest steps first (its next input, the
neighbour states of its current step), so when a key's queue is full a message for an earlier step
evicts the one for the farthest step (``inbox-evicted``); otherwise the newest is dropped
(``inbox-full``, ``inbox-keys``).  A flood of future steps therefore never pushes out what the role waits
for.  (Copies of the very step a role waits for cannot be told from the genuine one here: the role's own
checks drop them, and they pass through at ``MAX_ROUNDS`` per pump.)  :meth:`Bus.pump`
serves the waiting keys in turn, one message each per round, for at most ``MAX_ROUNDS`` rounds and never
more than was queued when it started — so a flood on one key delays nothing else and cannot keep a role
from stepping.

A *lazy* subscription (``subscribe(..., lazy=True)``, exact keys only) is for messages a role needs only
when something else arrives (a real-time node's neighbour states, needed when its next input comes):
their arrival does not end a blocking :meth:`Bus.pump`; the next pump that runs collects them first.  A
transport may then keep them outside Python until that pump (Zenoh: a bounded ring buffer per key), which
spares a thread switch and a wake-up of the role per message.

A subscription's *screen* (``subscribe(..., screen=...)``) sees the step a payload names
(:func:`~netsetest.messages.peek_step`, a few µs against a few tens for a decode) before anything is
decoded, on whatever thread the payload arrives: a drop reason drops the payload undecoded (counted under that
reason, as the role's handler would have counted it), None lets it be decoded and queued.  A role screens out
only what its handler would drop whatever the rest of the payload holds, and only for a reason that stays true
until the handler would run (a step it has passed, or after the run; the role's state only moves forward):
copies for steps nobody waits for cost a peek, not a decode.  The in-memory bus decodes every payload once
for all its subscribers and ignores screens (the roles' handlers drop the same payloads, for the same reasons).
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from collections import Counter, deque
from collections.abc import Callable

from netsetest.bus.keys import matches
from netsetest.bus.limits import MAX_PER_KEY
from netsetest.messages import BadMessage, Message, decode, encode, peek_step

Handler = Callable[[str, Message], None]
Screen = Callable[[int], str | None]  # the step a payload names → why the subscriber drops it undecoded, or None


MAX_ROUNDS = 16  # payloads per key one pump handles: a flooded key's decoding cost per pump is bounded
MAX_KEYS = 1024  # distinct (key, subscriber) queues: a wildcard subscription must not allocate per forged key
NO_STEP = -1  # the service rank of a message that names no step (Ready, End): never evicted for a step's


def _rank(msg: Message) -> int:
    """The step a message is for (NO_STEP if it names none): the lower, the sooner a role needs it."""
    step = getattr(msg, "step", None)
    return step if isinstance(step, int) else NO_STEP


class _KeyQueue(deque[Message]):
    """One key's waiting messages, FIFO, with the farthest step among them kept up to date: a full
    queue turns a flood of far steps away in O(1) (it is asked once per flood message)."""

    def __init__(self) -> None:
        super().__init__()
        self.far = NO_STEP - 1  # the largest rank queued (below every rank while empty)

    def push(self, msg: Message) -> None:
        self.append(msg)
        self.far = max(self.far, _rank(msg))

    def pop_first(self) -> Message:
        msg = self.popleft()
        if not self:
            self.far = NO_STEP - 1  # (as _refresh leaves an empty queue: most queues hold one message)
        elif _rank(msg) == self.far:
            self._refresh()
        return msg

    def drop_farthest(self) -> Message:
        i = next(i for i, m in enumerate(self) if _rank(m) == self.far)
        msg = self[i]
        del self[i]
        self._refresh()
        return msg

    def _refresh(self) -> None:
        self.far = max(map(_rank, self), default=NO_STEP - 1)


class Inbox:
    """Decoded messages per (key, handler), FIFO per key, bounded; thread-safe (transport threads put)."""

    def __init__(self, per_key: int = MAX_PER_KEY, max_keys: int = MAX_KEYS) -> None:
        self.per_key, self.max_keys = per_key, max_keys
        self._queues: dict[tuple[str, Handler], _KeyQueue] = {}  # insertion order = service order
        self._size = 0
        self._cv = threading.Condition()

    def put(self, key: str, msg: Message, handler: Handler) -> tuple[str, Message] | None:
        """Queue a message; None, or why a message was dropped and which (this one, or the one it evicted)."""
        rank = _rank(msg)
        with self._cv:
            q = self._queues.get((key, handler))
            if q is None:
                if len(self._queues) >= self.max_keys:
                    return "inbox-keys", msg
                q = self._queues[(key, handler)] = _KeyQueue()
            dropped = None
            if len(q) >= self.per_key:
                if q.far <= rank:
                    return "inbox-full", msg
                dropped = "inbox-evicted", q.drop_farthest()  # a later step than this one's: the role needs it after this one, if at all
                self._size -= 1
            q.push(msg)
            self._size += 1
            self._cv.notify()
        return dropped

    def __len__(self) -> int:
        return self._size

    def wait(self, timeout: float | None) -> bool:
        """Wait until something is queued (``timeout`` None: forever); whether something is."""
        with self._cv:
            return self._cv.wait_for(lambda: self._size > 0, timeout)

    def queued(self, key: str) -> int:
        """Messages waiting on ``key`` (every subscriber's)."""
        with self._cv:
            return sum(len(q) for (k, _), q in self._queues.items() if k == key)

    def take_round(self, most: int | None = None) -> list[tuple[str, Message, Handler]]:
        """One message from every waiting key (at most ``most`` keys), oldest key first."""
        with self._cv:
            out = []
            for kh in list(self._queues)[:most]:
                q = self._queues[kh]
                out.append((kh[0], q.pop_first(), kh[1]))
                if not q:
                    del self._queues[kh]
            self._size -= len(out)
            return out


class Bus(ABC):
    #: a bus that carries several roles (in memory): its drop counters are the run's, not one role's
    shared = False

    def __init__(self) -> None:
        self._inbox = Inbox()
        self.dropped: Counter[str] = Counter()
        self.received = 0
        # handler → told of every message the inbox dropped for it (the collector: a node-step it lost
        # itself is not a node's silence); called on the transport's thread, so it must only record
        self.overflow_listeners: dict[Handler, Handler] = {}  # told (key, message)

    def publish(self, key: str, msg: Message) -> None:
        self._send(key, encode(msg))

    @abstractmethod
    def _send(self, key: str, payload: bytes) -> None: ...

    def declare_publisher(self, key: str) -> None:
        """Get ready to publish on ``key`` before the first message (a transport announces it now)."""

    @abstractmethod
    def subscribe(self, key_expr: str, handler: Handler, lazy: bool = False, screen: Screen | None = None) -> None:
        """Deliver messages on ``key_expr`` to ``handler`` (in :meth:`pump`); ``lazy``, ``screen``: see the module doc."""

    def _collect_lazy(self) -> None:
        """Move what lazy subscriptions hold outside the inbox into it (transports that keep them apart)."""

    def close(self) -> None:
        """Release transport resources (sessions, sockets); idempotent."""

    def drop(self, reason: str) -> None:
        """Count a message a role dropped on this bus (by reason); every bus has it."""
        self.dropped[reason] += 1  # Counter += is one bytecode-level dict update: safe from any thread

    def _arrived(self) -> None:
        """Count a payload taken from the transport (any thread)."""
        self.received += 1

    def _decoded(self, payload: bytes) -> Message | None:
        """The message in ``payload``, or None (dropped and counted) if it is not a valid message."""
        try:
            return decode(payload)
        except BadMessage as exc:
            self.drop(exc.reason)
            return None

    def _enqueue(self, key: str, payload: bytes, handler: Handler, screen: Screen | None = None) -> None:
        """Take a payload from the transport: screened, then decoded and queued (or dropped and counted)."""
        self._arrived()
        if screen is not None:
            step = peek_step(payload)
            why = None if step is None else screen(step)
            if why is not None:
                self.drop(why)
                return
        msg = self._decoded(payload)
        if msg is not None:
            self._put(key, msg, handler)

    def _put(self, key: str, msg: Message, handler: Handler) -> None:
        dropped = self._inbox.put(key, msg, handler)
        if dropped is not None:
            self.drop(dropped[0])
            listener = self.overflow_listeners.get(handler)
            if listener is not None:
                listener(key, dropped[1])

    def pump(self, timeout: float | None = 0.0, limit: int | None = None) -> int:
        """Dispatch queued messages, the waiting keys in turn; wait up to ``timeout`` s for the first one.

        Handles at most what was queued when it started (and at most ``limit`` valid messages), so a
        flood cannot keep it from returning.  Returns how many valid messages ran.
        """
        self._collect_lazy()
        if not len(self._inbox) and (timeout is None or timeout > 0):
            self._inbox.wait(timeout)
            self._collect_lazy()
        budget = len(self._inbox)
        done = rounds = 0
        while budget > 0 and rounds < MAX_ROUNDS and (limit is None or done < limit):
            rounds += 1
            batch = self._inbox.take_round(budget if limit is None else min(budget, limit - done))
            if not batch:
                break
            for key, msg, handler in batch:
                budget -= 1
                handler(key, msg)
                done += 1
        return done

    def pending(self) -> int:
        """Payloads queued and not yet handled."""
        return len(self._inbox)

    def queued(self, key: str) -> int:
        """Messages on ``key`` received and not yet handled: what a message of another key, handled first
        (the pump serves the keys in turn), overtook here rather than on the way."""
        return self._inbox.queued(key)


class MemoryBus(Bus):
    """One process, deterministic: publish appends to a FIFO queue; subscribers are matched by key."""

    shared = True

    def __init__(self) -> None:
        super().__init__()
        # subscriptions in their order: exact keys by key, wildcard expressions apart (a network's are a few: the
        # collector's, End's), so that a key's route costs a lookup and a few matches, not one per subscription
        # (a 96-node ring has ~500: matching them all per key was O(N²) per run, a tenth of a short run's time)
        self._exact: dict[str, list[tuple[int, Handler]]] = {}
        self._wild: list[tuple[int, str, Handler]] = []
        self._count = 0
        self._routes: dict[str, list[Handler]] = {}  # key → matching handlers, in subscription order

    def subscribe(self, key_expr: str, handler: Handler, lazy: bool = False, screen: Screen | None = None) -> None:
        # lazy changes nothing here: the in-memory runtime never blocks in pump; nor does screen (module doc)
        if "*" in key_expr:
            self._wild.append((self._count, key_expr, handler))
        else:
            self._exact.setdefault(key_expr, []).append((self._count, handler))
        self._count += 1
        self._routes.clear()

    def _route(self, key: str) -> list[Handler]:
        """The handlers subscribed to ``key``, in the order they subscribed."""
        found = self._exact.get(key, []) + [(n, h) for n, pattern, h in self._wild if matches(pattern, key)]
        return [h for _, h in sorted(found, key=lambda nh: nh[0])]

    def _send(self, key: str, payload: bytes) -> None:
        handlers = self._routes.get(key)
        if handlers is None:
            handlers = self._routes[key] = self._route(key)
        if not handlers:
            return
        self._arrived()
        msg = self._decoded(payload)  # once, whatever the number of subscribers
        if msg is not None:
            for handler in handlers:
                self._put(key, msg, handler)

    def inject(self, key: str, payload: bytes) -> None:
        """Deliver raw bytes as if from the network (tests of malformed messages)."""
        self._send(key, payload)
