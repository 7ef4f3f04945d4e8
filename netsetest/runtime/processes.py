"""Main loops of the role processes over any bus (used by ``netsetest vehicle|node|collector``).

Start-up barrier: every role repeats :class:`Ready` until it is started; a role sets ``seen_all`` once it
has heard every other role.  The vehicle publishes step 0 when every node and the collector report
``seen_all`` — by then every subscription is known where it matters.

Lockstep: the vehicle publishes step k+1 once every alive node has published step k; a node silent for
``node_timeout`` s is declared dead and the run goes on without it.  A node waits for its expected
neighbours at most ``neighbour_timeout`` s, then proceeds without the missing ones.
Real time: the vehicle publishes a step every τs; nodes step as soon as their input arrives.
"""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable

from netsetest.bus import keys
from netsetest.bus.base import Bus
from netsetest.config.schema import Scenario
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, Objective
from netsetest.estimator.sdp import Variant
from netsetest.messages import Message, Ready
from netsetest.models.signals import SignalKind
from netsetest.roles.collector import Collector
from netsetest.roles.node import Node
from netsetest.roles.vehicle import Vehicle
from netsetest.runtime.report import EXIT_VIOLATION, exit_code, record_sink, write_summary

READY_PERIOD_S = 0.1


class Stop(Exception):
    """SIGTERM/SIGINT reached a role process: close the bus and leave."""


def install_signal_handlers() -> None:
    def handler(signum: int, frame: object) -> None:
        raise Stop(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)


def log(role: str, text: str) -> None:
    print(f"[{role}] {text}", file=sys.stderr, flush=True)


class Barrier:
    """Tracks Ready messages of the other roles and repeats our own until we are started."""

    def __init__(self, bus: Bus, run_id: str, me: Ready, others: set[tuple[str, int | None]]) -> None:
        self.bus, self.run, self.me, self.others = bus, run_id, me, others
        self.heard: set[tuple[str, int | None]] = set()
        self.complete: set[tuple[str, int | None]] = set()  # roles that reported seen_all
        self.last_sent = 0.0
        bus.subscribe(keys.ready(run_id), self.on_message)

    def on_message(self, key: str, msg: Message) -> None:
        if not isinstance(msg, Ready):
            return
        who = (msg.role, msg.node)
        self.heard.add(who)
        if msg.seen_all:
            self.complete.add(who)

    def tick(self, now: float, **changes: object) -> None:
        if now - self.last_sent >= READY_PERIOD_S:
            seen_all = self.others <= self.heard
            self.bus.publish(keys.ready(self.run), self.me.model_copy(update={"seen_all": seen_all, **changes}))
            self.last_sent = now


def _all_roles(sc: Scenario) -> set[tuple[str, int | None]]:
    return {("vehicle", None), ("collector", None)} | {("node", i) for i in sc.ids}


def run_vehicle(
    sc: Scenario,
    bus: Bus,
    run_id: str,
    signals: SignalKind,
    seed: int,
    realtime: bool,
    node_timeout: float,
    start_timeout: float,
    pace: float = 0.0,
) -> int:
    vehicle = Vehicle(sc, bus, run_id, signals, seed, realtime=realtime)
    me = ("vehicle", None)
    barrier = Barrier(bus, run_id, Ready(role="vehicle"), _all_roles(sc) - {me})
    t0 = time.monotonic()
    while not (barrier.others <= barrier.complete):
        barrier.tick(time.monotonic())
        bus.pump(timeout=0.02)
        if time.monotonic() - t0 > start_timeout:
            missing = sorted(f"{r}{'' if n is None else ' ' + str(n)}" for r, n in barrier.others - barrier.complete)
            log("vehicle", f"start-up timed out after {start_timeout:.0f} s; not ready: {', '.join(missing)}")
            return EXIT_VIOLATION
    barrier.tick(time.monotonic() + READY_PERIOD_S)  # a last Ready with seen_all for everyone
    log("vehicle", f"all {len(sc.ids)} nodes and the collector are ready; clock {'realtime' if realtime else 'lockstep'}")
    vehicle.advance()
    t_step = next_tick = time.monotonic()
    while not vehicle.done:
        now = time.monotonic()
        if realtime:
            bus.pump(timeout=max(0.0, min(next_tick + sc.tau_s - now, 0.05)))
        else:
            bus.pump(timeout=min(0.05, max(0.0, t_step + node_timeout - now)))
        now = time.monotonic()
        if realtime:
            if now >= next_tick + sc.tau_s:
                next_tick += sc.tau_s
                vehicle.advance()
        elif vehicle.ready_to_advance():
            if now - t_step >= pace:  # lockstep paced for watching (or for a restarted node to catch up)
                vehicle.advance()
                t_step = now
        elif now - t_step > node_timeout:
            log("vehicle", f"step {vehicle.k}: no state from node(s) {sorted(vehicle.waiting_for())} in {node_timeout:g} s; going on without")
            vehicle.advance()
            t_step = now
    time.sleep(0.2)  # let End reach everyone before the session closes
    return 0


def run_node(
    sc: Scenario,
    node_id: int,
    bus: Bus,
    run_id: str,
    variant: Variant,
    realtime: bool,
    neighbour_timeout: float,
    rejoin: bool,
    objective: Objective = DEFAULT_OBJECTIVE,
) -> int:
    node = Node(sc, node_id, bus, run_id, variant, rejoin=rejoin, objective=objective)
    role = f"node {node_id}"
    barrier = Barrier(bus, run_id, Ready(role="node", node=node_id), _all_roles(sc) - {("node", node_id)})
    while not node.ended:
        if node.k < 0:
            barrier.tick(time.monotonic())  # until started
        bus.pump(timeout=0.02)
        while True:
            now = time.monotonic()
            if realtime:
                node.give_up = True  # real time: step with whatever neighbours have arrived
            elif node.waiting_since is not None and now - node.waiting_since > neighbour_timeout:
                log(role, f"step {node.k + 1}: neighbour(s) {node.missing()} silent for {neighbour_timeout:g} s; going on without")
                node.give_up = True
            if not node.try_step(now):
                break
    return 0


class _CollectorProgress:
    """Prints ``@progress k`` lines on stdout for a parent process (``netsetest run``)."""

    def __init__(self, enabled: bool) -> None:
        self.enabled, self.last = enabled, -1

    def update(self, k: int) -> None:
        if self.enabled and k > self.last:
            print(f"@progress {k}", flush=True)
            self.last = k


def run_collector(
    sc: Scenario,
    bus: Bus,
    run_id: str,
    meta: dict,
    record: str | None,
    summary_json: str | None,
    progress: bool,
    idle_timeout: float,
    on_summary: Callable[[dict], None] | None = None,
) -> int:
    sink, _ = record_sink(record)  # opened now: the record grows step by step and survives a crash
    collector = Collector(sc, bus, run_id, sink)
    if sink is not None:
        sink.meta(meta)
    barrier = Barrier(bus, run_id, Ready(role="collector"), _all_roles(sc) - {("collector", None)})
    prog = _CollectorProgress(progress)
    last_msg = time.monotonic()
    while True:
        now = time.monotonic()
        if not collector.started:
            barrier.tick(now)
        if bus.pump(timeout=0.05):
            last_msg = time.monotonic()
        prog.update(collector.progress)
        if collector.ended is not None:
            # End overtakes the last states on other paths: wait until they are in (or a grace period)
            t_end = time.monotonic()
            while collector.progress < collector.ended.steps and time.monotonic() - t_end < 2.0:
                bus.pump(timeout=0.05)
            prog.update(collector.progress)
            break
        if now - last_msg > idle_timeout:
            log("collector", f"no message for {idle_timeout:g} s: the vehicle is gone; writing what was received")
            break
    summary = collector.finish(meta)
    write_summary(summary, summary_json)
    if on_summary:
        on_summary(summary)
    return exit_code(summary) if collector.ended is not None else EXIT_VIOLATION
