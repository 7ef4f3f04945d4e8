"""Lockstep flow control between the vehicle and the collector (issue 33): the window, the collector's
acknowledgment stride, and the one setting that changes the window (the benchmark's).

An honest role sends one message per key per step (the truth; a node's state), and the collector's inbox
holds at most MAX_PER_KEY messages per key (bus/base.py: the bound that stops a flood).  With the vehicle at
most ``ACK_WINDOW`` steps past the collector's acknowledgment (roles/vehicle.py), no key of the collector
holds more than ``ACK_WINDOW`` (+ a late state or two) unhandled honest messages, whatever the collector's
speed: an eighth of the bound, the rest is room for copies a peer repeats.  A few steps of lead are enough
for a collector that keeps up (it takes in a step in far less than a node solves one).

``NETSETEST_ACK_WINDOW`` (:data:`ACK_WINDOW_ENV`) in the environment of ``netsetest run`` (the vehicle process
inherits it) sets another window.  It exists for one user, the benchmark (netsetest/bench/flow.py), which
measures what the window costs by running the same ``netsetest run`` with and without it, interleaved: a
second way of building the run without a window would measure a different program.  The launcher refuses
a bad value before any role starts (exit 2).  Accepted: a whole number from ``ACK_STRIDE`` (a smaller window
would wait for an acknowledgment the collector only sends every ``ACK_STRIDE`` steps: a deadlock) to
``MAX_ACK_WINDOW`` (half the inbox bound: beyond, a paused collector's inbox would turn the run's own
messages away, the loss this window exists to prevent); or ``unbounded``, no window at all (the vehicle
never waits for the collector before its End), the run as it was before the window, which a slow collector
can make lose messages: only for measuring.
"""

from __future__ import annotations

from collections.abc import Mapping

from netsetest.bus.base import MAX_PER_KEY

ACK_WINDOW = MAX_PER_KEY // 8
# The collector acknowledges every ACK_STRIDE steps (one small message to every role per stride): the
# vehicle's lead stays between ACK_WINDOW − ACK_STRIDE + 1 and ACK_WINDOW steps.
ACK_STRIDE = ACK_WINDOW // 4
MAX_ACK_WINDOW = MAX_PER_KEY // 2  # the widest window that keeps a paused collector's honest backlog within half the bound
ACK_WINDOW_ENV = "NETSETEST_ACK_WINDOW"
UNBOUNDED = "unbounded"  # the setting's value for no window (the benchmark's "without" case)


def ack_window(environ: Mapping[str, str]) -> int | None:
    """The lockstep window ``environ`` sets (:data:`ACK_WINDOW` when it sets none; None: ``unbounded``);
    ValueError naming the setting and why."""
    text = environ.get(ACK_WINDOW_ENV)
    if text is None:
        return ACK_WINDOW
    if text.strip() == UNBOUNDED:
        return None
    try:
        w = int(text)
    except ValueError:
        w = None
    if w is None or not ACK_STRIDE <= w <= MAX_ACK_WINDOW:
        raise ValueError(
            f"{ACK_WINDOW_ENV}={text!r}: must be a whole number of steps from {ACK_STRIDE} (the collector acknowledges every "
            f"{ACK_STRIDE}) to {MAX_ACK_WINDOW} (half the inbox bound), or {UNBOUNDED!r} (no window: for the benchmark only)"
        )
    return w
