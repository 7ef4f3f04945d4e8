"""Lockstep flow control between the vehicle and the collector (issue 33): the protocol, both sides.

An honest role sends one message per key per step (the truth; a node's state), and the collector's inbox
holds at most MAX_PER_KEY messages per key (bus/base.py: the bound that stops a flood).  With the vehicle at
most ``ACK_WINDOW`` steps past the collector's acknowledgment, no key of the collector holds more than
``ACK_WINDOW`` (+ a late state or two) unhandled honest messages, whatever the collector's speed: an eighth of
the bound, the rest is room for copies a peer repeats.  A few steps of lead are enough for a collector that
keeps up (it takes in a step in far less than a node solves one).

On the wire the acknowledgment is the collector's Ready on its own key with ``acked``, the newest step whose
truth it took in (messages.py); the roles send and receive it, this module decides:

- the collector's side, :class:`Acknowledgments`: which step to acknowledge now (every ``ACK_STRIDE`` steps, one
  small message to every role per stride; the last step at once, since the vehicle's End waits for it);
- the vehicle's side, :class:`Window`: the newest step acknowledged (never beyond the step published: a forged
  acknowledgment cannot open the window past what the collector could have seen), and whether the next step,
  or the End, may go out; and :class:`Hold`, the vehicle held by a shut window: said once it lasts, the run ended
  once it outlasts the stall limit (the collector is stopped, or has lost its session).

The window is an option of the vehicle's spec (``netsetest vehicle --ack-window``, which ``netsetest run
--ack-window`` passes on; runtime/rolespec.py), read by :func:`parse_window`.  Accepted: a whole number from
``ACK_STRIDE`` (a smaller window would wait for an acknowledgment the collector only sends every ``ACK_STRIDE``
steps: a deadlock) to ``MAX_ACK_WINDOW`` (half the inbox bound: beyond, a paused collector's inbox would turn the
run's own messages away, the loss this window exists to prevent); or ``unbounded``, no window at all (the
vehicle never waits for the collector before its End), the run as it was before the window, which a slow
collector can make lose messages: the benchmark's (netsetest_bench/flow.py) measure of what the window costs,
the same ``netsetest run`` with and without it.

No bus, no messages here (a spec's default window is read by every command line): the roles do the I/O.
"""

from __future__ import annotations

from typing import Literal

from netsetest.bus.limits import MAX_PER_KEY

ACK_WINDOW = MAX_PER_KEY // 8
# The collector acknowledges every ACK_STRIDE steps (one small message to every role per stride): the
# vehicle's lead stays between ACK_WINDOW − ACK_STRIDE + 1 and ACK_WINDOW steps.
ACK_STRIDE = ACK_WINDOW // 4
MAX_ACK_WINDOW = MAX_PER_KEY // 2  # the widest window that keeps a paused collector's honest backlog within half the bound
UNBOUNDED = "unbounded"  # the option's value for no window (the benchmark's "without" case)
WINDOW_RANGE = (
    f"a whole number of steps from {ACK_STRIDE} (the collector acknowledges every {ACK_STRIDE}) to {MAX_ACK_WINDOW} "
    f"(half the inbox bound), or {UNBOUNDED!r} (no window: for the benchmark only)"
)
HoldState = Literal["waiting", "tell", "stalled"]


def check_window(window: int | None) -> int | None:
    """``window`` itself if it is one a run may have (None: unbounded); else ValueError saying the range."""
    if window is not None and not ACK_STRIDE <= window <= MAX_ACK_WINDOW:
        raise ValueError(f"must be {WINDOW_RANGE}")
    return window


def parse_window(text: str) -> int | None:
    """The window ``text`` names (None: ``unbounded``); ValueError saying the range."""
    if text.strip() == UNBOUNDED:
        return None
    try:
        window = int(text)
    except ValueError:
        raise ValueError(f"must be {WINDOW_RANGE}") from None
    return check_window(window)


def show_window(window: int | None) -> str:
    """The text :func:`parse_window` reads back as ``window``."""
    return UNBOUNDED if window is None else str(window)


class Acknowledgments:
    """The collector's side: the newest step it has told the vehicle it took in (the run's last step is ``last``)."""

    def __init__(self, last: int) -> None:
        self.last = last
        self.acked = -1

    def due(self, head: int) -> int | None:
        """With every truth up to step ``head`` taken in: the step to acknowledge now (None: none), every
        ACK_STRIDE steps, and the last step at once (the vehicle's End waits for it)."""
        if head >= self.acked + ACK_STRIDE or head == self.last > self.acked:
            self.acked = head
            return head
        return None


class Window:
    """The vehicle's side: it may lead the collector's acknowledgment by ``size`` steps (None: unbounded); its End,
    after step ``last``, waits for that step's acknowledgment whatever the size."""

    def __init__(self, size: int | None, last: int) -> None:
        self.size, self.last = size, last
        self.acked = -1  # the newest step the collector acknowledged

    def acknowledged(self, step: int, published: int) -> None:
        """The collector acknowledged ``step``; ``published``: the newest step the vehicle published (the cap)."""
        self.acked = max(self.acked, min(step, published))

    def open(self, published: int) -> bool:
        """The step after ``published`` is inside the window (step k + ``size`` needs step k acknowledged); the End
        needs the last step acknowledged (else it overtakes the truths still on their way and the collector counts
        it early)."""
        if published >= self.last:
            return self.acked >= self.last
        return self.size is None or published + 1 <= self.acked + self.size


class Hold:
    """The vehicle held by a shut window (lockstep): since when nothing new was acknowledged (a collector still
    acknowledging is alive, only behind: the wait starts again), said once past ``tell_after`` s (the node
    timeout), given up past ``limit`` s (``--stall-limit``)."""

    def __init__(self, tell_after: float, limit: float) -> None:
        self.tell_after, self.limit = tell_after, limit
        self.since: float | None = None
        self.acked = -1
        self.told = False

    def held(self, now: float, acked: int) -> HoldState:
        """The window is shut at ``now`` with step ``acked`` acknowledged: ``stalled`` past the limit, ``tell`` the
        first time past ``tell_after``, else ``waiting``."""
        if self.since is None or acked != self.acked:
            self.since, self.acked = now, acked
        waited = now - self.since
        if waited > self.limit:
            return "stalled"
        if waited > self.tell_after and not self.told:
            self.told = True
            return "tell"
        return "waiting"

    def released(self) -> None:
        """The vehicle went on: the next hold is a new one."""
        self.since, self.told = None, False
